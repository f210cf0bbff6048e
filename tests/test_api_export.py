"""GET /api/export/animals.csv: wide and long layouts, RFC 4180, formula neutralisation, filters."""

from __future__ import annotations

import csv
import io

import pytest

from app.routes.export import safe_cell, to_csv
from storage.db import session_scope
from storage.measurements import add_measurement
from tests.backend_support import backend_client, finished_calibration


@pytest.fixture(params=["sqlite", "postgresql"])
def client(request, tmp_path):
    with backend_client(request.param, tmp_path) as c:
        yield c


def herd(client) -> dict:
    """Two cattle (one with a hostile tag) and a sheep, measured on three dates."""
    engine = client.app.state.engine
    cal = finished_calibration(engine)
    ids = {}
    for tag, species, day, operator in [("=HYPERLINK(\"x\")", "Cattle", "2026-03-01", 'Ann "the tape", Smith'),
                                        ("DE 02", "cattle", "2026-04-01", "-Bob"),
                                        ("S1", "sheep", "2026-05-01", "Cy\nline two")]:
        a = client.post("/api/animals", json={"tag": tag, "species": species, "breed": "@mixed"}).json()
        s = client.post("/api/sessions", json={"animal_id": a["id"], "calibration_id": cal, "date": day,
                                               "operator": operator}).json()
        ids[tag] = s["id"]
    with session_scope(engine) as db:
        first = ids['=HYPERLINK("x")']
        add_measurement(db, session_id=first, name="body_length", kind="automatic", method="auto:side",
                        value_mm=1520.0, created_by="bodyscan")
        add_measurement(db, session_id=first, name="body_length", kind="manual", method="tape", value_mm=1600.0,
                        created_by="Ann")
        add_measurement(db, session_id=first, name="tail_length", kind="picked", method="polyline",
                        value_mm=701.5, created_by="Ann")
        add_measurement(db, session_id=ids["DE 02"], name="body_length", kind="manual", method="tape",
                        value_mm=1400.0)
        add_measurement(db, session_id=ids["S1"], name="wither height", kind="manual", value_mm=650.0)
    return ids


def read(client, **params) -> list[dict]:
    r = client.get("/api/export/animals.csv", params=params)
    assert r.status_code == 200, r.text
    assert r.headers["content-type"].startswith("text/csv") and "charset=utf-8" in r.headers["content-type"]
    assert "\r\n" in r.text
    return list(csv.DictReader(io.StringIO(r.content.decode("utf-8"), newline="")))


def test_wide_export_has_a_row_per_session_with_kinds_side_by_side(client):
    herd(client)
    rows = read(client)
    assert [r["tag"] for r in rows] == ["'=HYPERLINK(\"x\")", "DE 02", "S1"]
    first = rows[0]
    assert (first["date"], first["body_length_automatic_mm"], first["body_length_manual_mm"]) == (
        "2026-03-01", "1520.0", "1600.0")
    assert first["body_length_automatic_vs_manual_pct"] == "-5.0"  # negative numbers stay numbers
    assert first["tail_length_picked_mm"] == "701.5" and "tail_length_manual_mm" not in first
    assert first["operator"] == 'Ann "the tape", Smith'  # RFC 4180 quoting round-trips
    assert (rows[1]["operator"], rows[1]["breed"], rows[2]["operator"]) == ("'-Bob", "'@mixed", "Cy\nline two")
    assert rows[1]["body_length_automatic_mm"] == "" and rows[2]["wither height_manual_mm"] == "650.0"


def test_long_export_has_a_row_per_measurement_for_herd_software(client):
    herd(client)
    rows = read(client, format="long", species="CATTLE")
    assert [(r["tag"], r["name"], r["kind"], r["value_mm"], r["method"]) for r in rows] == [
        ("'=HYPERLINK(\"x\")", "body_length", "automatic", "1520.0", "auto:side"),
        ("'=HYPERLINK(\"x\")", "body_length", "manual", "1600.0", "tape"),
        ("'=HYPERLINK(\"x\")", "tail_length", "picked", "701.5", "polyline"),
        ("DE 02", "body_length", "manual", "1400.0", "tape"),
    ]
    assert rows[0]["who"] == "bodyscan" and rows[0]["when"].endswith("Z") and rows[0]["date"] == "2026-03-01"


def test_filters_select_species_and_a_date_range(client):
    herd(client)
    assert [r["tag"] for r in read(client, species="sheep")] == ["S1"]
    assert [r["tag"] for r in read(client, date_from="2026-03-15", date_to="2026-04-30")] == ["DE 02"]
    assert read(client, date_from="2027-01-01") == []
    bad = client.get("/api/export/animals.csv", params={"date_from": "March"})
    assert bad.status_code == 422 and "date_from" in bad.json()["message"]
    assert client.get("/api/export/animals.csv", params={"format": "xml"}).status_code == 422


def test_an_empty_database_exports_just_the_header(client):
    assert client.get("/api/export/animals.csv").text.startswith("animal_id,tag,species")
    assert client.get("/api/export/animals.csv", params={"bom": True}).content.startswith(b"\xef\xbb\xbfanimal_id")


@pytest.mark.parametrize(
    ("value", "cell"),
    [("=1+2", "'=1+2"), ("+SUM(A1)", "'+SUM(A1)"), ("-A1", "'-A1"), ("@cmd", "'@cmd"), ("\tx", "'\tx"),
     ("\rx", "'\rx"), ("-12.5", "-12.5"), ("+3", "+3"), (-4.25, -4.25), (0, 0), (None, ""), ("Ünïcode ok", "Ünïcode ok"),
     (True, "true")],
)
def test_cells_that_would_run_as_formulas_are_neutralised(value, cell):
    assert safe_cell(value) == cell


def test_csv_is_rfc_4180():
    text = to_csv(["a", "b"], [{"a": 'say "hi", then', "b": -1.5}, {"a": "x\ny"}])
    assert text == 'a,b\r\n"say ""hi"", then",-1.5\r\n"x\ny",\r\n'


def test_values_from_a_scan_that_warned_carry_its_warnings(client):
    """The scan's warnings (here: the animal cut by the picture's edge) follow its automatic value into
    both layouts; values without a scan, and sessions whose scans warned of nothing, have none."""
    import numpy as np

    from tests.backend_support import scan_with_cloud

    ids = herd(client)
    engine = client.app.state.engine
    first = ids['=HYPERLINK("x")']
    warning = "the animal reaches the bottom edge of the picture: part of it is probably out of view"
    scan_id = scan_with_cloud(engine, first, np.zeros((3, 3)), np.zeros(3, np.int64), np.zeros((3, 2)),
                              {"point_count": 3, "warnings": [warning, "=cmd"]})
    with session_scope(engine) as db:
        add_measurement(db, session_id=first, scan_id=scan_id, name="body_height", kind="automatic",
                        method="auto:side", value_mm=700.0, created_by="bodyscan")
    long = [r for r in read(client, format="long") if r["name"] == "body_height"]
    assert long[0]["scan_warnings"] == warning + " | =cmd"
    assert all(r["scan_warnings"] == "" for r in read(client, format="long") if r["name"] != "body_height")
    wide = {r["tag"]: r for r in read(client)}
    assert wide['\'=HYPERLINK("x")']["scan_warnings"] == warning + " | =cmd"
    assert wide["DE 02"]["scan_warnings"] == ""
