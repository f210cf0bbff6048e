"""Compressed byte storage inside the database (uploaded images, point clouds)."""

from __future__ import annotations

import hashlib
import zlib

from sqlmodel import Session

from .errors import NotFoundError
from .models import Blob

# Already-compressed formats (PNG, JPEG, zip, npz) gain nothing from zlib; keep them as they are
# unless compression saves at least this fraction.
MIN_SAVING = 0.05


def put_blob(session: Session, data: bytes) -> Blob:
    """Store ``data`` compressed with zlib when that helps; returns the flushed row (id set)."""
    packed = zlib.compress(data, 6)
    if len(packed) <= len(data) * (1 - MIN_SAVING):
        blob = Blob(sha256=hashlib.sha256(data).hexdigest(), size=len(data), codec="zlib", data=packed)
    else:
        blob = Blob(sha256=hashlib.sha256(data).hexdigest(), size=len(data), codec="identity", data=data)
    session.add(blob)
    session.flush()
    return blob


def get_bytes(session: Session, blob_id: int) -> bytes:
    """The original bytes of blob ``blob_id``; checks the stored digest."""
    blob = session.get(Blob, blob_id)
    if blob is None:
        raise NotFoundError("blob", blob_id)
    data = zlib.decompress(blob.data) if blob.codec == "zlib" else bytes(blob.data)
    if hashlib.sha256(data).hexdigest() != blob.sha256:
        raise ValueError(f"blob {blob_id}: stored data does not match its sha256 digest")
    return data
