"""The job queue in the database: enqueue, claim, heartbeat, finish, re-queue after a lost worker.

Claiming is safe with many worker processes on many machines: PostgreSQL skips rows another worker
has locked (``FOR UPDATE SKIP LOCKED``), and on every engine the claim is a conditional
``UPDATE ... WHERE status = 'queued'`` whose row count tells the winner.
"""

from __future__ import annotations

from collections.abc import Sequence
from datetime import timedelta

from sqlalchemy import or_, update
from sqlalchemy.engine import Engine
from sqlmodel import Session, select

from .errors import ConflictError, NotFoundError
from .models import Calibration, Job, JobKind, JobStatus, Scan, utcnow

TARGETS = {JobKind.calibration.value: Calibration, JobKind.scan.value: Scan}


def enqueue(session: Session, kind: JobKind, result_id: int) -> Job:
    """Add a queued job that will fill in calibration or scan ``result_id``."""
    job = Job(kind=kind.value, result_id=result_id)
    session.add(job)
    session.flush()
    return job


def get_job(session: Session, job_id: int) -> Job:
    job = session.get(Job, job_id)
    if job is None:
        raise NotFoundError("job", job_id)
    return job


def list_jobs(session: Session, status: JobStatus | None = None, kind: str | None = None,
              offset: int = 0, limit: int = 100) -> list[Job]:
    """Jobs, newest first, optionally of one status and kind."""
    query = select(Job)
    if status is not None:
        query = query.where(Job.status == status)
    if kind is not None:
        query = query.where(Job.kind == kind)
    return list(session.exec(query.order_by(Job.id.desc()).offset(offset).limit(limit)))


def retry_job(session: Session, job_id: int) -> Job:
    """Queue a failed job again with a fresh attempt count (its uploaded data was kept)."""
    job = get_job(session, job_id)
    if job.status != JobStatus.failed:
        raise ConflictError(f"job {job_id} is {job.status}; only failed jobs can be retried")
    job.status, job.error, job.progress, job.stage = JobStatus.queued, None, 0.0, "queued (retry)"
    job.attempts, job.worker, job.started_at, job.finished_at, job.heartbeat_at = 0, None, None, None, None
    session.add(job)
    _set_target(session, job, JobStatus.queued)
    session.flush()
    return job


def job_for(session: Session, kind: JobKind, result_id: int) -> Job | None:
    """The newest job filling in calibration/scan ``result_id``."""
    query = select(Job).where(Job.kind == kind.value, Job.result_id == result_id).order_by(Job.id.desc())
    return session.exec(query).first()


def claim_next(engine: Engine, worker: str, tries: int = 5) -> Job | None:
    """Claim the oldest queued job for ``worker`` (status -> running); None when the queue is empty."""
    for _ in range(tries):
        with Session(engine, expire_on_commit=False) as session:
            query = (select(Job.id).where(Job.status == JobStatus.queued).order_by(Job.id).limit(1)
                     .with_for_update(skip_locked=True))
            job_id = session.exec(query).first()
            if job_id is None:
                return None
            now = utcnow()
            claimed = session.exec(
                update(Job).where(Job.id == job_id, Job.status == JobStatus.queued).values(
                    status=JobStatus.running, worker=worker, attempts=Job.attempts + 1, started_at=now,
                    heartbeat_at=now, progress=0.0, stage="starting", error=None)
            ).rowcount
            if claimed == 1:
                _set_target(session, session.get(Job, job_id), JobStatus.running)
                session.commit()
                return session.get(Job, job_id)
            session.rollback()  # another worker won the race; try the next job
    return None


def heartbeat(engine: Engine, job_id: int, worker: str, progress: float | None = None,
              stage: str | None = None) -> bool:
    """Refresh the lease (and progress/stage); False when the job is no longer this worker's."""
    values: dict = {"heartbeat_at": utcnow()}
    if progress is not None:
        values["progress"] = min(max(float(progress), 0.0), 1.0)
    if stage is not None:
        values["stage"] = stage[:200]
    with Session(engine) as session:
        count = session.exec(update(Job).where(
            Job.id == job_id, Job.worker == worker, Job.status == JobStatus.running).values(**values)).rowcount
        session.commit()
    return count == 1


def finish_job(session: Session, job_id: int, worker: str, error: str | None = None) -> bool:
    """Mark a job (and its calibration/scan) succeeded, or failed with ``error``, inside ``session``.

    Returns False, changing nothing, when the job was re-queued or taken by another worker meanwhile.
    """
    status = JobStatus.failed if error else JobStatus.succeeded
    values = {"status": status, "error": error, "finished_at": utcnow()}
    if not error:
        values.update(progress=1.0, stage="done")
    count = session.exec(update(Job).where(
        Job.id == job_id, Job.worker == worker, Job.status == JobStatus.running).values(**values)).rowcount
    if count != 1:
        return False
    _set_target(session, session.get(Job, job_id), status, error)
    return True


def requeue_stale(engine: Engine, lease_s: float, max_attempts: int,
                  dead_workers: Sequence[str] = ()) -> list[int]:
    """Re-queue running jobs whose worker stopped sending heartbeats (or is known to be dead, by its
    ``host:pid`` name); fail those interrupted ``max_attempts`` times. Returns the ids of the jobs touched.
    """
    cutoff = utcnow() - timedelta(seconds=lease_s)
    touched = []
    lost = or_(Job.heartbeat_at < cutoff, Job.heartbeat_at.is_(None))
    if dead_workers:
        lost = or_(lost, Job.worker.in_(list(dead_workers)))
    with Session(engine, expire_on_commit=False) as session:
        query = select(Job).where(Job.status == JobStatus.running, lost).with_for_update(skip_locked=True)
        for job in session.exec(query).all():
            if job.attempts >= max_attempts:
                job.status, job.finished_at = JobStatus.failed, utcnow()
                job.error = (f"the job was interrupted {job.attempts} times (its worker crashed, ran out of "
                             "memory or was stopped); check the worker logs, then upload the data again")
                _set_target(session, job, JobStatus.failed, job.error)
            else:
                job.status, job.worker, job.stage = JobStatus.queued, None, "re-queued after its worker was lost"
                _set_target(session, job, JobStatus.queued)
            session.add(job)
            touched.append(job.id)
        session.commit()
    return touched


def release_job(engine: Engine, job_id: int, worker: str) -> bool:
    """Give a running job back to the queue without counting the attempt (a worker shutting down)."""
    with Session(engine) as session:
        count = session.exec(update(Job).where(
            Job.id == job_id, Job.worker == worker, Job.status == JobStatus.running).values(
            status=JobStatus.queued, worker=None, attempts=Job.attempts - 1, stage="re-queued: worker stopped",
            progress=0.0)).rowcount
        if count == 1:
            _set_target(session, session.get(Job, job_id), JobStatus.queued)
        session.commit()
    return count == 1


def _set_target(session: Session, job: Job | None, status: JobStatus, error: str | None = None) -> None:
    if job is None or job.kind not in TARGETS:
        return
    target = session.get(TARGETS[job.kind], job.result_id)
    if target is None:
        return
    target.status, target.error = status, error
    if status in (JobStatus.succeeded, JobStatus.failed):
        target.finished_at = utcnow()
    session.add(target)
