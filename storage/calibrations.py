"""Calibration records: uploaded capture files, rig settings and the calibration.json result."""

from __future__ import annotations

from sqlmodel import Session, select

from .blobs import get_bytes, put_blob
from .errors import ConflictError, NotFoundError
from .jobs import enqueue
from .models import Calibration, CalibrationFile, Job, JobKind, JobStatus


def create_calibration(session: Session, rig: dict, files: dict[str, bytes], name: str = "") -> tuple[Calibration, Job]:
    """Store rig settings and capture files (path -> bytes) and queue the calibration job."""
    calibration = Calibration(name=name, board_cols=rig["board_cols"], board_rows=rig["board_rows"],
                              square_mm=rig["square_mm"], stripes=rig["stripes"],
                              camera_gamma=rig.get("camera_gamma", 1.0))
    session.add(calibration)
    session.flush()
    for path, data in sorted(files.items()):
        blob = put_blob(session, data)
        session.add(CalibrationFile(calibration_id=calibration.id, path=path, blob_id=blob.id))
    job = enqueue(session, JobKind.calibration, calibration.id)
    return calibration, job


def get_calibration(session: Session, calibration_id: int) -> Calibration:
    calibration = session.get(Calibration, calibration_id)
    if calibration is None:
        raise NotFoundError("calibration", calibration_id)
    return calibration


def list_calibrations(session: Session, offset: int = 0, limit: int = 100) -> list[Calibration]:
    query = select(Calibration).order_by(Calibration.id.desc()).offset(offset).limit(limit)
    return list(session.exec(query))


def calibration_files(session: Session, calibration_id: int) -> dict[str, bytes]:
    """The uploaded capture files of a calibration, path -> original bytes."""
    rows = session.exec(select(CalibrationFile).where(CalibrationFile.calibration_id == calibration_id))
    return {row.path: get_bytes(session, row.blob_id) for row in rows}


def calibration_file_names(session: Session, calibration_id: int) -> list[str]:
    query = select(CalibrationFile.path).where(CalibrationFile.calibration_id == calibration_id)
    return sorted(session.exec(query))


def rig_of(calibration: Calibration) -> dict:
    """The rig settings of a calibration as in rig.json."""
    return {"board_cols": calibration.board_cols, "board_rows": calibration.board_rows,
            "square_mm": calibration.square_mm, "stripes": calibration.stripes,
            "camera_gamma": calibration.camera_gamma}


def store_result(session: Session, calibration_id: int, result: dict) -> None:
    """Save calibration.json of a finished calibration job."""
    calibration = get_calibration(session, calibration_id)
    calibration.result = result
    session.add(calibration)


def require_usable(session: Session, calibration_id: int) -> Calibration:
    """The calibration if it finished successfully, else ConflictError saying why it cannot be used."""
    calibration = get_calibration(session, calibration_id)
    if calibration.status == JobStatus.failed:
        raise ConflictError(f"calibration {calibration_id} failed ({calibration.error}); "
                            "upload a new calibration and use its id")
    if calibration.status != JobStatus.succeeded or calibration.result is None:
        raise ConflictError(f"calibration {calibration_id} is still {calibration.status}; "
                            "wait until its job reports 'succeeded'")
    return calibration
