"""`bodyscan demo`: a complete rig on the simulator, served with demo records.

Renders a capture (calibration poses and an animal seen from the side and from above), starts the real
service, and through its REST API uploads the calibration, creates demo animals and sessions, scans the
animal, adds tape measurements, then keeps serving until Ctrl-C. Run again, it reuses what it made.
"""

from __future__ import annotations

import io
import json
import threading
import time
import urllib.error
import urllib.request
import uuid
import zipfile
from pathlib import Path

DEMO_TAG = "DEMO-001"


def run_demo(workdir: Path, size: tuple[int, int] = (1536, 1024), serve: bool = True, host: str = "127.0.0.1",
             port: int = 8000) -> None:
    import uvicorn

    from app.config import get_settings
    from app.main import create_app

    workdir.mkdir(parents=True, exist_ok=True)
    capture = _capture(workdir / "capture", size)
    settings = get_settings()
    if not settings.database_url:
        settings = settings.model_copy(update={"data_dir": workdir})
    server = uvicorn.Server(uvicorn.Config(create_app(settings), host=host, port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    base = f"http://{host}:{port}"
    _wait_ready(base, server)
    print(f"bodyscan is serving on {base} (API docs {base}/docs), database {settings.db_url}", flush=True)
    try:
        _seed(base, capture)
        if serve:
            print("demo ready: open the page above; Ctrl-C stops the server", flush=True)
            while thread.is_alive():
                thread.join(0.5)
    except KeyboardInterrupt:
        pass
    finally:
        server.should_exit = True
        thread.join(10)


def _capture(path: Path, size: tuple[int, int]) -> Path:
    from measurement.simulate.capture import write_capture

    if (path / "truth" / "truth.json").exists():
        return path
    print(f"rendering a demo rig at {size[0]}x{size[1]} (12 calibration poses, side and top views)...", flush=True)
    t0 = time.perf_counter()
    write_capture(path, size=size, poses=12, seed=3, scenes=("side", "top"))
    print(f"  rendered in {time.perf_counter() - t0:.0f} s -> {path}", flush=True)
    return path


def _wait_ready(base: str, server) -> None:
    for _ in range(200):
        try:
            if _call("GET", f"{base}/api/health")["status"] == "ok":
                return
        except (urllib.error.URLError, ConnectionError):
            pass
        if server.should_exit:
            break
        time.sleep(0.1)
    raise SystemExit(f"the server did not start on {base} (is the port in use?)")


def _seed(base: str, capture: Path) -> None:
    animals = _call("GET", f"{base}/api/animals")
    if any(a["tag"] == DEMO_TAG for a in animals):
        print("demo records already present", flush=True)
        return
    print("calibrating the demo rig...", flush=True)
    archive = _zip(capture, ("rig.json", "calib/"))
    accepted = _multipart(f"{base}/api/calibrations", {}, {"archive": ("capture.zip", archive)})
    job = _wait_job(base, accepted["job_id"])
    cal = _call("GET", f"{base}/api/calibrations/{accepted['id']}")
    print(f"  calibration {cal['id']}: {job['status']}, E1 = {cal.get('reprojection_error_px')} px", flush=True)
    truth = json.loads((capture / "truth" / "truth.json").read_text())
    anatomy = truth["views"]["side"]["anatomy"]
    herd = [
        {"tag": DEMO_TAG, "species": "fox", "breed": "simulated", "sex": "female", "notes": "rendered quadruped"},
        {"tag": "DEMO-002", "species": "fox", "breed": "simulated", "sex": "male", "notes": "no scan yet"},
    ]
    created = [_call("POST", f"{base}/api/animals", a) for a in herd]
    session = _call("POST", f"{base}/api/sessions", {"animal_id": created[0]["id"], "calibration_id": cal["id"],
                                                     "operator": "demo", "notes": "simulated side and top views"})
    for view in ("side", "top"):
        image = (capture / "scan" / f"{view}.png").read_bytes()
        sc = _multipart(f"{base}/api/sessions/{session['id']}/scans", {"view": view}, {"image": (f"{view}.png", image)})
        job = _wait_job(base, sc["job_id"])
        print(f"  {view} scan {sc['id']}: {job['status']} {job.get('error') or ''}", flush=True)
    _call("POST", f"{base}/api/sessions/{session['id']}/measurements",
          {"name": "body_length", "kind": "manual", "value_mm": round(anatomy["torso_length_mm"], 1),
           "created_by": "demo", "note": "tape (the simulator's torso length)"})
    print(f"demo records stored: animals {DEMO_TAG}, DEMO-002; session {session['id']}", flush=True)


def _wait_job(base: str, job_id: int, timeout_s: float = 900) -> dict:
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < timeout_s:
        job = _call("GET", f"{base}/api/jobs/{job_id}")
        if job["status"] in ("succeeded", "failed"):
            return job
        time.sleep(0.5)
    raise SystemExit(f"job {job_id} did not finish within {timeout_s:.0f} s")


def _zip(folder: Path, prefixes: tuple[str, ...]) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_STORED) as zf:
        for p in sorted(folder.rglob("*")):
            rel = p.relative_to(folder).as_posix()
            if p.is_file() and rel.startswith(prefixes):
                zf.write(p, rel)
    return buf.getvalue()


def _call(method: str, url: str, body: dict | None = None) -> dict | list:
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(url, data=data, method=method, headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(req, timeout=60) as resp:
        return json.loads(resp.read() or b"null")


def _multipart(url: str, fields: dict[str, str], files: dict[str, tuple[str, bytes]]) -> dict:
    boundary = uuid.uuid4().hex
    parts = []
    for k, v in fields.items():
        parts.append(f'--{boundary}\r\nContent-Disposition: form-data; name="{k}"\r\n\r\n{v}\r\n'.encode())
    for k, (fname, data) in files.items():
        head = (f'--{boundary}\r\nContent-Disposition: form-data; name="{k}"; filename="{fname}"\r\n'
                "Content-Type: application/octet-stream\r\n\r\n").encode()
        parts.append(head + data + b"\r\n")
    body = b"".join(parts) + f"--{boundary}--\r\n".encode()
    req = urllib.request.Request(url, data=body, method="POST",
                                 headers={"Content-Type": f"multipart/form-data; boundary={boundary}"})
    with urllib.request.urlopen(req, timeout=120) as resp:
        return json.loads(resp.read())
