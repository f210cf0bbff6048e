"""Liveness of the service and its database."""

from fastapi import APIRouter
from sqlalchemy import text

from app.config import software_version
from app.deps import DbDep

router = APIRouter(tags=["health"])


@router.get("/health")
def health(db: DbDep) -> dict:
    """``{"status": "ok"}`` when the service can reach its database."""
    db.exec(text("SELECT 1"))
    return {"status": "ok", "version": software_version()}
