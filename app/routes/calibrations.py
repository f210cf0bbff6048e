"""Calibration uploads (pose images or a zip of a capture folder) and their results."""

from __future__ import annotations

from collections.abc import Callable
from typing import Annotated

from fastapi import APIRouter, File, Form, Query, UploadFile

from app.deps import DbDep, SettingsDep
from app.errors import BadUpload
from app.schemas import Accepted, CalibrationOut
from app.tasks import ARCHIVE
from app.uploads import capture_path, read_upload
from measurement.capture import GAMMA_RANGE
from storage import calibrations
from storage.jobs import job_for
from storage.models import Calibration, JobKind

router = APIRouter(prefix="/calibrations", tags=["calibrations"])
RIG_FIELDS = ("board_cols", "board_rows", "square_mm", "stripes")
MAX_CORNERS = 200
MAX_STRIPES = 4096


@router.post("", status_code=202, response_model=Accepted)
def create_calibration(
    db: DbDep,
    settings: SettingsDep,
    files: Annotated[list[UploadFile] | None, File(description="pose images named as in the capture layout, "
                                                   "e.g. calib/pose_01_board.png; rig.json may be one of them")] = None,
    archive: Annotated[UploadFile | None, File(description="one zip of a capture folder")] = None,
    board_cols: Annotated[int | None, Form(ge=2, le=MAX_CORNERS, description="chessboard inner corners along a row")] = None,
    board_rows: Annotated[int | None, Form(ge=2, le=MAX_CORNERS, description="chessboard inner corners along a column")] = None,
    square_mm: Annotated[float | None, Form(gt=0, lt=1000, description="chessboard square size, mm")] = None,
    stripes: Annotated[int | None, Form(ge=2, le=MAX_STRIPES, description="projector stripe count")] = None,
    camera_gamma: Annotated[float | None, Form(ge=GAMMA_RANGE[0], le=GAMMA_RANGE[1],
                                               description="the camera's display gamma: 1.0 if it writes light "
                                                           "linearly (default), 2.2 if it writes sRGB-like "
                                                           "images")] = None,
    name: Annotated[str, Form(max_length=200)] = "",
):
    """Store the capture and queue the calibration job. Rig fields override the upload's rig.json.

    The images are checked now (layout, readable, one size); the calibration itself runs in a worker:
    poll ``GET /api/jobs/{job_id}``.
    """
    given = {k: v for k, v in zip(RIG_FIELDS, (board_cols, board_rows, square_mm, stripes), strict=True)
             if v is not None}
    stored, load = _read(files, archive, settings.max_upload_bytes)
    rig = _validated_rig(load, given)
    if camera_gamma is not None:
        rig["camera_gamma"] = camera_gamma
    record, job = calibrations.create_calibration(db, rig, stored, name=name.strip())
    return Accepted(id=record.id, job_id=job.id)


@router.get("", response_model=list[CalibrationOut])
def list_calibrations(db: DbDep, offset: int = Query(0, ge=0), limit: int = Query(100, ge=1, le=1000)):
    return [_out(db, c, with_result=False) for c in calibrations.list_calibrations(db, offset, limit)]


@router.get("/{calibration_id}", response_model=CalibrationOut)
def read_calibration(calibration_id: int, db: DbDep):
    """Status and rig; once succeeded also every field of calibration.json (intrinsics, planes, errors,
    per-pose diagnostics)."""
    return _out(db, calibrations.get_calibration(db, calibration_id), with_result=True)


def _out(db, record: Calibration, with_result: bool) -> CalibrationOut:
    job = job_for(db, JobKind.calibration, record.id)
    extra = dict(record.result or {}) if with_result else {}
    for key in CalibrationOut.model_fields:
        extra.pop(key, None)  # calibration.json never overrides the record's own fields
    return CalibrationOut(**record.model_dump(exclude={"result"}, warnings=False), job_id=job.id if job else None,
                          files=calibrations.calibration_file_names(db, record.id), **extra)


def _read(files: list[UploadFile] | None, archive: UploadFile | None, limit: int) -> tuple[dict, Callable]:
    """Stored files (path -> bytes) and a loader ``rig -> Capture`` that validates them."""
    from measurement.capture import capture_from_files, capture_from_zip

    files = [f for f in files or [] if f.filename or f.size]  # browsers send an empty part for "no file"
    if bool(files) == (archive is not None):
        raise BadUpload("send either the pose images as 'files' or one zip of the capture folder as 'archive'")
    if archive is not None:
        data = read_upload(archive, limit, "archive")
        return {ARCHIVE: data}, lambda rig: capture_from_zip(data, rig, max_bytes=4 * limit)
    stored: dict[str, bytes] = {}
    for upload in files:
        path = capture_path(upload.filename, "files")
        if path in stored:
            raise BadUpload(f"files: {path!r} was uploaded twice")
        stored[path] = read_upload(upload, limit, "files")
    return stored, lambda rig: capture_from_files(stored, rig)


def _validated_rig(load: Callable, given: dict) -> dict:
    """Decode and check the capture now; returns the rig settings (form fields over rig.json)."""
    from measurement.capture import RigSettings
    from measurement.errors import CaptureError

    if len(given) == len(RIG_FIELDS):
        capture = load(RigSettings.from_dict(given, source="form fields"))
    else:
        try:
            capture = load(None)
        except CaptureError as exc:
            if not str(exc).startswith("rig.json: missing"):
                raise
            missing = [k for k in RIG_FIELDS if k not in given]
            raise BadUpload(f"rig settings missing: {', '.join(missing)} (send them as form fields or "
                            "include rig.json in the upload)") from None
        if given:
            capture = load(RigSettings.from_dict({**capture.rig.to_dict(), **given}, source="form fields"))
    if not capture.poses:
        raise CaptureError("no calibration images: upload calib/pose_NN_board.png (and pose_NN_stripes.png) files")
    rig = capture.rig.to_dict()
    for name, top in (("board_cols", MAX_CORNERS), ("board_rows", MAX_CORNERS), ("stripes", MAX_STRIPES)):
        if rig[name] > top:
            raise BadUpload(f"rig.json: {name} = {rig[name]} is more than the largest supported ({top})")
    return rig
