"""Scan results: status, automatic measurements, the point cloud as PLY and the stored image."""

from __future__ import annotations

from urllib.parse import quote

from fastapi import APIRouter, Query, Response

from app.deps import DbDep
from app.schemas import ScanOut
from storage import sessions
from storage.jobs import job_for
from storage.models import JobKind, Scan

router = APIRouter(prefix="/scans", tags=["scans"])


def scan_out(db, scan: Scan) -> ScanOut:
    job = job_for(db, JobKind.scan, scan.id)
    return ScanOut(**scan.model_dump(warnings=False), job_id=job.id if job else None)


@router.get("/{scan_id}", response_model=ScanOut)
def read_scan(scan_id: int, db: DbDep):
    """Status, point count and the automatic measurements (mm) of a scan."""
    return scan_out(db, sessions.get_scan(db, scan_id))


@router.get("/{scan_id}/cloud.ply", response_class=Response,
            responses={200: {"content": {"application/octet-stream": {}}, "description": "binary PLY"}})
def download_cloud(scan_id: int, db: DbDep, scene: bool = Query(
        False, description="every reconstructed point (floor and wall too) instead of the isolated animal")) -> Response:
    """The animal's point cloud, binary little-endian PLY: x, y, z in mm (camera frame) and stripe index."""
    from measurement.ply import write_ply

    cloud = sessions.scan_cloud(db, scan_id)
    prefix = "scene_" if scene and "scene_points" in cloud else ""
    body = write_ply(cloud[f"{prefix}points"], cloud.get(f"{prefix}stripe"))
    name = f"scan_{scan_id}_scene.ply" if prefix else f"scan_{scan_id}.ply"
    return Response(body, media_type="application/octet-stream", headers={"Content-Disposition": attachment(name)})


@router.get("/{scan_id}/image", response_class=Response,
            responses={200: {"content": {"application/octet-stream": {}}, "description": "the uploaded file"}})
def download_image(scan_id: int, db: DbDep) -> Response:
    """The scan image exactly as uploaded."""
    scan = sessions.get_scan(db, scan_id)
    return Response(sessions.scan_image(db, scan_id), media_type="application/octet-stream",
                    headers={"Content-Disposition": attachment(scan.image_name or f"scan_{scan_id}")})


def attachment(name: str) -> str:
    """A Content-Disposition value that survives any file name (HTTP headers are latin-1)."""
    fallback = "".join(c if c.isascii() and c.isprintable() and c not in '"\\' else "_" for c in name)
    return f"attachment; filename=\"{fallback}\"; filename*=UTF-8''{quote(name, safe='')}"
