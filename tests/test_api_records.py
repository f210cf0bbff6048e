"""Animals, sessions and scan uploads through the REST API."""

from __future__ import annotations

import pytest
from sqlmodel import Session, select

from storage.db import session_scope
from storage.jobs import claim_next, finish_job
from storage.models import Scan
from tests.backend_support import backend_client, finished_calibration, png

RIG = {"board_cols": 9, "board_rows": 6, "square_mm": 25.0, "stripes": 40}


@pytest.fixture(params=["sqlite", "postgresql"])
def client(request, tmp_path):
    with backend_client(request.param, tmp_path) as c:
        yield c


def engine_of(client):
    return client.app.state.engine


def animal(client, tag="A1", **fields) -> dict:
    r = client.post("/api/animals", json={"tag": tag, **fields})
    assert r.status_code == 201, r.text
    return r.json()


def session_for(client, calibration_id: int, tag="A1") -> dict:
    a = animal(client, tag, species="cattle")
    r = client.post("/api/sessions", json={"animal_id": a["id"], "calibration_id": calibration_id,
                                           "date": "2026-05-04", "operator": "Ann"})
    assert r.status_code == 201, r.text
    return r.json()


def queued_calibration(client) -> int:
    files = [("files", ("calib/pose_01_board.png", png()))]
    return client.post("/api/calibrations", files=files, data=RIG).json()["id"]


def test_animal_records_can_be_created_listed_changed_and_deleted(client):
    a = animal(client, "DE 0123", species="Cattle", breed="Holstein", sex="female", birth_date="2023-03-01")
    animal(client, "DE 0999", species="sheep")
    assert [x["tag"] for x in client.get("/api/animals", params={"species": "cattle"}).json()] == ["DE 0123"]
    assert [x["tag"] for x in client.get("/api/animals", params={"tag": "999"}).json()] == ["DE 0999"]
    r = client.patch(f"/api/animals/{a['id']}", json={"status": "sold", "notes": "to farm B"})
    assert (r.json()["status"], r.json()["breed"], r.json()["birth_date"]) == ("sold", "Holstein", "2023-03-01")
    assert client.delete(f"/api/animals/{a['id']}").status_code == 204
    assert client.get(f"/api/animals/{a['id']}").status_code == 404


@pytest.mark.parametrize(
    ("payload", "field"),
    [({"tag": ""}, "tag"), ({"tag": "   "}, "tag"), ({"tag": "X", "sex": "robot"}, "sex"),
     ({"tag": "X", "birth_date": "yesterday"}, "birth_date"), ({"tag": "X", "colour": "red"}, "colour"),
     ({}, "tag")],
)
def test_invalid_animal_fields_are_422_naming_the_field(client, payload, field):
    r = client.post("/api/animals", json=payload)
    assert r.status_code == 422
    assert field in r.json()["message"]


def test_duplicate_tags_are_409_and_animals_with_sessions_are_kept(client):
    cal = finished_calibration(engine_of(client))
    s = session_for(client, cal, "T1")
    r = client.post("/api/animals", json={"tag": "T1"})
    assert (r.status_code, r.json()["detail"]) == (409, "animal tag 'T1' already exists")
    r = client.delete(f"/api/animals/{s['animal_id']}")
    assert r.status_code == 409 and "set its status" in r.json()["detail"]
    assert client.get(f"/api/animals/{s['animal_id']}").status_code == 200


def test_sessions_need_an_existing_animal_and_a_calibration_that_did_not_fail(client):
    cal = finished_calibration(engine_of(client))
    a = animal(client)
    assert client.post("/api/sessions", json={"animal_id": 99, "calibration_id": cal}).status_code == 404
    r = client.post("/api/sessions", json={"animal_id": a["id"], "calibration_id": 99})
    assert (r.status_code, r.json()["detail"]) == (404, "calibration 99 not found")
    pending = queued_calibration(client)
    assert client.post("/api/sessions", json={"animal_id": a["id"], "calibration_id": pending}).status_code == 201


def test_a_session_shows_its_animal_scans_and_measurements(client):
    cal = finished_calibration(engine_of(client))
    s = session_for(client, cal)
    client.post(f"/api/sessions/{s['id']}/scans", files={"image": ("side.png", png(640, 427))}, data={"view": "side"})
    client.post(f"/api/sessions/{s['id']}/measurements", json={"name": "heart_girth", "kind": "manual",
                                                              "value_mm": 1830})
    detail = client.get(f"/api/sessions/{s['id']}").json()
    assert (detail["date"], detail["operator"], detail["animal"]["tag"]) == ("2026-05-04", "Ann", "A1")
    assert [(x["view"], x["status"]) for x in detail["scans"]] == [("side", "queued")]
    assert [(m["name"], m["value_mm"]) for m in detail["measurements"]] == [("heart_girth", 1830.0)]


def test_a_scan_upload_is_queued_and_its_image_kept(client):
    cal = finished_calibration(engine_of(client))
    s = session_for(client, cal)
    image = png(640, 427)
    r = client.post(f"/api/sessions/{s['id']}/scans", files={"image": ("cow 1.png", image)}, data={"view": "top"})
    assert r.status_code == 202, r.text
    scan = client.get(f"/api/scans/{r.json()['id']}").json()
    assert (scan["status"], scan["view"], scan["job_id"], scan["point_count"]) == ("queued", "top", r.json()["job_id"], None)
    got = client.get(f"/api/scans/{scan['id']}/image")
    assert got.content == image and "cow 1.png" in got.headers["content-disposition"]
    r = client.get(f"/api/scans/{scan['id']}/cloud.ply")
    assert r.status_code == 409 and "no point cloud yet" in r.json()["detail"]


def test_scans_against_an_unfinished_or_failed_calibration_are_409(client):
    pending = queued_calibration(client)
    s = session_for(client, pending)
    r = client.post(f"/api/sessions/{s['id']}/scans", files={"image": ("side.png", png(640, 427))})
    assert r.status_code == 409 and "still queued" in r.json()["detail"]
    engine = engine_of(client)
    job = claim_next(engine, "w:1")
    with session_scope(engine) as db:
        finish_job(db, job.id, "w:1", error="pose_03_board.png: chessboard 9x6 not found")
    r = client.post(f"/api/sessions/{s['id']}/scans", files={"image": ("side.png", png(640, 427))})
    assert r.status_code == 409
    assert "failed (pose_03_board.png: chessboard 9x6 not found)" in r.json()["detail"]
    with Session(engine) as db:
        assert db.exec(select(Scan)).all() == []


@pytest.mark.parametrize(
    ("files", "data", "message"),
    [
        ({"image": ("side.png", b"GIF89a nonsense")}, {"view": "side"}, "side.png: not a readable image"),
        ({"image": ("side.png", png(640, 427)[:-40])}, {"view": "side"}, "side.png: "),
        ({"image": ("side.png", png(320, 240))}, {"view": "side"}, "side.png: image is 320x240 but calibration"),
        ({"image": ("side.png", png(640, 427))}, {"view": "underneath"}, "view 'underneath' unknown"),
        ({"image": ("side.png", b"")}, {"view": "side"}, "file is empty"),
    ],
)
def test_bad_scan_uploads_are_422_with_a_clear_message(client, files, data, message):
    s = session_for(client, finished_calibration(engine_of(client)))
    r = client.post(f"/api/sessions/{s['id']}/scans", files=files, data=data)
    assert r.status_code == 422, r.text
    assert message in r.json()["detail"]
    assert client.get(f"/api/sessions/{s['id']}").json()["scans"] == []


def test_a_scan_for_an_unknown_session_is_404(client):
    r = client.post("/api/sessions/5/scans", files={"image": ("side.png", png())})
    assert (r.status_code, r.json()["detail"]) == (404, "session 5 not found")


def test_failed_jobs_are_listed_and_can_be_retried_on_their_stored_uploads(client):
    engine = engine_of(client)
    cal = queued_calibration(client)
    job = claim_next(engine, "w:1")
    with session_scope(engine) as db:
        finish_job(db, job.id, "w:1", error="the job was interrupted 3 times")
    failed = client.get("/api/jobs", params={"status": "failed"}).json()
    assert [(j["id"], j["kind"]) for j in failed] == [(job.id, "calibration")]
    r = client.post(f"/api/jobs/{job.id}/retry")
    assert r.status_code == 202 and (r.json()["status"], r.json()["attempts"], r.json()["error"]) == ("queued", 0, None)
    assert client.get(f"/api/calibrations/{cal}").json()["status"] == "queued"
    r = client.post(f"/api/jobs/{job.id}/retry")
    assert r.status_code == 409 and "only failed jobs" in r.json()["detail"]


def test_the_openapi_document_lists_the_contract_paths(client):
    paths = client.get("/openapi.json").json()["paths"]
    for path in ("/api/health", "/api/calibrations", "/api/calibrations/{calibration_id}", "/api/jobs/{job_id}",
                 "/api/animals", "/api/animals/{animal_id}", "/api/sessions", "/api/sessions/{session_id}",
                 "/api/sessions/{session_id}/scans", "/api/scans/{scan_id}", "/api/scans/{scan_id}/cloud.ply",
                 "/api/sessions/{session_id}/measurements", "/api/export/animals.csv"):
        assert path in paths
    assert client.get("/docs").status_code == 200


def test_an_ambient_image_is_kept_with_the_scan_and_must_match_its_size(client):
    s = session_for(client, finished_calibration(engine_of(client)))
    files = {"image": ("side.png", png(640, 427)), "ambient": ("side_ambient.png", png(320, 240))}
    r = client.post(f"/api/sessions/{s['id']}/scans", files=files, data={"view": "side"})
    assert r.status_code == 422 and "side_ambient.png: the ambient image must have the size of side.png" in r.json()["detail"]
    dark = png(640, 427, value=30)
    files["ambient"] = ("side_ambient.png", dark)
    r = client.post(f"/api/sessions/{s['id']}/scans", files=files, data={"view": "side"})
    assert r.status_code == 202, r.text
    with Session(engine_of(client)) as db:
        from storage.sessions import scan_ambient

        assert scan_ambient(db, r.json()["id"]) == dark


def test_a_session_date_operator_and_notes_can_be_corrected(client):
    s = session_for(client, finished_calibration(engine_of(client)))
    r = client.patch(f"/api/sessions/{s['id']}", json={"date": "2026-05-05", "notes": "calm animal"})
    assert r.status_code == 200, r.text
    assert (r.json()["date"], r.json()["operator"], r.json()["notes"]) == ("2026-05-05", "Ann", "calm animal")
    for body in ({"animal_id": 2}, {"operator": None}, {"date": "soon"}):
        assert client.patch(f"/api/sessions/{s['id']}", json=body).status_code == 422


def test_an_accepted_upload_is_committed_before_the_answer_arrives(client):
    # The session dependency commits inside the request: the job of a 202 is visible at once.
    accepted = client.post("/api/calibrations", files=[("files", ("calib/pose_01_board.png", png()))], data=RIG)
    assert client.get(f"/api/jobs/{accepted.json()['job_id']}").status_code == 200


def test_health_reports_the_queue(client):
    queued_calibration(client)
    body = client.get("/api/health").json()
    assert body["status"] == "ok" and body["jobs"] == {"queued": 1, "running": 0}
    assert body["workers"] == {"expected": 0, "alive": 0}  # the test app runs no worker processes


def test_a_frame_the_scan_refuses_fails_its_job_naming_the_uploaded_file(client, small_capture, tmp_path):
    """A glare frame passes the upload's checks (readable, the calibration's size) and is refused by the
    scan job: the job's error names the uploaded file, not just "image"."""
    import json

    from app.jobs import run_until_idle
    from storage import calibrations
    from tests.backend_support import settings_for

    truth = json.loads((small_capture / "truth" / "truth.json").read_text())
    w, h = truth["image_size"]
    engine = engine_of(client)
    cal_id = finished_calibration(engine, image_size=(w, h))
    with session_scope(engine) as db:
        calibrations.store_result(db, cal_id, truth)
    s = session_for(client, cal_id)
    r = client.post(f"/api/sessions/{s['id']}/scans", files={"image": ("glare.png", png(w, h, 255))},
                    data={"view": "side"})
    assert r.status_code in (201, 202), r.text
    assert run_until_idle(engine, settings_for(tmp_path)) == 1
    failed = client.get("/api/jobs", params={"status": "failed"}).json()
    assert len(failed) == 1
    assert failed[0]["error"].startswith("glare.png: more than half of the image is saturated"), failed[0]["error"]
