"""Picked measurements: picks are snapped onto the scan's stripe mesh, then measured.

The mesh is built from every reconstructed point of the scan (the scene), not only from the points the
pipeline kept as the animal: isolating the animal is a heuristic that can drop a neck or a tail, while
the technician's pick says where the animal is. Picks in empty space are refused (``snap_max_mm``).

``distance`` is the straight line between the two snapped picks (a calliper). ``polyline`` follows the
surface: the picked path is resampled every ``path_step_mm`` and every sample is snapped, so a tail or
a girth is measured along the skin rather than by chords through the body.
"""

from __future__ import annotations

import threading
from collections import OrderedDict

import numpy as np
from sqlmodel import Session

from app.config import Settings
from measurement.surface import SurfaceMesh, polyline_length, snap, stripe_mesh, surface_path
from storage import sessions
from storage.errors import InvalidInputError

CACHE_SIZE = 8
_cache: OrderedDict[tuple, SurfaceMesh] = OrderedDict()
_lock = threading.Lock()


def surface_of(db: Session, scan_id: int) -> SurfaceMesh:
    """The stripe mesh of a finished scan, cached per stored cloud."""
    scan = sessions.get_scan(db, scan_id)
    key = (str(db.get_bind().url), scan_id, scan.cloud_blob_id)
    with _lock:
        if key in _cache:
            _cache.move_to_end(key)
            return _cache[key]
    cloud = sessions.scan_cloud(db, scan_id)
    if len(cloud["points"]) == 0:
        raise InvalidInputError(f"scan {scan_id} has no points to measure on")
    prefix = "scene_" if "scene_points" in cloud and len(cloud["scene_points"]) else ""
    points = cloud[f"{prefix}points"]
    uv = cloud.get(f"{prefix}uv", points[:, :2])  # without image positions, order stripe points by height
    stripe = cloud.get(f"{prefix}stripe", np.full(len(points), -1))  # without stripe ids: snap to the points
    surface = stripe_mesh(points, stripe, uv)
    with _lock:
        _cache[key] = surface
        while len(_cache) > CACHE_SIZE:
            _cache.popitem(last=False)
    return surface


def measure(db: Session, scan_id: int, kind: str, picks: list, settings: Settings) -> tuple[float, list]:
    """Value in mm and the snapped picks (K, 3 lists, mm) of a ``distance`` or ``polyline``."""
    picks = np.asarray(picks, dtype=np.float64)
    surface = surface_of(db, scan_id)
    snapped = snap(picks, surface)
    offsets = np.linalg.norm(snapped - picks, axis=1)
    worst = int(np.argmax(offsets))
    if offsets[worst] > settings.snap_max_mm:
        raise InvalidInputError(
            f"points[{worst}] {np.round(picks[worst], 1).tolist()} is {offsets[worst]:.1f} mm from the surface of "
            f"scan {scan_id} (at most {settings.snap_max_mm:g} mm allowed): pick on the animal")
    if kind == "distance":
        value = float(np.linalg.norm(snapped[1] - snapped[0]))
    else:
        value = polyline_length(surface_path(picks, surface, step_mm=settings.path_step_mm))
    return value, np.round(snapped, 4).tolist()
