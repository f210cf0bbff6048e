"""The job queue and runner: claiming, leases, lost workers, failures a technician can act on."""

from __future__ import annotations

import multiprocessing
import os
import socket
import time

from sqlmodel import Session, select

from app import jobs as runner
from app.tasks import automatic_values
from measurement.errors import CalibrationError
from storage import calibrations
from storage.db import session_scope
from storage.jobs import claim_next, finish_job, get_job, heartbeat, release_job, requeue_stale
from storage.models import Calibration, Job, JobKind, JobStatus
from tests.backend_support import (
    png,
    settings_for,
)

RIG = {"board_cols": 9, "board_rows": 6, "square_mm": 20.0, "stripes": 40}


def queue_calibrations(engine, n: int) -> list[int]:
    with session_scope(engine) as db:
        return [calibrations.create_calibration(db, RIG, {"pose_01_board.png": png()})[1].id for _ in range(n)]


def job(engine, job_id: int) -> Job:
    with Session(engine) as db:
        return get_job(db, job_id)


def test_jobs_are_claimed_oldest_first_and_only_once(engine):
    ids = queue_calibrations(engine, 3)
    claimed = [claim_next(engine, f"w:{i}") for i in range(4)]
    assert [j.id for j in claimed[:3]] == ids and claimed[3] is None
    first = job(engine, ids[0])
    assert (first.status, first.worker, first.attempts) == (JobStatus.running, "w:0", 1)
    with Session(engine) as db:
        assert db.get(Calibration, first.result_id).status == JobStatus.running


def _claim_all(url: str, name: str, out) -> None:
    from storage.db import make_engine

    engine = make_engine(url)
    got = []
    while (j := claim_next(engine, name)) is not None:
        got.append(j.id)
    out.put(got)


def test_concurrent_workers_in_separate_processes_never_share_a_job(engine, db_url):
    ids = queue_calibrations(engine, 40)
    ctx = multiprocessing.get_context("spawn")
    out = ctx.Queue()
    procs = [ctx.Process(target=_claim_all, args=(db_url, f"w:{i}", out)) for i in range(3)]
    for p in procs:
        p.start()
    results = [out.get(timeout=120) for _ in procs]
    for p in procs:
        p.join(30)
    claimed = [i for r in results for i in r]
    assert sorted(claimed) == ids  # every job exactly once


def test_a_job_whose_worker_stopped_beating_is_requeued_then_failed_after_max_attempts(engine):
    (jid,) = queue_calibrations(engine, 1)
    for attempt in (1, 2):
        assert claim_next(engine, "dead:1").id == jid
        time.sleep(0.05)
        assert requeue_stale(engine, lease_s=0.01, max_attempts=2) == ([jid] if attempt == 1 else [jid])
        expected = JobStatus.queued if attempt == 1 else JobStatus.failed
        assert job(engine, jid).status == expected
    failed = job(engine, jid)
    assert "interrupted 2 times" in failed.error
    with Session(engine) as db:
        assert db.get(Calibration, failed.result_id).status == JobStatus.failed


def test_a_fresh_heartbeat_keeps_the_job_and_a_lost_one_refuses_late_results(engine):
    (jid,) = queue_calibrations(engine, 1)
    claim_next(engine, "a:1")
    assert heartbeat(engine, jid, "a:1", 0.4, "finding corners")
    assert requeue_stale(engine, lease_s=60, max_attempts=3) == []
    assert (job(engine, jid).progress, job(engine, jid).stage) == (0.4, "finding corners")
    time.sleep(0.05)
    requeue_stale(engine, lease_s=0.01, max_attempts=3)
    assert claim_next(engine, "b:2").id == jid
    assert not heartbeat(engine, jid, "a:1", 0.9, "late")
    with session_scope(engine) as db:
        assert not finish_job(db, jid, "a:1")
        assert finish_job(db, jid, "b:2")
    assert job(engine, jid).status == JobStatus.succeeded


def test_jobs_of_a_dead_process_on_this_host_are_requeued_when_a_worker_starts(engine, tmp_path):
    (jid,) = queue_calibrations(engine, 1)
    proc = multiprocessing.get_context("spawn").Process(target=os.getpid)
    proc.start()
    proc.join()
    claim_next(engine, f"{socket.gethostname()}:{proc.pid}:abcdef")
    assert runner.reap(engine, settings_for(tmp_path)) == [jid]
    assert job(engine, jid).status == JobStatus.queued


def test_a_worker_shutting_down_hands_its_job_back_without_using_an_attempt(engine):
    (jid,) = queue_calibrations(engine, 1)
    claim_next(engine, "w:1")
    assert release_job(engine, jid, "w:1")
    back = job(engine, jid)
    assert (back.status, back.attempts, back.worker) == (JobStatus.queued, 0, None)


def test_a_core_error_fails_the_job_with_its_message(engine, tmp_path, monkeypatch):
    def calibrate_fails(engine, job, report):
        report(0.3, "finding chessboards")
        raise CalibrationError("pose_07_board.png: chessboard 9x6 not found")

    monkeypatch.setitem(runner.HANDLERS, JobKind.calibration.value, calibrate_fails)
    (jid,) = queue_calibrations(engine, 1)
    assert runner.run_until_idle(engine, settings_for(tmp_path)) == 1
    failed = job(engine, jid)
    assert (failed.status, failed.error) == (JobStatus.failed, "pose_07_board.png: chessboard 9x6 not found")
    assert failed.stage == "finding chessboards"
    with Session(engine) as db:
        cal = db.get(Calibration, failed.result_id)
    assert (cal.status, cal.error) == (JobStatus.failed, failed.error)


def test_a_crash_in_the_runner_is_reported_as_an_internal_error_with_the_stage(engine, tmp_path, monkeypatch):
    def crashes(engine, job, report):
        report(0.5, "fitting light planes")
        raise ZeroDivisionError("division by zero")

    monkeypatch.setitem(runner.HANDLERS, JobKind.calibration.value, crashes)
    (jid,) = queue_calibrations(engine, 1)
    runner.run_until_idle(engine, settings_for(tmp_path))
    error = job(engine, jid).error
    assert error.startswith("internal error while fitting light planes: ZeroDivisionError")
    assert f"job id {jid}" in error


def test_a_successful_handler_stores_its_result_with_the_job(engine, tmp_path, monkeypatch):
    def succeeds(engine, job, report):
        report(0.9, "writing")
        return lambda db: calibrations.store_result(db, job.result_id, {"reprojection_error_px": 0.1})

    monkeypatch.setitem(runner.HANDLERS, JobKind.calibration.value, succeeds)
    (jid,) = queue_calibrations(engine, 1)
    runner.run_until_idle(engine, settings_for(tmp_path))
    done = job(engine, jid)
    assert (done.status, done.progress, done.stage) == (JobStatus.succeeded, 1.0, "done")
    with Session(engine) as db:
        assert db.get(Calibration, done.result_id).result == {"reprojection_error_px": 0.1}


def test_automatic_values_are_read_from_the_pipeline_measurements():
    found = {"point_count": 900, "body_length_mm": 1500.5, "body_height_mm": 1200.0, "view": "side",
             "body_length": {"points": [[0, 0, 1], [1500.5, 0, 1]]}, "flag_mm": True, "bad_mm": float("nan")}
    assert automatic_values(found) == [
        ("body_height", 1200.0, None), ("body_length", 1500.5, [[0, 0, 1], [1500.5, 0, 1]])]


def test_unknown_job_kinds_fail_cleanly(engine, tmp_path):
    with session_scope(engine) as db:
        record = calibrations.create_calibration(db, RIG, {"pose_01_board.png": png()})[0]
        db.exec(select(Job)).first().kind = "mystery"
    runner.run_until_idle(engine, settings_for(tmp_path))
    with Session(engine) as db:
        assert "unknown job kind 'mystery'" in db.exec(select(Job)).first().error
        assert db.get(Calibration, record.id).status == JobStatus.queued  # untouched: no handler ran


def test_a_job_of_an_earlier_process_with_our_pid_is_requeued(engine, tmp_path):
    (jid,) = queue_calibrations(engine, 1)
    claim_next(engine, f"{socket.gethostname()}:{os.getpid()}:000000")  # e.g. PID 1 of a restarted container
    assert runner.reap(engine, settings_for(tmp_path)) == [jid]
    mine = claim_next(engine, runner.worker_id())  # our own running job is left alone
    assert mine.id == jid
    assert runner.reap(engine, settings_for(tmp_path)) == []
    assert job(engine, jid).status == JobStatus.running
