"""Liveness of the service, its database and its workers."""

from fastapi import APIRouter, Request
from sqlalchemy import func
from sqlmodel import select

from app.config import software_version
from app.deps import DbDep
from storage.models import Job, JobStatus

router = APIRouter(tags=["health"])


@router.get("/health")
def health(request: Request, db: DbDep) -> dict:
    """``{"status": "ok", ...}`` when the service reaches its database; also the queue and the workers
    this server runs (``expected`` 0 when separate ``bodyscan worker`` processes take the jobs)."""
    counts = dict(db.exec(select(Job.status, func.count()).where(
        Job.status.in_([JobStatus.queued, JobStatus.running])).group_by(Job.status)).all())
    pool = getattr(request.app.state, "pool", None)
    return {"status": "ok", "version": software_version(),
            "jobs": {"queued": counts.get(JobStatus.queued, 0), "running": counts.get(JobStatus.running, 0)},
            "workers": {"expected": request.app.state.settings.workers if pool else 0,
                        "alive": pool.alive() if pool else 0}}
