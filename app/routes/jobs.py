"""Job status for polling."""

from fastapi import APIRouter

from app.deps import DbDep
from app.schemas import JobOut
from storage.jobs import get_job

router = APIRouter(prefix="/jobs", tags=["jobs"])


@router.get("/{job_id}", response_model=JobOut)
def read_job(job_id: int, db: DbDep):
    """Status, progress (0..1) with stage, and on failure the reason."""
    return get_job(db, job_id)
