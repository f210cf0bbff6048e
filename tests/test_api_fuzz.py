"""No bad request gets a 5xx, and none of them changes what is stored."""

from __future__ import annotations

import json

import pytest
from fastapi.testclient import TestClient

from app.main import create_app
from tests.backend_support import backend_client, finished_calibration, png, settings_for, zip_bytes

RIG = {"board_cols": "9", "board_rows": "6", "square_mm": "25", "stripes": "40"}


def bad_requests(sid: int, aid: int) -> list[tuple[str, str, dict]]:
    garbage = [b"", b"\x00" * 10, b"\x89PNG\r\n\x1a\n" + b"\xff" * 50, png()[:40], "ünï".encode(), b"PK\x05\x06" + b"\0" * 18]
    out = []
    for blob in garbage:
        out.append(("POST", "/api/calibrations", {"files": [("files", ("calib/pose_01_board.png", blob))], "data": RIG}))
        out.append(("POST", "/api/calibrations", {"files": {"archive": ("a.zip", blob)}}))
        out.append(("POST", f"/api/sessions/{sid}/scans", {"files": {"image": ("s.png", blob)}, "data": {"view": "side"}}))
    names = ["", "/etc/passwd", "calib/../../x.png", "ü/pose_01_board.png", "a" * 300]
    for name in names:
        out.append(("POST", "/api/calibrations", {"files": [("files", (name, png()))], "data": RIG}))
    out += [
        ("POST", "/api/calibrations", {"files": {"archive": ("a.zip", zip_bytes({"rig.json": json.dumps({"stripes": -1}).encode()}))}}),
        ("POST", "/api/calibrations", {"files": {"archive": ("a.zip", zip_bytes({"rig.json": b"[1,2]", "calib/pose_01_board.png": png()}))}}),
        ("POST", "/api/calibrations", {"files": [("files", ("calib/pose_01_board.png", png()))],
                                       "data": {**RIG, "square_mm": "inf"}}),
        ("POST", "/api/calibrations", {"files": [("files", ("calib/pose_01_board.png", png()))],
                                       "data": {**RIG, "board_cols": "99999999999999999999"}}),
        ("POST", "/api/calibrations", {"content": b"--x\r\nnot multipart", "headers": {"content-type": "multipart/form-data; boundary=x"}}),
        ("POST", "/api/animals", {"content": b"{not json", "headers": {"content-type": "application/json"}}),
        ("POST", "/api/animals", {"json": {"tag": "x" * 500}}),
        ("POST", "/api/animals", {"json": {"tag": "ok", "birth_date": "2024-02-30"}}),
        ("POST", "/api/animals", {"json": ["tag"]}),
        ("PATCH", f"/api/animals/{aid}", {"json": {"tag": None, "sex": None}}),
        ("PATCH", f"/api/animals/{aid}", {"json": {"tag": ""}}),
        ("GET", "/api/animals/abc", {}),
        ("GET", "/api/animals/99999999999999999999999", {}),
        ("GET", "/api/animals?limit=-1", {}),
        ("DELETE", "/api/animals/424242", {}),
        ("POST", "/api/sessions", {"json": {"animal_id": aid, "calibration_id": "x"}}),
        ("POST", "/api/sessions", {"json": {"animal_id": aid, "calibration_id": 1, "date": "31.12.2025"}}),
        ("GET", "/api/sessions/0", {}),
        ("POST", f"/api/sessions/{sid}/measurements", {"json": {"name": "\x00", "kind": "manual", "value_mm": 1}}),
        ("POST", f"/api/sessions/{sid}/measurements", {"json": {"name": "a", "kind": "manual", "value_mm": "1e999"}}),
        ("POST", f"/api/sessions/{sid}/measurements", {"json": {"name": "a", "kind": "polyline", "scan_id": 1,
                                                               "points": [[1e308, 1e308, 1e308]] * 3}}),
        ("POST", f"/api/sessions/{sid}/measurements", {"json": {"name": "a", "kind": "distance", "scan_id": 1,
                                                               "points": [[0, 0, 0], [1, 1, 1]]}}),
        ("GET", "/api/scans/1/cloud.ply", {}),
        ("GET", "/api/scans/-1", {}),
        ("GET", "/api/jobs/0", {}),
        ("GET", "/api/export/animals.csv?date_to=2026-13-01", {}),
        ("DELETE", "/api/measurements/999", {}),
        ("PATCH", f"/api/animals/{aid}", {"json": {"tag": "   "}}),
    ]
    return out


@pytest.mark.parametrize("backend", ["sqlite", "postgresql"])
def test_bad_requests_get_4xx_and_leave_stored_data_intact(backend, tmp_path):
    with backend_client(backend, tmp_path, max_upload_mb=2) as client:
        cal = finished_calibration(client.app.state.engine)
        a = client.post("/api/animals", json={"tag": "KEEP", "species": "cattle"}).json()
        s = client.post("/api/sessions", json={"animal_id": a["id"], "calibration_id": cal}).json()
        m = client.post(f"/api/sessions/{s['id']}/measurements", json={"name": "girth", "kind": "manual", "value_mm": 1800})
        before = [client.get(p).json() for p in (f"/api/sessions/{s['id']}", "/api/calibrations", "/api/animals")]
        statuses = []
        for method, path, kwargs in bad_requests(s["id"], a["id"]):
            r = client.request(method, path, **kwargs)
            statuses.append((method, path, r.status_code))
            assert 400 <= r.status_code < 500, (method, path, str(kwargs)[:200], r.status_code, r.text[:300])
            assert "detail" in r.json()
        after = [client.get(p).json() for p in (f"/api/sessions/{s['id']}", "/api/calibrations", "/api/animals")]
        assert after == before
        assert m.status_code == 201


@pytest.mark.parametrize("size_mb", [3])
def test_a_request_larger_than_the_limit_is_413_before_it_is_read(tmp_path, size_mb):
    with TestClient(create_app(settings_for(tmp_path, max_upload_mb=2))) as client:
        body = b"x" * (size_mb << 20)
        r = client.post("/api/calibrations", files={"archive": ("a.zip", body)})
        assert r.status_code == 413 and "limit of 2 MB" in r.json()["detail"]
