"""Response and request models of the REST API that are not plain table families (see storage.models)."""

from __future__ import annotations

import datetime as dt
from typing import Literal

from pydantic import ConfigDict, Field, FiniteFloat, model_validator
from sqlmodel import SQLModel

from storage.models import AnimalPublic, JobStatus, MeasurementPublic, UTCDateTime

Point = tuple[FiniteFloat, FiniteFloat, FiniteFloat]


class Accepted(SQLModel):
    """202 answer of an upload: the record that will be filled in and the job that fills it."""

    id: int
    job_id: int
    status: JobStatus = JobStatus.queued


class JobOut(SQLModel):
    id: int
    kind: str
    status: JobStatus
    progress: float = Field(description="0..1")
    stage: str
    error: str | None
    result_id: int
    attempts: int
    created_at: UTCDateTime
    started_at: UTCDateTime | None
    finished_at: UTCDateTime | None


class CalibrationOut(SQLModel):
    """Status and rig of a calibration; once succeeded, every field of calibration.json as well."""

    model_config = ConfigDict(extra="allow")

    id: int
    name: str
    status: JobStatus
    error: str | None
    job_id: int | None
    board_cols: int
    board_rows: int
    square_mm: float
    stripes: int
    camera_gamma: float
    files: list[str]
    created_at: UTCDateTime
    finished_at: UTCDateTime | None


class ScanOut(SQLModel):
    id: int
    session_id: int
    view: str
    image_name: str
    status: JobStatus
    error: str | None
    job_id: int | None
    point_count: int | None
    measurements: dict | None = Field(description="automatic measurements of the pipeline, mm")
    created_at: UTCDateTime
    finished_at: UTCDateTime | None


class SessionOut(SQLModel):
    id: int
    animal_id: int
    calibration_id: int
    date: dt.date
    operator: str
    notes: str
    created_at: UTCDateTime


class SessionDetail(SessionOut):
    animal: AnimalPublic
    scans: list[ScanOut]
    measurements: list[MeasurementPublic] = Field(description="current value of every measurement")


class MeasurementCreate(SQLModel):
    """A picked measurement (``distance``: 2 points, ``polyline``: 2 or more, snapped onto the surface of
    ``scan_id``) or a ``manual`` tape value in mm."""

    model_config = ConfigDict(extra="forbid")

    name: str = Field(min_length=1, max_length=64, pattern=r"^[^\x00-\x1f]+$",
                      description="body_length, body_height, tail_length, neck_width or any name")
    kind: Literal["distance", "polyline", "manual"]
    points: list[Point] | None = Field(default=None, max_length=2000, description="picked points, mm")
    scan_id: int | None = None
    value_mm: float | None = Field(default=None, gt=0, lt=100_000, description="manual tape value, mm")
    note: str = Field(default="", max_length=2000)
    created_by: str = Field(default="", max_length=120, description="operator name")

    @model_validator(mode="after")
    def _fits_kind(self) -> MeasurementCreate:
        if self.kind == "manual":
            if self.value_mm is None:
                raise ValueError("value_mm is required for a manual measurement")
            if self.points:
                raise ValueError("a manual measurement takes value_mm, not points")
            return self
        if self.scan_id is None:
            raise ValueError(f"scan_id is required for a {self.kind} measurement (the scan to snap onto)")
        if self.value_mm is not None:
            raise ValueError(f"a {self.kind} measurement is computed from points; do not send value_mm")
        count = len(self.points or [])
        if self.kind == "distance" and count != 2:
            raise ValueError(f"a distance takes exactly 2 points, got {count}")
        if self.kind == "polyline" and count < 2:
            raise ValueError(f"a polyline takes at least 2 points, got {count}")
        return self


class MeasurementRevise(SQLModel):
    """A correction: new points (picked) or a new value (manual), with who and why."""

    model_config = ConfigDict(extra="forbid")

    points: list[Point] | None = Field(default=None, min_length=2, max_length=2000)
    value_mm: float | None = Field(default=None, gt=0, lt=100_000)
    note: str = Field(default="", max_length=2000, description="why it was changed")
    created_by: str = Field(default="", max_length=120)
