"""Database tables and their Create / Public / Update model families.

Units: millimetres for every length, UTC for every timestamp. Large payloads (uploaded images, point
clouds) live in :class:`Blob` rows and are referenced by id, so listing records never loads them.
The migrations in ``storage/migrations`` must match these tables (a test compares them).
"""

from __future__ import annotations

import datetime as dt
from datetime import UTC, datetime
from enum import StrEnum
from typing import Annotated, Any

from pydantic import AfterValidator, ConfigDict, field_validator, model_validator
from sqlalchemy import JSON, Column, DateTime, Index, LargeBinary, String, UniqueConstraint
from sqlmodel import Field, SQLModel


def utcnow() -> datetime:
    """Timezone-aware current UTC time."""
    return datetime.now(UTC)


def _as_utc(value: datetime) -> datetime:
    # SQLite hands back naive datetimes; everything we store is UTC.
    return value.replace(tzinfo=UTC) if value.tzinfo is None else value.astimezone(UTC)


UTCDateTime = Annotated[datetime, AfterValidator(_as_utc)]


def _ts_column(nullable: bool = False) -> Any:
    if nullable:
        return Field(default=None, sa_type=DateTime(timezone=True), nullable=True)
    return Field(default_factory=utcnow, sa_type=DateTime(timezone=True), nullable=False)


class JobStatus(StrEnum):
    queued = "queued"
    running = "running"
    succeeded = "succeeded"
    failed = "failed"


class JobKind(StrEnum):
    calibration = "calibration"
    scan = "scan"


class MeasurementKind(StrEnum):
    automatic = "automatic"
    picked = "picked"
    manual = "manual"


class View(StrEnum):
    side = "side"
    top = "top"
    front = "front"
    back = "back"


class Sex(StrEnum):
    female = "female"
    male = "male"
    castrated = "castrated"
    unknown = "unknown"


# --- blobs -------------------------------------------------------------------------------------------


class Blob(SQLModel, table=True):
    """Compressed bytes of an uploaded file or a computed cloud; ``size`` is the uncompressed length."""

    id: int | None = Field(default=None, primary_key=True)
    sha256: str = Field(max_length=64, index=True)
    size: int
    codec: str = Field(max_length=16)
    data: bytes = Field(sa_column=Column(LargeBinary, nullable=False))
    created_at: datetime = _ts_column()


# --- animals -----------------------------------------------------------------------------------------


class AnimalBase(SQLModel):
    tag: str = Field(min_length=1, max_length=64, index=True, unique=True,
                     description="ear tag or other herd identifier, unique")
    species: str = Field(default="", max_length=64)
    breed: str = Field(default="", max_length=64)
    sex: Sex = Field(default=Sex.unknown, sa_type=String(16))
    birth_date: dt.date | None = None
    status: str = Field(default="active", max_length=32, description="e.g. active, sold, deceased")
    notes: str = Field(default="", max_length=4000)


class Animal(AnimalBase, table=True):
    id: int | None = Field(default=None, primary_key=True)
    created_at: datetime = _ts_column()
    updated_at: datetime = _ts_column()


class AnimalCreate(AnimalBase):
    model_config = ConfigDict(extra="forbid")

    @field_validator("tag")
    @classmethod
    def _strip_tag(cls, v: str) -> str:
        v = v.strip()
        if not v:
            raise ValueError("tag must not be blank")
        return v


class AnimalUpdate(SQLModel):
    model_config = ConfigDict(extra="forbid")

    tag: str | None = Field(default=None, min_length=1, max_length=64)
    species: str | None = Field(default=None, max_length=64)
    breed: str | None = Field(default=None, max_length=64)
    sex: Sex | None = None
    birth_date: dt.date | None = None
    status: str | None = Field(default=None, max_length=32)
    notes: str | None = Field(default=None, max_length=4000)

    @field_validator("tag")
    @classmethod
    def _strip_tag(cls, v: str | None) -> str | None:
        return None if v is None else AnimalCreate._strip_tag(v)

    @model_validator(mode="after")
    def _null_only_clears_birth_date(self) -> AnimalUpdate:
        for name in sorted(self.model_fields_set):
            if getattr(self, name) is None and name != "birth_date":
                raise ValueError(f"{name} cannot be null (leave it out to keep its value)")
        return self


class AnimalPublic(AnimalBase):
    id: int
    created_at: UTCDateTime
    updated_at: UTCDateTime


# --- calibrations ------------------------------------------------------------------------------------


class Calibration(SQLModel, table=True):
    """Rig settings, uploaded images (CalibrationFile rows) and, once the job succeeded, calibration.json."""

    id: int | None = Field(default=None, primary_key=True)
    name: str = Field(default="", max_length=200)
    board_cols: int
    board_rows: int
    square_mm: float
    stripes: int
    camera_gamma: float = Field(default=1.0)  # the camera's display gamma (1.0: linear, 2.2: sRGB-like)
    status: JobStatus = Field(default=JobStatus.queued, sa_type=String(16))
    error: str | None = Field(default=None, max_length=4000)
    result: dict | None = Field(default=None, sa_type=JSON)
    created_at: datetime = _ts_column()
    finished_at: datetime | None = _ts_column(nullable=True)


class CalibrationFile(SQLModel, table=True):
    """One uploaded capture file (pose image or rig.json) of a calibration, by its capture-relative path."""

    __tablename__ = "calibration_file"
    __table_args__ = (UniqueConstraint("calibration_id", "path"),)

    id: int | None = Field(default=None, primary_key=True)
    calibration_id: int = Field(foreign_key="calibration.id", index=True, ondelete="CASCADE")
    path: str = Field(max_length=255)
    blob_id: int = Field(foreign_key="blob.id")


# --- sessions, scans ---------------------------------------------------------------------------------


class SessionBase(SQLModel):
    animal_id: int = Field(foreign_key="animal.id", index=True)
    calibration_id: int = Field(foreign_key="calibration.id", index=True)
    date: dt.date = Field(default_factory=lambda: utcnow().date())
    operator: str = Field(default="", max_length=120)
    notes: str = Field(default="", max_length=4000)


class MeasuringSession(SessionBase, table=True):
    """An animal measured on a date with one calibration (the API calls it a session)."""

    __tablename__ = "measuring_session"

    id: int | None = Field(default=None, primary_key=True)
    created_at: datetime = _ts_column()


class SessionCreate(SessionBase):
    model_config = ConfigDict(extra="forbid")


class SessionUpdate(SQLModel):
    """Corrections to a session's date, operator or notes (its animal and calibration are fixed)."""

    model_config = ConfigDict(extra="forbid")

    date: dt.date | None = None
    operator: str | None = Field(default=None, max_length=120)
    notes: str | None = Field(default=None, max_length=4000)

    @model_validator(mode="after")
    def _no_nulls(self) -> SessionUpdate:
        for name in sorted(self.model_fields_set):
            if getattr(self, name) is None:
                raise ValueError(f"{name} cannot be null (leave it out to keep its value)")
        return self


class Scan(SQLModel, table=True):
    """One image of a session for one view, its cloud (npz blob) and its automatic measurements."""

    id: int | None = Field(default=None, primary_key=True)
    session_id: int = Field(foreign_key="measuring_session.id", index=True)
    view: str = Field(max_length=16)
    image_name: str = Field(default="", max_length=255)
    image_blob_id: int = Field(foreign_key="blob.id")
    ambient_blob_id: int | None = Field(default=None, foreign_key="blob.id",
                                        description="optional image with the projector off")
    cloud_blob_id: int | None = Field(default=None, foreign_key="blob.id")
    status: JobStatus = Field(default=JobStatus.queued, sa_type=String(16))
    error: str | None = Field(default=None, max_length=4000)
    point_count: int | None = None
    measurements: dict | None = Field(default=None, sa_type=JSON)
    created_at: datetime = _ts_column()
    finished_at: datetime | None = _ts_column(nullable=True)


# --- measurements (append-only audit trail) ----------------------------------------------------------


class Measurement(SQLModel, table=True):
    """One revision of a named value. Rows are never updated: a change appends a row of the same series.

    ``points`` are the 3D points (mm, camera frame) the value was computed from; for picked values these
    are the snapped points, ``picked_points`` the raw picks. A deleted value is a row with ``deleted``.
    """

    id: int | None = Field(default=None, primary_key=True)
    series: str = Field(max_length=32, index=True)
    revision: int = 1
    session_id: int = Field(foreign_key="measuring_session.id", index=True)
    scan_id: int | None = Field(default=None, foreign_key="scan.id")
    calibration_id: int | None = Field(default=None, foreign_key="calibration.id")
    name: str = Field(max_length=64)
    kind: str = Field(max_length=16)
    method: str = Field(default="", max_length=32)
    value_mm: float | None = None
    points: list | None = Field(default=None, sa_type=JSON)
    picked_points: list | None = Field(default=None, sa_type=JSON)
    note: str = Field(default="", max_length=2000)
    deleted: bool = False
    created_by: str = Field(default="", max_length=120)
    software_version: str = Field(default="", max_length=32)
    created_at: datetime = _ts_column()


class MeasurementPublic(SQLModel):
    id: int
    series: str
    revision: int
    session_id: int
    scan_id: int | None
    calibration_id: int | None
    name: str
    kind: str
    method: str
    value_mm: float | None
    points: list | None
    picked_points: list | None
    note: str
    deleted: bool
    created_by: str
    software_version: str
    created_at: UTCDateTime


# --- jobs --------------------------------------------------------------------------------------------


class Job(SQLModel, table=True):
    """A unit of work for the worker pool. ``result_id`` is the calibration or scan the job fills in.

    A running job's ``heartbeat_at`` is refreshed by its worker; a job whose heartbeat is older than
    the lease is re-queued (up to a maximum number of attempts) when any worker polls.
    """

    __table_args__ = (Index("ix_job_status_id", "status", "id"),)

    id: int | None = Field(default=None, primary_key=True)
    kind: str = Field(max_length=16)
    status: JobStatus = Field(default=JobStatus.queued, sa_type=String(16), index=True)
    progress: float = 0.0
    stage: str = Field(default="queued", max_length=200)
    error: str | None = Field(default=None, max_length=4000)
    result_id: int
    attempts: int = 0
    worker: str | None = Field(default=None, max_length=120)
    heartbeat_at: datetime | None = _ts_column(nullable=True)
    created_at: datetime = _ts_column()
    started_at: datetime | None = _ts_column(nullable=True)
    finished_at: datetime | None = _ts_column(nullable=True)
