"""POST/GET /api/calibrations and /api/jobs: uploads are checked at once, bad ones answered with 4xx."""

from __future__ import annotations

import json

import pytest
from sqlmodel import Session, func, select

from storage.models import Blob, Calibration
from tests.backend_support import backend_client, png, zip_bytes

RIG = {"board_cols": 9, "board_rows": 6, "square_mm": 25.0, "stripes": 40}


@pytest.fixture(params=["sqlite", "postgresql"])
def client(request, tmp_path):
    with backend_client(request.param, tmp_path, max_upload_mb=1) as c:
        yield c


def pose_files(n: int = 3, folder: str = "calib/") -> list[tuple[str, tuple[str, bytes, str]]]:
    out = []
    for i in range(1, n + 1):
        out.append(("files", (f"{folder}pose_{i:02d}_board.png", png(), "image/png")))
        out.append(("files", (f"{folder}pose_{i:02d}_stripes.png", png(value=60), "image/png")))
    return out


def stored_calibrations(client) -> int:
    with Session(client.app.state.engine) as db:
        return db.exec(select(func.count()).select_from(Calibration)).one()


def test_pose_images_with_rig_fields_are_accepted_and_queued(client):
    r = client.post("/api/calibrations", files=pose_files(), data={**RIG, "name": "barn A"})
    assert r.status_code == 202, r.text
    ids = r.json()
    cal = client.get(f"/api/calibrations/{ids['id']}").json()
    assert (cal["status"], cal["name"], cal["job_id"], cal["square_mm"]) == ("queued", "barn A", ids["job_id"], 25.0)
    assert cal["files"][:2] == ["calib/pose_01_board.png", "calib/pose_01_stripes.png"]
    job = client.get(f"/api/jobs/{ids['job_id']}").json()
    assert {k: job[k] for k in ("id", "kind", "status", "progress", "stage", "error", "result_id")} == {
        "id": ids["job_id"], "kind": "calibration", "status": "queued", "progress": 0.0, "stage": "queued",
        "error": None, "result_id": ids["id"]}


def test_a_zip_takes_its_rig_from_rig_json_and_form_fields_override_it(client):
    files = {"capture/rig.json": json.dumps(RIG).encode(), "capture/calib/pose_01_board.png": png(),
             "capture/calib/pose_01_stripes.png": png(), "capture/scan/side.png": png()}
    r = client.post("/api/calibrations", files={"archive": ("cap.zip", zip_bytes(files))}, data={"stripes": "32"})
    assert r.status_code == 202, r.text
    cal = client.get(f"/api/calibrations/{r.json()['id']}").json()
    assert (cal["board_cols"], cal["stripes"], cal["files"]) == (9, 32, ["archive.zip"])


def test_bare_pose_names_and_rig_json_among_the_files_work(client):
    files = pose_files(2, folder="") + [("files", ("rig.json", json.dumps(RIG).encode(), "application/json"))]
    r = client.post("/api/calibrations", files=files)
    assert r.status_code == 202, r.text


@pytest.mark.parametrize(
    ("kwargs", "status", "message"),
    [
        ({"files": [("files", ("calib/pose_01_board.png", b"not an image"))]}, 422,
         "pose_01_board.png: not a readable image"),
        ({"files": [("files", ("calib/pose_01_board.png", png()[:-30]))]}, 422, "pose_01_board.png: "),
        ({"files": [("files", ("calib/board1.png", png()))]}, 422, "calib/board1.png: calibration images must be named"),
        ({"files": [("files", ("../../etc/pose_01_board.png", png()))]}, 422, "'..' are not allowed"),
        ({"files": [("files", ("calib/pose_01_board.png", b""))]}, 422, "file is empty"),
        ({"files": [("files", ("calib/pose_01_board.png", png())), ("files", ("calib/pose_01_board.png", png()))]},
         422, "uploaded twice"),
        ({"files": [("files", ("calib/pose_01_stripes.png", png()))]}, 422, "no matching pose_01_board"),
        ({"files": [("files", ("scan/side.png", png()))]}, 422, "no calibration images"),
        ({"archive": ("cap.zip", b"PK\x03\x04 broken")}, 422, "archive: not a zip file"),
        ({"archive": ("cap.zip", zip_bytes({"rig.json": json.dumps(RIG).encode(), "../pose_01_board.png": png()}))},
         422, "unsafe path"),
        ({"archive": ("cap.zip", zip_bytes({"rig.json": json.dumps(RIG).encode(), "/abs/pose_01_board.png": png()}))},
         422, "unsafe path"),
        ({"archive": ("cap.zip", zip_bytes({"rig.json": json.dumps(RIG).encode(), "calib/p1.png": png()}))},
         422, "calib/p1.png"),
        ({"archive": ("cap.zip", zip_bytes({"rig.json": b"{oops", "calib/pose_01_board.png": png()}))},
         422, "rig.json: not valid JSON"),
        ({"archive": ("cap.zip", zip_bytes({"calib/pose_01_board.png": png()}))}, 422, "rig settings missing: board_cols"),
    ],
)
def test_bad_captures_get_a_4xx_naming_the_file_and_store_nothing(client, kwargs, status, message):
    if "archive" in kwargs:
        r = client.post("/api/calibrations", files={"archive": kwargs["archive"]})
    else:
        r = client.post("/api/calibrations", files=kwargs["files"], data=RIG)
    assert r.status_code == status, r.text
    assert message in r.json()["detail"]
    assert stored_calibrations(client) == 0


def test_missing_rig_settings_are_listed(client):
    r = client.post("/api/calibrations", files=pose_files(1), data={"board_cols": 9})
    assert r.status_code == 422
    assert r.json()["detail"].startswith("rig settings missing: board_rows, square_mm, stripes")


def test_invalid_rig_values_name_the_field(client):
    r = client.post("/api/calibrations", files=pose_files(1), data={**RIG, "board_cols": 1})
    assert r.status_code == 422
    assert "board_cols: Input should be greater than or equal to 2" in r.json()["message"]
    rig_json = json.dumps({**RIG, "board_rows": 1}).encode()
    r = client.post("/api/calibrations", files={"archive": ("c.zip", zip_bytes({"rig.json": rig_json,
                                                                                  "calib/pose_01_board.png": png()}))})
    assert r.status_code == 422
    assert "rig.json: board_rows must be an integer >= 2" in r.json()["detail"]
    r = client.post("/api/calibrations", files=pose_files(1), data={**RIG, "square_mm": "twenty"})
    assert r.status_code == 422
    assert "square_mm" in r.json()["message"]


def test_the_camera_s_display_gamma_comes_from_the_form_or_rig_json_and_is_checked(client):
    """A camera writing sRGB-like images is calibrated with camera_gamma 2.2 (linear, 1.0, by default): the
    record keeps it for the scans; an implausible value is refused, naming the field, and nothing is stored."""
    r = client.post("/api/calibrations", files=pose_files(1), data=RIG)
    assert client.get(f"/api/calibrations/{r.json()['id']}").json()["camera_gamma"] == 1.0
    r = client.post("/api/calibrations", files=pose_files(1), data={**RIG, "camera_gamma": "2.2"})
    assert r.status_code == 202, r.text
    assert client.get(f"/api/calibrations/{r.json()['id']}").json()["camera_gamma"] == 2.2
    rig_json = json.dumps({**RIG, "camera_gamma": 1.8}).encode()
    r = client.post("/api/calibrations", files={"archive": ("c.zip", zip_bytes({"rig.json": rig_json,
                                                                                  "calib/pose_01_board.png": png()}))})
    assert client.get(f"/api/calibrations/{r.json()['id']}").json()["camera_gamma"] == 1.8
    before = stored_calibrations(client)
    r = client.post("/api/calibrations", files=pose_files(1), data={**RIG, "camera_gamma": "9"})
    assert r.status_code == 422 and "camera_gamma" in r.json()["message"]
    rig_json = json.dumps({**RIG, "camera_gamma": "sRGB"}).encode()
    r = client.post("/api/calibrations", files={"archive": ("c.zip", zip_bytes({"rig.json": rig_json,
                                                                                  "calib/pose_01_board.png": png()}))})
    assert r.status_code == 422 and "rig.json: camera_gamma must be a number" in r.json()["detail"]
    assert stored_calibrations(client) == before


def test_files_and_archive_together_or_neither_are_refused(client):
    both = pose_files(1) + [("archive", ("c.zip", zip_bytes({"rig.json": b"{}"})))]
    for files in (both, None):
        r = client.post("/api/calibrations", files=files, data=RIG)
        assert r.status_code == 422
        assert "either the pose images as 'files' or one zip" in r.json()["detail"]


def test_an_oversize_upload_is_refused_with_413_and_the_limit(client):
    big = png() + b"\0" * (1_100_000)
    r = client.post("/api/calibrations", files=[("files", ("calib/pose_01_board.png", big))], data=RIG)
    assert r.status_code == 413
    assert "limit of 1 MB" in r.json()["detail"] and "BODYSCAN_MAX_UPLOAD_MB" in r.json()["detail"]
    assert stored_calibrations(client) == 0


def test_uploaded_images_are_kept_byte_for_byte_in_the_database(client):
    image = png(80, 60)
    r = client.post("/api/calibrations", files=[("files", ("calib/pose_01_board.png", image))], data=RIG)
    with Session(client.app.state.engine) as db:
        from storage.calibrations import calibration_files

        assert calibration_files(db, r.json()["id"]) == {"calib/pose_01_board.png": image}
        assert db.exec(select(func.count()).select_from(Blob)).one() == 1


def test_unknown_ids_are_404(client):
    for path in ("/api/calibrations/77", "/api/jobs/77"):
        r = client.get(path)
        assert r.status_code == 404
        assert "77 not found" in r.json()["detail"]
