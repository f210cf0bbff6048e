"""Rows for the CSV export: one per session (wide) or one per measurement (long), as plain dicts.

Formatting and spreadsheet safety belong to the web layer; here values stay numbers (mm, %).
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass

from sqlalchemy import func
from sqlmodel import Session, select

from .measurements import current_measurements
from .models import Animal, Measurement, MeasuringSession, Scan

KINDS = ("automatic", "picked", "manual")
PREFERRED = ("body_length", "body_height", "tail_length", "neck_width")
BASE = ("animal_id", "tag", "species", "breed", "sex", "birth_date", "animal_status",
        "session_id", "date", "operator", "calibration_id")
LONG = ("animal_id", "tag", "species", "session_id", "date", "name", "kind", "value_mm", "method",
        "who", "when", "scan_id", "view", "calibration_id", "software_version", "measurement_id", "revision",
        "scan_warnings")
WARNINGS_SEP = " | "  # between a scan's warnings in one cell


@dataclass(frozen=True)
class ExportFilter:
    """Which sessions to export: species (case-insensitive), session date range (inclusive)."""

    species: str | None = None
    date_from: dt.date | None = None
    date_to: dt.date | None = None
    animal_id: int | None = None


def selected_sessions(session: Session, flt: ExportFilter) -> list[tuple[MeasuringSession, Animal]]:
    query = select(MeasuringSession, Animal).join(Animal, Animal.id == MeasuringSession.animal_id)
    if flt.species:
        query = query.where(func.lower(Animal.species) == flt.species.lower())
    if flt.date_from:
        query = query.where(MeasuringSession.date >= flt.date_from)
    if flt.date_to:
        query = query.where(MeasuringSession.date <= flt.date_to)
    if flt.animal_id is not None:
        query = query.where(Animal.id == flt.animal_id)
    return list(session.exec(query.order_by(Animal.tag, MeasuringSession.date, MeasuringSession.id)).all())


def wide_rows(session: Session, flt: ExportFilter) -> tuple[list[str], list[dict]]:
    """Header and one row per session: animal fields, ISO date, each measurement per kind in mm, the %
    difference of automatic and picked values to the manual one where both exist, and what the session's
    scans warned about (a cut-off animal, a faint coat or shadow, parts left unplaced), once each."""
    pairs = selected_sessions(session, flt)
    values = _latest_values([s.id for s, _ in pairs], session)
    said: dict[int, dict[str, None]] = {}  # session -> its scans' warnings, once each, in scan order
    for scan in _scans(session, [s.id for s, _ in pairs]):
        said.setdefault(scan.session_id, {}).update(dict.fromkeys(scan.warnings))
    header = list(BASE) + _measure_columns(values) + ["scan_warnings"]
    rows = []
    for record, animal in pairs:
        row = _base(record, animal)
        for (sid, name, kind), value in values.items():
            if sid == record.id:
                row[f"{name}_{kind}_mm"] = round(value, 2)
        for key in [h for h in header if h.endswith("_vs_manual_pct")]:
            name, kind = key[: -len("_vs_manual_pct")].rsplit("_", 1)
            ref, val = values.get((record.id, name, "manual")), values.get((record.id, name, kind))
            if ref and val is not None:
                row[key] = round((val - ref) / ref * 100.0, 2)
        row["scan_warnings"] = WARNINGS_SEP.join(said.get(record.id, {})) or None
        rows.append(row)
    return header, rows


def long_rows(session: Session, flt: ExportFilter) -> tuple[list[str], list[dict]]:
    """Header and one row per current measurement value, for herd-management software; a value from a
    scan carries that scan's warnings."""
    pairs = {s.id: (s, a) for s, a in selected_sessions(session, flt)}
    scans = {scan.id: scan for scan in _scans(session, list(pairs))}
    rows = []
    for m in current_measurements(session, list(pairs)):
        record, animal = pairs[m.session_id]
        rows.append({
            "animal_id": animal.id, "tag": animal.tag, "species": animal.species, "session_id": record.id,
            "date": record.date.isoformat(), "name": m.name, "kind": m.kind,
            "value_mm": None if m.value_mm is None else round(m.value_mm, 2), "method": m.method,
            "who": m.created_by, "when": _iso(m.created_at), "scan_id": m.scan_id,
            "view": scans[m.scan_id].view if m.scan_id in scans else None,
            "calibration_id": m.calibration_id, "software_version": m.software_version,
            "measurement_id": m.id, "revision": m.revision,
            "scan_warnings": WARNINGS_SEP.join(scans[m.scan_id].warnings) or None if m.scan_id in scans else None,
        })
    rows.sort(key=lambda r: (r["tag"], r["date"], r["session_id"], r["name"], KINDS.index(r["kind"])
                             if r["kind"] in KINDS else 9))
    return list(LONG), rows


@dataclass(frozen=True)
class _ScanInfo:
    id: int
    session_id: int
    view: str | None
    warnings: tuple[str, ...]


def _scans(session: Session, session_ids: list[int]) -> list[_ScanInfo]:
    """The scans of these sessions (one query), in id order, with the warnings their measurements hold."""
    if not session_ids:
        return []
    found = session.exec(select(Scan.id, Scan.session_id, Scan.view, Scan.measurements)
                         .where(Scan.session_id.in_(session_ids)).order_by(Scan.id)).all()
    return [_ScanInfo(scan_id, sid, view, tuple(str(w) for w in (meas or {}).get("warnings") or ()))
            for scan_id, sid, view, meas in found]


def _latest_values(session_ids: list[int], session: Session) -> dict[tuple[int, str, str], float]:
    """(session, name, kind) -> newest current value; a re-scan or second pick replaces the older one."""
    out: dict[tuple[int, str, str], float] = {}
    for m in sorted(current_measurements(session, session_ids), key=_order):
        if m.value_mm is not None:
            out[(m.session_id, m.name, m.kind)] = m.value_mm
    return out


def _order(m: Measurement) -> int:
    return m.id


def _measure_columns(values: dict) -> list[str]:
    names = {name for _, name, _ in values}
    kinds = {name: {k for _, n, k in values if n == name} for name in names}
    ordered = [n for n in PREFERRED if n in names] + sorted(names - set(PREFERRED))
    cols = []
    for name in ordered:
        cols += [f"{name}_{k}_mm" for k in KINDS if k in kinds[name]]
        if "manual" in kinds[name]:
            cols += [f"{name}_{k}_vs_manual_pct" for k in ("automatic", "picked") if k in kinds[name]]
    return cols


def _base(record: MeasuringSession, animal: Animal) -> dict:
    return {"animal_id": animal.id, "tag": animal.tag, "species": animal.species, "breed": animal.breed,
            "sex": animal.sex, "birth_date": animal.birth_date.isoformat() if animal.birth_date else None,
            "animal_status": animal.status, "session_id": record.id, "date": record.date.isoformat(),
            "operator": record.operator, "calibration_id": record.calibration_id}


def _iso(ts: dt.datetime) -> str:
    if ts.tzinfo is None:
        ts = ts.replace(tzinfo=dt.UTC)
    return ts.astimezone(dt.UTC).isoformat(timespec="seconds").replace("+00:00", "Z")
