"""Measuring sessions (an animal on a date with one calibration) and their scans."""

from __future__ import annotations

import io

import numpy as np
from sqlmodel import Session, select

from .animals import get_animal
from .blobs import get_bytes, put_blob
from .calibrations import get_calibration, require_usable
from .errors import ConflictError, NotFoundError
from .jobs import enqueue
from .models import Job, JobKind, JobStatus, MeasuringSession, Scan, SessionCreate, SessionUpdate

CLOUD_KEYS = ("points", "stripe", "uv", "scene_points", "scene_stripe", "scene_uv")


def create_session(session: Session, data: SessionCreate) -> MeasuringSession:
    """Insert a session; the animal must exist and the calibration must not have failed."""
    get_animal(session, data.animal_id)
    calibration = get_calibration(session, data.calibration_id)
    if calibration.status == JobStatus.failed:
        raise ConflictError(f"calibration {calibration.id} failed ({calibration.error}); choose another one")
    record = MeasuringSession.model_validate(data)
    session.add(record)
    session.flush()
    return record


def get_session(session: Session, session_id: int) -> MeasuringSession:
    record = session.get(MeasuringSession, session_id)
    if record is None:
        raise NotFoundError("session", session_id)
    return record


def update_session(session: Session, session_id: int, data: SessionUpdate) -> MeasuringSession:
    """Apply the fields present in ``data``."""
    record = get_session(session, session_id)
    for key, value in data.model_dump(exclude_unset=True).items():
        setattr(record, key, value)
    session.add(record)
    session.flush()
    return record


def list_sessions(session: Session, animal_id: int | None = None, offset: int = 0,
                  limit: int = 100) -> list[MeasuringSession]:
    query = select(MeasuringSession)
    if animal_id is not None:
        query = query.where(MeasuringSession.animal_id == animal_id)
    query = query.order_by(MeasuringSession.date.desc(), MeasuringSession.id.desc())
    return list(session.exec(query.offset(offset).limit(limit)))


def create_scan(session: Session, session_id: int, view: str, image_name: str, image: bytes,
                ambient: bytes | None = None) -> tuple[Scan, Job]:
    """Store a scan image (and optional ambient image) of a session and queue its scan job; the
    session's calibration must have succeeded."""
    record = get_session(session, session_id)
    require_usable(session, record.calibration_id)
    blob = put_blob(session, image)
    ambient_id = put_blob(session, ambient).id if ambient is not None else None
    scan = Scan(session_id=session_id, view=view, image_name=image_name, image_blob_id=blob.id,
                ambient_blob_id=ambient_id)
    session.add(scan)
    session.flush()
    return scan, enqueue(session, JobKind.scan, scan.id)


def get_scan(session: Session, scan_id: int) -> Scan:
    scan = session.get(Scan, scan_id)
    if scan is None:
        raise NotFoundError("scan", scan_id)
    return scan


def scans_of(session: Session, session_id: int) -> list[Scan]:
    return list(session.exec(select(Scan).where(Scan.session_id == session_id).order_by(Scan.id)))


def scan_image(session: Session, scan_id: int) -> bytes:
    return get_bytes(session, get_scan(session, scan_id).image_blob_id)


def scan_ambient(session: Session, scan_id: int) -> bytes | None:
    """The ambient (projector off) image of a scan, None when none was uploaded."""
    blob_id = get_scan(session, scan_id).ambient_blob_id
    return None if blob_id is None else get_bytes(session, blob_id)


def store_scan_result(session: Session, scan_id: int, cloud: dict[str, np.ndarray], measurements: dict) -> Scan:
    """Save a scan's cloud arrays (see CLOUD_KEYS) compressed, its point count and measurements."""
    scan = get_scan(session, scan_id)
    buf = io.BytesIO()
    np.savez_compressed(buf, **{k: np.asarray(v) for k, v in cloud.items() if v is not None})
    scan.cloud_blob_id = put_blob(session, buf.getvalue()).id
    scan.point_count = int(len(cloud["points"]))
    scan.measurements = measurements
    session.add(scan)
    return scan


def scan_cloud(session: Session, scan_id: int) -> dict[str, np.ndarray]:
    """The cloud arrays of a finished scan; ConflictError while it is not done."""
    scan = get_scan(session, scan_id)
    if scan.status != JobStatus.succeeded or scan.cloud_blob_id is None:
        detail = f" ({scan.error})" if scan.error else ""
        raise ConflictError(f"scan {scan_id} is {scan.status}{detail}; it has no point cloud yet")
    with np.load(io.BytesIO(get_bytes(session, scan.cloud_blob_id))) as npz:
        return {k: npz[k] for k in npz.files}
