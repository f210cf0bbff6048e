"""End to end over HTTP: a real ``bodyscan serve`` (uvicorn + one worker process, SQLite file) driven like a
technician would: upload a simulated capture, calibrate, create an animal and a session, scan, pick and
tape measurements, download the PLY and the CSV, and compare everything with the simulator's truth.

Small on purpose (640x427 images, 8 poses) so it runs in well under two minutes on two cores.
"""

from __future__ import annotations

import csv
import importlib
import io
import json
import os
import socket
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import httpx
import numpy as np
import pytest
from scipy.spatial import cKDTree

ROOT = Path(__file__).resolve().parents[1]
CORE = [("measurement.calibration", "calibrate"), ("measurement.pipeline", "scan"), ("measurement.ply", "write_ply"),
        ("measurement.simulate.capture", "write_capture")]
JOB_TIMEOUT_S = 240


def missing_core() -> list[str]:
    missing = []
    for module, name in CORE:
        try:
            if not hasattr(importlib.import_module(module), name):
                missing.append(f"{module}.{name}")
        except ImportError:
            missing.append(f"{module}.{name}")
    return missing


@pytest.fixture(scope="module")
def capture(tmp_path_factory) -> Path:
    if missing := missing_core():
        pytest.fail("the end-to-end test needs the measurement core, which lacks " + ", ".join(missing))
    from measurement.simulate.capture import write_capture

    return write_capture(tmp_path_factory.mktemp("capture"), stripes=40, size=(640, 427), seed=3,
                         scenes=("side",), poses=8)


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    """Base URL of ``bodyscan serve`` on a free port with its own data folder; stopped afterwards."""
    data = tmp_path_factory.mktemp("data")
    port = free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("BODYSCAN_")}
    env.update(BODYSCAN_DATA_DIR=str(data), BODYSCAN_WORKERS="1", BODYSCAN_LOG_LEVEL="INFO",
               PYTHONPATH=str(ROOT))
    log = open(data / "server.log", "wb")  # noqa: SIM115  (closed below)
    proc = subprocess.Popen([sys.executable, "-m", "app.cli", "serve", "--port", str(port)], cwd=data,
                            env=env, stdout=log, stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{port}"
    try:
        wait_healthy(url, proc, data / "server.log")
        yield url
    finally:
        proc.terminate()
        try:
            proc.wait(20)
        except subprocess.TimeoutExpired:
            proc.kill()
        log.close()
        print((data / "server.log").read_text()[-4000:])  # noqa: T201  (shown when a test fails)
    assert (data / "bodyscan.db").exists()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_healthy(url: str, proc: subprocess.Popen, log: Path, timeout_s: float = 60) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            pytest.fail(f"bodyscan serve exited with {proc.returncode}:\n{log.read_text()[-3000:]}")
        try:
            r = httpx.get(f"{url}/api/health", timeout=2)
            if r.status_code == 200 and r.json()["status"] == "ok":
                return
        except httpx.HTTPError:
            pass
        time.sleep(0.2)
    pytest.fail(f"bodyscan serve did not answer /api/health in {timeout_s} s:\n{log.read_text()[-3000:]}")


def finished_job(api: httpx.Client, job_id: int) -> dict:
    """Poll a job until it ends; progress must never go backwards while it runs."""
    deadline, last = time.monotonic() + JOB_TIMEOUT_S, 0.0
    while time.monotonic() < deadline:
        job = api.get(f"/api/jobs/{job_id}").json()
        if job["status"] in ("succeeded", "failed"):
            return job
        assert job["progress"] >= last - 1e-9, job
        last = job["progress"]
        time.sleep(0.25)
    pytest.fail(f"job {job_id} did not finish in {JOB_TIMEOUT_S} s: {job}")


def zipped(folder: Path, parts: tuple[str, ...]) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for path in sorted(folder.rglob("*")):
            rel = path.relative_to(folder).as_posix()
            if path.is_file() and rel.startswith(parts):
                zf.write(path, f"capture/{rel}")
    return buf.getvalue()


def read_ply(data: bytes) -> dict[str, np.ndarray]:
    """Vertex properties of a binary little-endian PLY."""
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    assert "format binary_little_endian 1.0" in header
    count = next(int(line.split()[2]) for line in header if line.startswith("element vertex"))
    types = {"float": "<f4", "double": "<f8", "int": "<i4", "uint": "<u4", "uchar": "u1", "short": "<i2",
             "float32": "<f4", "float64": "<f8", "int32": "<i4", "uint8": "u1"}
    props = [(line.split()[2], types[line.split()[1]]) for line in header if line.startswith("property")]
    return np.frombuffer(data, dtype=np.dtype(props), count=count, offset=end)


def tail_picks(anatomy: dict, every: int = 3) -> list[list[float]]:
    """The tail centreline moved onto its camera-facing skin: what a technician clicks along the tail."""
    centre = np.asarray(anatomy["tail_centreline"])
    radius = np.asarray(anatomy["tail_radius_mm"])
    toward = -centre / np.linalg.norm(centre, axis=1, keepdims=True)
    picks = centre + toward * radius[:, None]
    keep = sorted(set(range(0, len(picks), every)) | {len(picks) - 1})
    return picks[keep].tolist()


def test_technician_workflow_over_http(server, capture):
    truth = json.loads((capture / "truth" / "truth.json").read_text())
    anatomy = truth["views"]["side"]["anatomy"]
    with httpx.Client(base_url=server, timeout=60) as api:
        # calibration from a zip of the capture folder (rig settings from its rig.json)
        r = api.post("/api/calibrations", files={"archive": ("capture.zip", zipped(capture, ("rig.json", "calib/")))},
                     data={"name": "e2e rig"})
        assert r.status_code == 202, r.text
        cal_id, job = r.json()["id"], finished_job(api, r.json()["job_id"])
        assert job["status"] == "succeeded", job
        assert (job["kind"], job["result_id"], job["progress"]) == ("calibration", cal_id, 1.0)
        cal = api.get(f"/api/calibrations/{cal_id}").json()
        assert cal["status"] == "succeeded" and cal["image_size"] == [640, 427]
        assert cal["reprojection_error_px"] < 0.5
        assert sum(p["used"] for p in cal["poses"]) >= 6
        fx_truth = truth["camera_matrix"][0][0]
        assert cal["camera_matrix"][0][0] == pytest.approx(fx_truth, rel=0.02)
        assert len(cal["planes"]) >= 30

        # records
        animal = api.post("/api/animals", json={"tag": "E2E-1", "species": "fox", "sex": "female"}).json()
        session = api.post("/api/sessions", json={"animal_id": animal["id"], "calibration_id": cal_id,
                                                  "date": "2026-06-01", "operator": "Tess"}).json()

        # scan
        image = (capture / "scan" / "side.png").read_bytes()
        ambient = (capture / "scan" / "side_ambient.png").read_bytes()
        r = api.post(f"/api/sessions/{session['id']}/scans", data={"view": "side"},
                     files={"image": ("side.png", image, "image/png"), "ambient": ("side_ambient.png", ambient)})
        assert r.status_code == 202, r.text
        scan_id, job = r.json()["id"], finished_job(api, r.json()["job_id"])
        assert job["status"] == "succeeded", job
        scan = api.get(f"/api/scans/{scan_id}").json()
        assert scan["point_count"] > 1000
        auto = scan["measurements"]
        assert auto["body_length_mm"] == pytest.approx(anatomy["torso_length_mm"], rel=0.08)
        assert auto["body_height_mm"] == pytest.approx(anatomy["withers_height_mm"], rel=0.08)

        # the cloud lies on the true lit stripes
        ply = read_ply(api.get(f"/api/scans/{scan_id}/cloud.ply").content)
        assert len(ply) == scan["point_count"]
        cloud = np.stack([ply["x"], ply["y"], ply["z"]], axis=1).astype(np.float64)
        exact = np.load(capture / "truth" / "side_stripes.npz")["points"]
        gap = cKDTree(exact).query(cloud)[0]
        assert np.median(gap) < 2.0 and np.percentile(gap, 90) < 6.0

        # picked: neck width between the landmarks, tail along its skin; manual: tape body length
        m = api.post(f"/api/sessions/{session['id']}/measurements", json={
            "name": "neck_width", "kind": "distance", "points": anatomy["neck_landmarks"], "scan_id": scan_id,
            "created_by": "Tess"})
        assert m.status_code == 201, m.text
        neck = m.json()
        assert neck["value_mm"] == pytest.approx(anatomy["neck_width_mm"], abs=4.0)
        t = api.post(f"/api/sessions/{session['id']}/measurements", json={
            "name": "tail_length", "kind": "polyline", "points": tail_picks(anatomy), "scan_id": scan_id})
        assert t.status_code == 201, t.text
        tail = t.json()
        assert tail["value_mm"] == pytest.approx(anatomy["tail_length_mm"], rel=0.05)
        tape = api.post(f"/api/sessions/{session['id']}/measurements", json={
            "name": "body_length", "kind": "manual", "value_mm": anatomy["torso_length_mm"], "created_by": "Tess"})
        assert tape.status_code == 201, tape.text

        detail = api.get(f"/api/sessions/{session['id']}").json()
        kinds = {(x["name"], x["kind"]) for x in detail["measurements"]}
        assert {("body_length", "automatic"), ("body_length", "manual"), ("neck_width", "picked"),
                ("tail_length", "picked")} <= kinds

        # CSV: wide row with automatic, picked and manual side by side; long rows for herd software
        wide = list(csv.DictReader(io.StringIO(api.get("/api/export/animals.csv").text, newline="")))
        assert len(wide) == 1 and wide[0]["tag"] == "E2E-1" and wide[0]["date"] == "2026-06-01"
        row = wide[0]
        assert float(row["body_length_automatic_mm"]) == pytest.approx(auto["body_length_mm"], abs=0.01)
        assert float(row["body_length_manual_mm"]) == pytest.approx(anatomy["torso_length_mm"], abs=0.01)
        expected_pct = (auto["body_length_mm"] - anatomy["torso_length_mm"]) / anatomy["torso_length_mm"] * 100
        assert float(row["body_length_automatic_vs_manual_pct"]) == pytest.approx(expected_pct, abs=0.01)
        assert float(row["neck_width_picked_mm"]) == pytest.approx(neck["value_mm"], abs=0.01)
        assert float(row["tail_length_picked_mm"]) == pytest.approx(tail["value_mm"], abs=0.01)
        long = list(csv.DictReader(io.StringIO(
            api.get("/api/export/animals.csv", params={"format": "long", "species": "FOX"}).text, newline="")))
        assert {(x["name"], x["kind"]) for x in long} == kinds
        assert {x["who"] for x in long if x["kind"] != "automatic"} == {"Tess", ""}


def test_bad_input_over_http_is_4xx_and_a_failed_calibration_blocks_scans(server, capture):
    with httpx.Client(base_url=server, timeout=60) as api:
        assert api.get("/api/sessions/12345").status_code == 404
        board = (capture / "calib" / "pose_01_board.png").read_bytes()
        r = api.post("/api/calibrations", files=[("files", ("calib/pose_01_board.png", board[: len(board) // 2]))],
                     data={"board_cols": 9, "board_rows": 6, "square_mm": 25, "stripes": 40})
        assert r.status_code == 422 and "pose_01_board.png" in r.json()["detail"]

        # a board size that is not on the images: the job fails with a message naming the problem
        files = [("files", (f"calib/{p.name}", p.read_bytes())) for p in sorted((capture / "calib").glob("pose_0[12]_*"))]
        r = api.post("/api/calibrations", files=files, data={"board_cols": 5, "board_rows": 4, "square_mm": 25,
                                                             "stripes": 40})
        assert r.status_code == 202, r.text
        job = finished_job(api, r.json()["job_id"])
        assert job["status"] == "failed" and job["error"] and "internal error" not in job["error"]
        animal = api.post("/api/animals", json={"tag": "E2E-2"}).json()
        r = api.post("/api/sessions", json={"animal_id": animal["id"], "calibration_id": r.json()["id"]})
        assert r.status_code == 409 and "failed" in r.json()["detail"]
