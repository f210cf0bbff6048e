"""The job runner: worker processes claim calibration and scan jobs from the database and run the core.

A worker is ``bodyscan worker`` (any machine sharing the database) or one of the processes that
``bodyscan serve`` starts. While a job runs its worker refreshes the job's heartbeat; a job whose
worker died is re-queued by the next worker that polls (or at once when a worker on the same host
starts and sees the dead process id), and failed after ``max_attempts`` interruptions.
"""

from __future__ import annotations

import logging
import os
import signal
import socket
import threading
import time
import uuid

from sqlalchemy.engine import Engine
from sqlmodel import Session, select

from app.config import Settings, software_version
from app.tasks import HANDLERS, Apply
from measurement.errors import MeasurementError
from storage.db import make_engine, session_scope, upgrade
from storage.jobs import claim_next, finish_job, heartbeat, release_job, requeue_stale
from storage.models import Job, JobStatus

log = logging.getLogger(__name__)
_TOKEN = uuid.uuid4().hex[:6]  # tells this process from an earlier one that had the same pid (containers)


class JobLost(Exception):
    """The job was re-queued or claimed by another worker while this one was running it."""


class WorkerStopped(BaseException):
    """SIGTERM/SIGINT arrived; the current job is handed back to the queue."""


def worker_id() -> str:
    """``host:pid:token`` of this process, stored with the jobs it claims."""
    return f"{socket.gethostname()}:{os.getpid()}:{_TOKEN}"


# --- running one job ---------------------------------------------------------------------------------


class _Lease:
    """Heartbeats for one job: from the progress callback (throttled) and from a background thread."""

    def __init__(self, engine: Engine, job_id: int, worker: str, every_s: float) -> None:
        self.engine, self.job_id, self.worker, self.every_s = engine, job_id, worker, every_s
        self.lost = False
        self.stage = "starting"
        self._last = 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._beat, name=f"lease-{job_id}", daemon=True)

    def __enter__(self) -> _Lease:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()

    def report(self, fraction: float, stage: str) -> None:
        """Progress callback handed to the core; aborts the job when the lease was lost."""
        now = time.monotonic()
        if stage != self.stage or now - self._last > 0.5:
            self.stage, self._last = stage, now
            if not heartbeat(self.engine, self.job_id, self.worker, fraction, stage):
                self.lost = True
        if self.lost:
            raise JobLost(f"job {self.job_id} was taken over by another worker")

    def _beat(self) -> None:
        while not self._stop.wait(self.every_s):
            try:
                if not heartbeat(self.engine, self.job_id, self.worker):
                    self.lost = True
            except Exception:  # a busy database must not kill the job; the next beat retries
                log.warning("heartbeat of job %s failed", self.job_id, exc_info=True)


def execute(engine: Engine, job: Job, worker: str, settings: Settings) -> JobStatus | None:
    """Run a claimed job and record its outcome; None when the job was lost to another worker."""
    handler = HANDLERS.get(job.kind)
    with _Lease(engine, job.id, worker, settings.heartbeat_s) as lease:
        try:
            if handler is None:
                raise MeasurementError(f"unknown job kind {job.kind!r}")
            apply = handler(engine, job, lease.report)
            error = None
        except JobLost:
            log.warning("job %s lost to another worker; result discarded", job.id)
            return None
        except MeasurementError as exc:
            apply, error = None, str(exc)
        except Exception as exc:
            log.exception("job %s (%s) crashed in stage %r", job.id, job.kind, lease.stage)
            apply = None
            error = (f"internal error while {lease.stage}: {type(exc).__name__}: {exc}. This is a bug in "
                     f"bodyscan {software_version()}; please report it with job id {job.id}")
    return _record(engine, job, worker, apply, error)


def _record(engine: Engine, job: Job, worker: str, apply: Apply | None, error: str | None) -> JobStatus | None:
    try:
        with session_scope(engine) as db:
            if apply is not None:
                apply(db)
            if not finish_job(db, job.id, worker, error=error):
                raise JobLost(f"job {job.id} was taken over by another worker")
    except JobLost:
        log.warning("job %s lost to another worker before it finished; result discarded", job.id)
        return None
    except (ValueError, TypeError) as exc:  # a result the database cannot take
        log.exception("storing the result of job %s failed", job.id)
        with session_scope(engine) as db:
            finish_job(db, job.id, worker, error=f"internal error while storing the result: {exc}")
        return JobStatus.failed
    log.info("job %s (%s) %s%s", job.id, job.kind, "failed: " if error else "succeeded", error or "")
    return JobStatus.failed if error else JobStatus.succeeded


# --- the worker loop ---------------------------------------------------------------------------------


def reap(engine: Engine, settings: Settings) -> list[int]:
    """Re-queue jobs of dead workers: stale heartbeats anywhere, or dead processes on this host."""
    return requeue_stale(engine, settings.job_lease_s, settings.max_attempts, dead_workers=_dead_local(engine))


def _dead_local(engine: Engine) -> list[str]:
    """Workers of running jobs that were on this host and whose process is gone."""
    host, me = socket.gethostname(), worker_id()
    with Session(engine) as db:
        running = db.exec(select(Job.worker).where(Job.status == JobStatus.running)).all()
    dead = []
    for name in set(filter(None, running)) - {me}:
        parts = name.split(":")
        if len(parts) != 3 or parts[0] != host or not parts[1].isdigit():
            continue
        pid = int(parts[1])
        if pid == os.getpid() or not _alive(pid):  # our own pid under another token: an earlier life
            dead.append(name)
    return dead


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def run_until_idle(engine: Engine, settings: Settings, worker: str | None = None) -> int:
    """Claim and run jobs until the queue is empty; returns how many ran (used by tests and tools)."""
    worker = worker or worker_id()
    reap(engine, settings)
    count = 0
    while (job := claim_next(engine, worker)) is not None:
        execute(engine, job, worker, settings)
        count += 1
    return count


def run_worker(settings: Settings, stop: threading.Event | None = None) -> None:
    """Poll the queue until ``stop`` is set or SIGTERM/SIGINT arrives. Migrates the schema first."""
    engine = make_engine(settings.db_url)
    upgrade(engine)
    me, stop = worker_id(), stop or threading.Event()
    _install_stop_signals()
    if settings.warm_up:
        threading.Thread(target=_warm_up, name="warm-up", daemon=True).start()
    log.info("worker %s polling %s", me, engine.url.render_as_string(hide_password=True))
    last_reap = 0.0
    job = None
    try:
        while not stop.is_set():
            if time.monotonic() - last_reap > min(settings.job_lease_s / 4, 30.0):
                if touched := reap(engine, settings):
                    log.warning("re-queued or failed jobs of lost workers: %s", touched)
                last_reap = time.monotonic()
            job = claim_next(engine, me)
            if job is None:
                stop.wait(settings.poll_s)
                continue
            log.info("worker %s runs job %s (%s)", me, job.id, job.kind)
            execute(engine, job, me, settings)
            job = None
    except WorkerStopped:
        log.info("worker %s stopping", me)
        if job is not None:
            release_job(engine, job.id, me)
    finally:
        engine.dispose()


def _warm_up() -> None:
    """Compile (or load) the scan kernels while the worker already polls; a job that comes meanwhile
    waits for the kernels it needs, no longer than it would have anyway."""
    from measurement.warmup import warm_up

    try:
        log.info("scan kernels ready in %.1f s", warm_up())
    except Exception:  # a failed warm-up costs only the first scan's compile time
        log.exception("warming up the scan kernels failed; the first scan compiles them")


def _install_stop_signals() -> None:
    if threading.current_thread() is not threading.main_thread():
        return

    def _stop(signum, _frame):
        raise WorkerStopped(signal.Signals(signum).name)

    signal.signal(signal.SIGTERM, _stop)
    signal.signal(signal.SIGINT, _stop)
