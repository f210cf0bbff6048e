"""CSV export of sessions and measurements for spreadsheets and herd-management software.

UTF-8, RFC 4180 (CRLF line ends, quotes doubled, fields with separators quoted by the csv module).
Text cells that a spreadsheet would run as a formula (starting with = + - @, tab or CR) get a leading
apostrophe; numbers stay numbers, negative ones included.
"""

from __future__ import annotations

import csv
import datetime as dt
import io
import re
from typing import Literal

from fastapi import APIRouter, Query, Response

from app.deps import DbDep
from storage.export import ExportFilter, long_rows, wide_rows

router = APIRouter(prefix="/export", tags=["export"])
FORMULA_START = ("=", "+", "-", "@", "\t", "\r")
PLAIN_NUMBER = re.compile(r"^[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?$")


@router.get("/animals.csv", response_class=Response,
            responses={200: {"content": {"text/csv": {}}, "description": "CSV, UTF-8"}})
def export_csv(
    db: DbDep,
    format: Literal["wide", "long"] = Query("wide", description="wide: a row per session; long: a row per measurement"),
    species: str | None = Query(None, description="only this species (case-insensitive)"),
    date_from: dt.date | None = Query(None, description="first session date, ISO (inclusive)"),
    date_to: dt.date | None = Query(None, description="last session date, ISO (inclusive)"),
    animal_id: int | None = None,
    bom: bool = Query(False, description="start with a UTF-8 byte-order mark (helps old Excel)"),
) -> Response:
    """Sessions with their measurements in mm (wide) or one measurement per row (long)."""
    flt = ExportFilter(species=species, date_from=date_from, date_to=date_to, animal_id=animal_id)
    header, rows = (wide_rows if format == "wide" else long_rows)(db, flt)
    text = to_csv(header, rows)
    name = f"bodyscan_{format}_{dt.date.today().isoformat()}.csv"
    return Response(("\ufeff" if bom else "") + text, media_type="text/csv; charset=utf-8",
                    headers={"Content-Disposition": f'attachment; filename="{name}"'})


def to_csv(header: list[str], rows: list[dict]) -> str:
    """RFC 4180 text: header line, then the rows' values in header order (missing values empty)."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\r\n")
    writer.writerow([safe_cell(h) for h in header])
    for row in rows:
        writer.writerow([safe_cell(row.get(h)) for h in header])
    return buf.getvalue()


def safe_cell(value) -> str | int | float:
    """A cell value that a spreadsheet shows as text, never runs; numbers pass through."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return value
    text = str(value)
    if text.startswith(FORMULA_START) and not PLAIN_NUMBER.match(text):
        return "'" + text
    return text
