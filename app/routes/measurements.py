"""Picked and manual measurements of a session, corrections and their history (audit trail)."""

from __future__ import annotations

from fastapi import APIRouter, Response

from app.config import software_version
from app.deps import DbDep, SettingsDep
from app.picking import measure
from app.schemas import MeasurementCreate, MeasurementRevise
from storage import measurements, sessions
from storage.errors import ConflictError, InvalidInputError
from storage.models import MeasurementKind, MeasurementPublic

router = APIRouter(tags=["measurements"])


@router.post("/sessions/{session_id}/measurements", status_code=201, response_model=MeasurementPublic)
def add_measurement(session_id: int, data: MeasurementCreate, db: DbDep, settings: SettingsDep):
    """Add a picked (``distance``/``polyline``, points snapped onto the scan surface) or manual value."""
    record = sessions.get_session(db, session_id)
    fields = dict(session_id=session_id, name=data.name.strip(), note=data.note, created_by=data.created_by,
                  software_version=software_version(), calibration_id=record.calibration_id)
    if data.scan_id is not None:
        _check_scan_of(db, session_id, data.scan_id)
    if data.kind == "manual":
        return measurements.add_measurement(db, **fields, kind=MeasurementKind.manual.value, method="tape",
                                            value_mm=data.value_mm, scan_id=data.scan_id)
    value, snapped = measure(db, data.scan_id, data.kind, data.points, settings)
    return measurements.add_measurement(db, **fields, kind=MeasurementKind.picked.value, method=data.kind,
                                        scan_id=data.scan_id, value_mm=value, points=snapped,
                                        picked_points=[list(p) for p in data.points])


@router.get("/sessions/{session_id}/measurements", response_model=list[MeasurementPublic])
def list_measurements(session_id: int, db: DbDep, history: bool = False):
    """Current value of every measurement; ``?history=true`` lists every revision in order."""
    sessions.get_session(db, session_id)
    if history:
        return measurements.session_history(db, session_id)
    return measurements.current_measurements(db, [session_id])


@router.get("/measurements/{measurement_id}", response_model=MeasurementPublic)
def read_measurement(measurement_id: int, db: DbDep):
    return measurements.get_measurement(db, measurement_id)


@router.get("/measurements/{measurement_id}/history", response_model=list[MeasurementPublic])
def measurement_history(measurement_id: int, db: DbDep):
    """Every revision of this measurement, oldest first, with who changed it, when and why."""
    return measurements.history(db, measurement_id)


@router.patch("/measurements/{measurement_id}", response_model=MeasurementPublic)
def revise_measurement(measurement_id: int, data: MeasurementRevise, db: DbDep, settings: SettingsDep):
    """Correct a picked (new points) or manual (new value) measurement; appends a revision."""
    current = measurements.get_measurement(db, measurement_id)
    changes = dict(note=data.note, created_by=data.created_by, software_version=software_version())
    if current.kind == MeasurementKind.automatic.value:
        raise ConflictError("automatic measurements come from the scan and are not edited; "
                            "add a picked or manual measurement instead")
    if current.kind == MeasurementKind.manual.value:
        if data.value_mm is None or data.points is not None:
            raise InvalidInputError("a manual measurement is corrected with value_mm")
        changes["value_mm"] = data.value_mm
    else:
        if data.points is None or data.value_mm is not None:
            raise InvalidInputError(f"a picked {current.method} is corrected with new points")
        if current.method == "distance" and len(data.points) != 2:
            raise InvalidInputError(f"a distance takes exactly 2 points, got {len(data.points)}")
        value, snapped = measure(db, current.scan_id, current.method, data.points, settings)
        changes.update(value_mm=value, points=snapped, picked_points=[list(p) for p in data.points])
    return measurements.revise_measurement(db, measurement_id, **changes)


@router.delete("/measurements/{measurement_id}", status_code=204)
def delete_measurement(measurement_id: int, db: DbDep, by: str = "", note: str = "") -> Response:
    """Withdraw a measurement; its history stays (a deletion is an appended revision)."""
    measurements.delete_measurement(db, measurement_id, by=by, note=note)
    return Response(status_code=204)


def _check_scan_of(db, session_id: int, scan_id: int) -> None:
    scan = sessions.get_scan(db, scan_id)
    if scan.session_id != session_id:
        raise InvalidInputError(f"scan {scan_id} belongs to session {scan.session_id}, not to session {session_id}")
