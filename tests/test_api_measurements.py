"""Picked and manual measurements: snapping onto the scan surface, corrections and their audit trail."""

from __future__ import annotations

import numpy as np
import pytest

from storage.db import session_scope
from storage.measurements import add_measurement
from tests.backend_support import backend_client, finished_calibration, scan_with_cloud
from tests.test_surface import DEPTH, RADIUS, cylinder_scan, helix, helix_length, radial_offset


@pytest.fixture(params=["sqlite", "postgresql"])
def client(request, tmp_path):
    with backend_client(request.param, tmp_path) as c:
        yield c


@pytest.fixture
def scanned(client):
    """(session id, scan id) of a session whose side scan is a sampled cylinder (radius 150 mm)."""
    engine = client.app.state.engine
    cal = finished_calibration(engine)
    a = client.post("/api/animals", json={"tag": "C1", "species": "cattle"}).json()
    s = client.post("/api/sessions", json={"animal_id": a["id"], "calibration_id": cal}).json()
    points, stripe, uv = cylinder_scan()
    return s["id"], scan_with_cloud(engine, s["id"], points, stripe, uv)


def radius_of(points) -> np.ndarray:
    p = np.asarray(points)
    return np.linalg.norm(p[:, 1:] - [0.0, DEPTH], axis=1)


def post(client, session_id, **body):
    return client.post(f"/api/sessions/{session_id}/measurements", json=body)


def test_a_picked_distance_is_measured_between_picks_snapped_onto_the_surface(client, scanned):
    sid, scan = scanned
    truth = radial_offset(np.array([[7.5, 0.0, 0.0], [97.5, 0.0, 0.0]]) + [0, 0, DEPTH - RADIUS], 0.0)
    picks = radial_offset(truth, 5.0)  # clicked 5 mm in front of the skin
    r = post(client, sid, name="neck_width", kind="distance", points=picks.tolist(), scan_id=scan, created_by="Ann")
    assert r.status_code == 201, r.text
    m = r.json()
    assert (m["kind"], m["method"], m["created_by"], m["scan_id"]) == ("picked", "distance", "Ann", scan)
    assert np.abs(radius_of(m["points"]) - RADIUS).max() < 0.2
    assert m["value_mm"] == pytest.approx(90.0, abs=0.3)
    assert m["picked_points"] == picks.tolist()
    assert m["software_version"] and m["calibration_id"] is not None


def test_a_picked_polyline_follows_the_surface(client, scanned):
    sid, scan = scanned
    r = post(client, sid, name="tail_length", kind="polyline", points=radial_offset(helix(6), 2.0).tolist(), scan_id=scan)
    assert r.status_code == 201, r.text
    assert r.json()["value_mm"] == pytest.approx(helix_length(), rel=0.01)


@pytest.mark.parametrize(
    ("body", "status", "message"),
    [
        ({"kind": "distance", "points": [[0, 0, 1350], [0, 50, 1360], [0, 60, 1370]]}, 422, "exactly 2 points"),
        ({"kind": "polyline", "points": [[0, 0, 1350]]}, 422, "at least 2 points"),
        ({"kind": "distance", "points": [[0, 0, 1000], [10, 0, 1350]]}, 422, "points[0]"),
        ({"kind": "distance", "points": [[0, 0], [10, 0]]}, 422, "points"),
        ({"kind": "distance", "points": [[0, 0, "NaN"], [10, 0, 1350]]}, 422, "points"),
        ({"kind": "distance", "points": [[0, 0, 1350], [10, 0, 1350]], "scan_id": None}, 422, "scan_id is required"),
        ({"kind": "distance", "points": [[0, 0, 1350], [10, 0, 1350]], "scan_id": 999}, 404, "scan 999 not found"),
        ({"kind": "manual"}, 422, "value_mm is required"),
        ({"kind": "manual", "value_mm": -3}, 422, "value_mm"),
        ({"kind": "spline", "points": [[0, 0, 1350], [10, 0, 1350]]}, 422, "kind"),
    ],
)
def test_bad_measurements_are_refused_with_the_reason(client, scanned, body, status, message):
    sid, scan = scanned
    payload = {"name": "x", "scan_id": scan, **body}
    r = post(client, sid, **payload)
    assert r.status_code == status, r.text
    assert message in (r.json().get("message") or r.json()["detail"])
    assert client.get(f"/api/sessions/{sid}/measurements").json() == []


def test_a_scan_of_another_session_cannot_be_used(client, scanned):
    sid, scan = scanned
    other = client.post("/api/sessions", json={"animal_id": 1, "calibration_id": 1}).json()
    r = post(client, other["id"], name="x", kind="distance", points=[[0, 0, 1350], [10, 0, 1350]], scan_id=scan)
    assert r.status_code == 422 and f"scan {scan} belongs to session {sid}" in r.json()["detail"]


def test_corrections_are_appended_and_the_history_shown(client, scanned):
    sid, scan = scanned
    first = post(client, sid, name="tail_length", kind="polyline", points=radial_offset(helix(4), 1.0).tolist(),
                 scan_id=scan, created_by="Ann").json()
    fixed = client.patch(f"/api/measurements/{first['id']}", json={
        "points": radial_offset(helix(9), 1.0).tolist(), "note": "more points", "created_by": "Bob"})
    assert fixed.status_code == 200, fixed.text
    tape = post(client, sid, name="tail_length", kind="manual", value_mm=500, created_by="Ann").json()
    client.patch(f"/api/measurements/{tape['id']}", json={"value_mm": 505, "created_by": "Bob", "note": "re-taped"})
    assert client.delete(f"/api/measurements/{tape['id']}", params={"by": "Cy", "note": "wrong animal"}).status_code == 204

    current = client.get(f"/api/sessions/{sid}/measurements").json()
    assert [(m["kind"], m["revision"], m["created_by"]) for m in current] == [("picked", 2, "Bob")]
    trail = client.get(f"/api/measurements/{tape['id']}/history").json()
    assert [(m["value_mm"], m["created_by"], m["deleted"], m["note"]) for m in trail] == [
        (500.0, "Ann", False, ""), (505.0, "Bob", False, "re-taped"), (505.0, "Cy", True, "wrong animal")]
    assert len(client.get(f"/api/sessions/{sid}/measurements", params={"history": True}).json()) == 5


def test_corrections_must_fit_the_kind_and_automatic_values_are_not_edited(client, scanned):
    sid, scan = scanned
    with session_scope(client.app.state.engine) as db:
        auto = add_measurement(db, session_id=sid, scan_id=scan, name="body_length", kind="automatic",
                               method="auto:side", value_mm=1500.0)
    r = client.patch(f"/api/measurements/{auto.id}", json={"value_mm": 1400})
    assert r.status_code == 409 and "not edited" in r.json()["detail"]
    tape = post(client, sid, name="height", kind="manual", value_mm=1300).json()
    r = client.patch(f"/api/measurements/{tape['id']}", json={"points": [[0, 0, 1350], [1, 0, 1350]]})
    assert r.status_code == 422 and "corrected with value_mm" in r.json()["detail"]
    assert client.patch("/api/measurements/999", json={"value_mm": 1}).status_code == 404
