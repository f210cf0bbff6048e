"""Measuring sessions: an animal on a date with one calibration, and the scans uploaded to it."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, File, Form, Query, UploadFile

from app.deps import DbDep, SettingsDep
from app.errors import BadUpload
from app.routes.scans import scan_out
from app.schemas import Accepted, SessionDetail, SessionOut
from app.uploads import read_upload
from storage import animals, measurements, sessions
from storage.calibrations import require_usable
from storage.models import MeasurementPublic, SessionCreate, SessionUpdate, View

router = APIRouter(prefix="/sessions", tags=["sessions"])


@router.post("", status_code=201, response_model=SessionOut)
def create_session(data: SessionCreate, db: DbDep):
    """Open a session for an animal with a calibration (which may still be running, but not failed)."""
    return sessions.create_session(db, data)


@router.get("", response_model=list[SessionOut])
def list_sessions(db: DbDep, animal_id: int | None = None, offset: int = Query(0, ge=0),
                  limit: int = Query(100, ge=1, le=1000)):
    return sessions.list_sessions(db, animal_id=animal_id, offset=offset, limit=limit)


@router.get("/{session_id}", response_model=SessionDetail)
def read_session(session_id: int, db: DbDep):
    """The session with its animal, scans and the current value of each measurement."""
    record = sessions.get_session(db, session_id)
    return SessionDetail(
        **record.model_dump(), animal=animals.get_animal(db, record.animal_id),
        scans=[scan_out(db, s) for s in sessions.scans_of(db, session_id)],
        measurements=[MeasurementPublic.model_validate(m) for m in measurements.current_measurements(db, [session_id])],
    )


@router.patch("/{session_id}", response_model=SessionOut)
def update_session(session_id: int, data: SessionUpdate, db: DbDep):
    """Correct the date, operator or notes of a session."""
    return sessions.update_session(db, session_id, data)


@router.post("/{session_id}/scans", status_code=202, response_model=Accepted)
def upload_scan(
    session_id: int,
    db: DbDep,
    settings: SettingsDep,
    image: Annotated[UploadFile, File(description="the stripe image of the animal (PNG, TIFF, JPEG, BMP)")],
    view: Annotated[str, Form(description="side, top, front or back")] = "side",
    ambient: Annotated[UploadFile | None, File(description="optional: the same view with the projector off; "
                                                           "evens out fur and skin colour")] = None,
):
    """Store the image and queue the scan job; the session's calibration must have succeeded (409)."""
    from measurement.images import decode_image

    if view not in {v.value for v in View}:
        raise BadUpload(f"view {view!r} unknown; choose side, top, front or back")
    record = sessions.get_session(db, session_id)
    calibration = require_usable(db, record.calibration_id)
    name = _base_name(image.filename, "image")
    data = read_upload(image, settings.max_upload_bytes, "image")
    gray = decode_image(data, name)
    size = (calibration.result or {}).get("image_size")
    if size and [gray.shape[1], gray.shape[0]] != list(size):
        raise BadUpload(f"{name}: image is {gray.shape[1]}x{gray.shape[0]} but calibration {calibration.id} "
                        f"was made with {size[0]}x{size[1]} images from the same camera")
    dark = None
    if ambient is not None and (ambient.filename or ambient.size):  # browsers send an empty part for none
        dark_name = _base_name(ambient.filename, "ambient")
        dark = read_upload(ambient, settings.max_upload_bytes, "ambient")
        if decode_image(dark, dark_name).shape != gray.shape:
            raise BadUpload(f"{dark_name}: the ambient image must have the size of {name} "
                            f"({gray.shape[1]}x{gray.shape[0]})")
    scan, job = sessions.create_scan(db, session_id, view, name, data, dark)
    return Accepted(id=scan.id, job_id=job.id)


def _base_name(filename: str | None, default: str) -> str:
    return (filename or default).replace("\\", "/").rsplit("/", 1)[-1] or default
