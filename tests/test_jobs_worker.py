"""Real worker processes: a killed worker's job is taken over, a stopped worker hands its job back."""

from __future__ import annotations

import json
import multiprocessing
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from sqlmodel import Session

from app import jobs as runner
from app.config import Settings
from storage import calibrations
from storage.db import session_scope
from storage.jobs import get_job
from storage.models import JobKind, JobStatus
from tests.backend_support import migrated_engine, png, settings_for

ROOT = Path(__file__).resolve().parents[1]
RIG = {"board_cols": 9, "board_rows": 6, "square_mm": 20.0, "stripes": 40}


def slow_calibration(engine, job, report):
    """Stands in for a long calibration: reports progress for about ``SLOW_S`` seconds."""
    steps = 40
    for i in range(steps):
        report(i / steps, f"step {i}")
        time.sleep(float(os.environ.get("SLOW_S", "2")) / steps)
    return lambda db: calibrations.store_result(db, job.result_id, {"reprojection_error_px": 0.2})


def worker_with_slow_jobs(settings_json: str) -> None:
    runner.HANDLERS[JobKind.calibration.value] = slow_calibration
    runner.run_worker(Settings.model_validate_json(settings_json))


def start_worker(settings: Settings) -> multiprocessing.Process:
    proc = multiprocessing.get_context("spawn").Process(target=worker_with_slow_jobs, args=(settings.model_dump_json(),))
    proc.start()
    return proc


def wait_for(engine, job_id: int, predicate, timeout_s: float = 60.0):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with Session(engine) as db:
            job = get_job(db, job_id)
        if predicate(job):
            return job
        time.sleep(0.05)
    pytest.fail(f"job {job_id} never reached the expected state; last: {job.status} {job.stage}")


@pytest.fixture
def setup(tmp_path):
    settings = settings_for(tmp_path, poll_s=0.05, heartbeat_s=0.2, job_lease_s=30)
    engine = migrated_engine(settings.db_url)
    with session_scope(engine) as db:
        job = calibrations.create_calibration(db, RIG, {"pose_01_board.png": png()})[1]
    yield settings, engine, job.id
    engine.dispose()


def test_a_job_of_a_killed_worker_is_finished_by_the_next_worker(setup):
    settings, engine, job_id = setup
    first = start_worker(settings)
    wait_for(engine, job_id, lambda j: j.status == JobStatus.running and j.progress > 0)
    os.kill(first.pid, signal.SIGKILL)
    first.join()
    second = start_worker(settings)  # same host: sees the dead pid and re-queues at once, no lease wait
    try:
        done = wait_for(engine, job_id, lambda j: j.status == JobStatus.succeeded)
    finally:
        second.terminate()
        second.join(10)
    assert done.attempts == 2 and f":{second.pid}:" in done.worker
    with Session(engine) as db:
        assert calibrations.get_calibration(db, done.result_id).result == {"reprojection_error_px": 0.2}


def test_a_worker_stopped_with_sigterm_hands_its_job_back(setup):
    settings, engine, job_id = setup
    worker = start_worker(settings)
    wait_for(engine, job_id, lambda j: j.status == JobStatus.running and j.progress > 0)
    worker.terminate()
    worker.join(20)
    assert worker.exitcode == 0
    with Session(engine) as db:
        job = get_job(db, job_id)
    assert (job.status, job.attempts, job.stage) == (JobStatus.queued, 0, "re-queued: worker stopped")


def test_bodyscan_worker_once_runs_a_real_calibration_job(tmp_path):
    from measurement.simulate.capture import write_capture

    cap = write_capture(tmp_path / "capture", size=(640, 427), seed=5, scenes=(), poses=6)
    files = {p.relative_to(cap).as_posix(): p.read_bytes() for p in sorted((cap / "calib").iterdir())}
    url = f"sqlite:///{tmp_path / 'bodyscan.db'}"
    engine = migrated_engine(url)
    with session_scope(engine) as db:
        rig = {**json.loads((cap / "rig.json").read_text()), "camera_gamma": 2.2}  # recorded for its scans
        cal, job = calibrations.create_calibration(db, rig, files)
    env = {k: v for k, v in os.environ.items() if not k.startswith("BODYSCAN_")}
    env.update(BODYSCAN_DATABASE_URL=url, PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-m", "app.cli", "worker", "--once"], env=env, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "ran 1 job(s)" in out.stdout
    with Session(engine) as db:
        done, record = get_job(db, job.id), calibrations.get_calibration(db, cal.id)
    assert done.status == JobStatus.succeeded, done.error
    assert record.result["image_size"] == [640, 427] and record.result["reprojection_error_px"] < 0.5
    assert record.result["camera_gamma"] == 2.2 and record.result["rig"]["camera_gamma"] == 2.2
    engine.dispose()


def test_the_serve_pool_restarts_a_worker_that_died(tmp_path):
    from app.pool import WorkerPool

    settings = settings_for(tmp_path, poll_s=0.05).model_copy(update={"workers": 1})
    migrated_engine(settings.db_url).dispose()
    pool = WorkerPool(settings, check_s=0.1).start()
    try:
        (first,) = pool.pids()
        os.kill(first, signal.SIGKILL)
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and (pool.pids() == [first] or pool.alive() != 1):
            time.sleep(0.05)
        assert pool.alive() == 1 and pool.pids() != [first]
    finally:
        pool.stop()
    assert pool.alive() == 0
