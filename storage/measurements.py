"""Measurements as an append-only audit trail.

Every value belongs to a *series* (one named quantity of a session, e.g. the picked tail length). A
change appends a row with the next revision number; a deletion appends a row marked ``deleted``.
The current value of a series is its newest row, and the whole series is its history.
"""

from __future__ import annotations

import uuid

from sqlalchemy import func
from sqlmodel import Session, select

from .errors import NotFoundError
from .models import Measurement


def add_measurement(session: Session, **fields) -> Measurement:
    """Start a new series with its first revision; ``fields`` are Measurement columns."""
    row = Measurement(series=uuid.uuid4().hex, revision=1, **fields)
    session.add(row)
    session.flush()
    return row


def get_measurement(session: Session, measurement_id: int) -> Measurement:
    row = session.get(Measurement, measurement_id)
    if row is None:
        raise NotFoundError("measurement", measurement_id)
    return row


def revise_measurement(session: Session, measurement_id: int, **changes) -> Measurement:
    """Append a revision of the series of ``measurement_id`` with ``changes`` applied to its newest row."""
    latest = _latest_of_series(session, get_measurement(session, measurement_id).series)
    if latest.deleted:
        raise NotFoundError("measurement", measurement_id)
    data = latest.model_dump(exclude={"id", "created_at", "revision"})
    data.update(changes)
    row = Measurement(**data, revision=latest.revision + 1)
    session.add(row)
    session.flush()
    return row


def delete_measurement(session: Session, measurement_id: int, by: str = "", note: str = "") -> Measurement:
    """Append a tombstone revision; the history keeps every earlier value."""
    return revise_measurement(session, measurement_id, deleted=True, created_by=by, note=note)


def current_measurements(session: Session, session_ids: list[int] | None = None) -> list[Measurement]:
    """The newest, not deleted revision of every series (of the given sessions), oldest series first."""
    newest = select(func.max(Measurement.id)).group_by(Measurement.series)
    query = select(Measurement).where(Measurement.id.in_(newest), Measurement.deleted.is_(False))
    if session_ids is not None:
        query = query.where(Measurement.session_id.in_(session_ids))
    return list(session.exec(query.order_by(Measurement.session_id, Measurement.name, Measurement.id)))


def history(session: Session, measurement_id: int) -> list[Measurement]:
    """Every revision of the series ``measurement_id`` belongs to, oldest first."""
    series = get_measurement(session, measurement_id).series
    return list(session.exec(select(Measurement).where(Measurement.series == series).order_by(Measurement.revision)))


def session_history(session: Session, session_id: int) -> list[Measurement]:
    """All revisions of all measurements of a session in the order they were made."""
    return list(session.exec(select(Measurement).where(Measurement.session_id == session_id).order_by(Measurement.id)))


def _latest_of_series(session: Session, series: str) -> Measurement:
    query = select(Measurement).where(Measurement.series == series).order_by(Measurement.revision.desc())
    return session.exec(query).first()
