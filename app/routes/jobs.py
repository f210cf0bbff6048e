"""Job status for polling, the job list of the queue, and retrying failed jobs."""

from fastapi import APIRouter, Query

from app.deps import DbDep
from app.schemas import JobOut
from storage.jobs import get_job, list_jobs, retry_job
from storage.models import JobKind, JobStatus

router = APIRouter(prefix="/jobs", tags=["jobs"])


@router.get("", response_model=list[JobOut])
def read_jobs(db: DbDep, status: JobStatus | None = None, kind: JobKind | None = None,
              offset: int = Query(0, ge=0), limit: int = Query(100, ge=1, le=1000)):
    """The queue, newest first: e.g. ``?status=failed`` to see what needs attention."""
    return list_jobs(db, status=status, kind=kind.value if kind else None, offset=offset, limit=limit)


@router.get("/{job_id}", response_model=JobOut)
def read_job(job_id: int, db: DbDep):
    """Status, progress (0..1) with stage, and on failure the reason."""
    return get_job(db, job_id)


@router.post("/{job_id}/retry", status_code=202, response_model=JobOut)
def retry(job_id: int, db: DbDep):
    """Run a failed job again on its stored uploads (e.g. after a worker ran out of memory)."""
    return retry_job(db, job_id)
