"""Reading multipart uploads: size limits and file names that cannot escape the capture layout."""

from __future__ import annotations

from pathlib import PurePosixPath

from fastapi import UploadFile

from app.errors import BadUpload, UploadTooLarge

CHUNK = 1 << 20


def read_upload(upload: UploadFile, limit: int, field: str) -> bytes:
    """The bytes of one uploaded file; UploadTooLarge past ``limit`` bytes, BadUpload when empty."""
    parts, total = [], 0
    upload.file.seek(0)
    while chunk := upload.file.read(CHUNK):
        total += len(chunk)
        if total > limit:
            raise UploadTooLarge(f"{field} {upload.filename!r} is larger than the limit of {limit / 2**20:.0f} MB "
                                 "(set BODYSCAN_MAX_UPLOAD_MB to change it)")
        parts.append(chunk)
    if total == 0:
        raise BadUpload(f"{field} {upload.filename or '(no name)'!r}: file is empty")
    return b"".join(parts)


def capture_path(filename: str | None, field: str) -> str:
    """A relative POSIX path like ``calib/pose_01_board.png`` or ``pose_01_board.png``.

    Browsers send bare names, command-line clients may send folders; absolute paths, ``..`` and
    drive letters are refused.
    """
    if not filename or not filename.strip():
        raise BadUpload(f"{field}: every uploaded file needs a file name (e.g. calib/pose_01_board.png)")
    path = PurePosixPath(filename.replace("\\", "/"))
    if path.is_absolute() or ".." in path.parts or ":" in path.parts[0]:
        raise BadUpload(f"{field} {filename!r}: absolute paths and '..' are not allowed in file names")
    return path.as_posix()
