"""What each kind of job does: read its inputs from the database, run the measurement core, and return
how to store the result (applied by the runner in the same transaction that marks the job done).

The calibration and scan code is imported inside the handlers, when a job runs, not when the app starts.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from sqlalchemy.engine import Engine
from sqlmodel import Session

from app.config import software_version
from storage import calibrations, measurements, sessions
from storage.db import session_scope
from storage.models import Job, JobKind, MeasurementKind

Report = Callable[[float, str], None]
Apply = Callable[[Session], None]
ARCHIVE = "archive.zip"


def run_calibration(engine: Engine, job: Job, report: Report) -> Apply:
    """Calibrate from the stored capture files; returns how to store calibration.json."""
    from measurement.calibration import calibrate
    from measurement.capture import RigSettings, capture_from_files, capture_from_zip

    with session_scope(engine) as db:
        record = calibrations.get_calibration(db, job.result_id)
        files = calibrations.calibration_files(db, record.id)
        rig = RigSettings.from_dict(calibrations.rig_of(record))
    report(0.0, "reading images")
    if set(files) == {ARCHIVE}:
        capture = capture_from_zip(files[ARCHIVE], rig)
    else:
        capture = capture_from_files(files, rig)
    result = to_jsonable(calibrate(capture, progress=report).to_dict())
    return lambda db: calibrations.store_result(db, job.result_id, result)


def run_scan(engine: Engine, job: Job, report: Report) -> Apply:
    """Reconstruct the cloud of a stored scan image; returns how to store cloud and measurements."""
    from measurement.calibration import load_calibration
    from measurement.errors import MeasurementError, naming_files
    from measurement.images import decode_image
    from measurement.pipeline import scan

    with session_scope(engine) as db:
        record = sessions.get_scan(db, job.result_id)
        owner = sessions.get_session(db, record.session_id)
        calibration = calibrations.require_usable(db, owner.calibration_id)
        image, ambient = sessions.scan_image(db, record.id), sessions.scan_ambient(db, record.id)
    report(0.05, "decoding image")
    name = record.image_name or f"scan {record.id}"
    gray = decode_image(image, name)
    dark = decode_image(ambient, f"ambient image of scan {record.id}") if ambient is not None else None
    report(0.1, "reconstructing point cloud")
    try:
        result = scan(gray, load_calibration(calibration.result), view=record.view, ambient=dark)
    except MeasurementError as exc:
        raise naming_files(exc, name, f"ambient image of {name}" if dark is not None else None) from None
    cloud = {key: getattr(result, key, None) for key in sessions.CLOUD_KEYS}
    found = to_jsonable(result.measurements)

    def apply(db: Session) -> None:
        sessions.store_scan_result(db, record.id, cloud, found)
        for name, value, points in automatic_values(found):
            measurements.add_measurement(
                db, session_id=owner.id, scan_id=record.id, calibration_id=calibration.id, name=name,
                kind=MeasurementKind.automatic.value, method=f"auto:{record.view}", value_mm=value,
                points=points, created_by="bodyscan", software_version=software_version())

    return apply


HANDLERS: dict[str, Callable[[Engine, Job, Report], Apply]] = {
    JobKind.calibration.value: run_calibration,
    JobKind.scan.value: run_scan,
}


def automatic_values(found: dict) -> list[tuple[str, float, list | None]]:
    """(name, value in mm, source points) for every ``<name>_mm`` number in a scan's measurements.

    The source points are taken from ``found[<name>]["points"]`` when the pipeline gives them.
    """
    out = []
    for key, value in sorted(found.items()):
        if not key.endswith("_mm") or isinstance(value, bool) or not isinstance(value, int | float):
            continue
        if not np.isfinite(value):
            continue
        name = key[: -len("_mm")]
        detail = found.get(name)
        points = detail.get("points") if isinstance(detail, dict) else None
        out.append((name, float(value), points))
    return out


def to_jsonable(value):
    """numpy scalars/arrays inside dicts and lists -> plain Python, NaN/inf -> None (JSON has neither)."""
    if isinstance(value, dict):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [to_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value
