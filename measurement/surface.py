"""A triangle mesh of the scanned surface between neighbouring stripes, and snapping picks onto it.

Stripes are ~15 mm apart on the animal, so a picked point snapped to the nearest *stripe point* can move
by half a stripe spacing along the body. The stripe order gives a mesh almost for free: the points of
stripe k and stripe k+1, each ordered by image row, are zipped into a triangle strip. Snapping onto that
mesh keeps a pick where it was on the surface, and a path resampled and snapped onto the mesh follows
the surface between the picks.

Pure numpy/scipy/trimesh; lengths in millimetres, points in the camera frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.sparse import csr_matrix
from scipy.spatial import cKDTree


@dataclass(frozen=True)
class MeshParams:
    """Knobs of :func:`stripe_mesh`.

    max_edge_mm : longest triangle edge kept, mm; None (default) derives it from the scan as
        ``edge_factor`` times the median edge between neighbouring stripes. Longer edges would bridge a
        gap in a stripe, a missing stripe or the step from the body to the background or a leg.
    edge_factor : the automatic limit in stripe spacings; 2.5 keeps oblique flanks, where the spacing
        on the surface grows, and drops bridges over a missing stripe.
    """

    max_edge_mm: float | None = None
    edge_factor: float = 2.5


@dataclass(frozen=True, eq=False)
class SurfaceMesh:
    """A stripe mesh with the lookups snapping needs.

    mesh : trimesh.Trimesh, vertices (N, 3) float64 mm (the scan points, in input order), faces (F, 3) int
    tree : cKDTree over the vertices
    vertex_faces : (N, F) sparse incidence matrix, vertex -> faces
    longest_edge_mm : longest edge of any face, mm (0 without faces)
    """

    mesh: trimesh.Trimesh
    tree: cKDTree
    vertex_faces: csr_matrix
    longest_edge_mm: float


def stripe_mesh(points: np.ndarray, stripe: np.ndarray, uv: np.ndarray,
                params: MeshParams = MeshParams()) -> SurfaceMesh:
    """Mesh the surface between neighbouring stripes.

    points : (N, 3) float, mm — scan points
    stripe : (N,) int — stripe index of each point (negative: unassigned, not meshed)
    uv : (N, 2) float, px — image position of each point, OpenCV (x, y); rows order the points of a stripe

    Returns a :class:`SurfaceMesh` whose vertices are ``points``. Triangles join stripe k and k + 1 only;
    triangles with an edge longer than ``params.max_edge_mm`` are dropped.
    """
    points = _check_points(points, "points")
    stripe = np.asarray(stripe).astype(np.int64, copy=False)
    uv = np.asarray(uv, dtype=np.float64)
    if stripe.shape != (len(points),):
        raise ValueError(f"stripe must have shape ({len(points)},), got {stripe.shape}")
    if uv.shape != (len(points), 2):
        raise ValueError(f"uv must have shape ({len(points)}, 2), got {uv.shape}")
    ids = np.unique(stripe[stripe >= 0])
    members = {k: _by_row(np.flatnonzero(stripe == k), uv) for k in ids}
    strips = [_zip_strips(members[k], members[k + 1], uv) for k in ids if k + 1 in members]
    faces = np.concatenate(strips) if strips else np.zeros((0, 3), np.int64)
    edges = _edge_lengths(points, faces)
    limit = params.max_edge_mm
    if limit is None:
        # Every face's first corner lies on stripe k and its second on k + 1 (see _zip_strips), so
        # that edge (column 1 of _edge_lengths) is a rung between stripes: its median is the spacing.
        limit = params.edge_factor * float(np.median(edges[:, 1])) if len(faces) else 0.0
    return _surface(points, faces[edges.max(axis=1, initial=0.0) <= limit])


def snap(points: np.ndarray, surface: SurfaceMesh) -> np.ndarray:
    """Closest points on the surface mesh.

    points : (K, 3) float, mm. Returns (K, 3) float64, mm. Points that belong to no triangle (a lone
    stripe) are still valid targets, so the result is never farther than the nearest scan point.
    """
    points = _check_points(points, "points")
    if len(surface.mesh.vertices) == 0:
        raise ValueError("cannot snap onto an empty surface (the scan has no points)")
    verts, faces = surface.mesh.vertices, surface.mesh.faces
    d0, nearest = surface.tree.query(points)
    out = verts[nearest].copy()
    if len(faces) == 0:
        return out
    # The closest triangle has all its vertices within d0 + longest edge of the query point.
    for i, (q, radius) in enumerate(zip(points, d0 + surface.longest_edge_mm, strict=True)):
        near = surface.tree.query_ball_point(q, radius)
        cand = np.unique(surface.vertex_faces[near].indices)
        if len(cand) == 0:
            continue
        closest = trimesh.triangles.closest_point(verts[faces[cand]], np.repeat(q[None], len(cand), axis=0))
        dist = np.linalg.norm(closest - q, axis=1)
        if dist.min() < d0[i]:
            out[i] = closest[np.argmin(dist)]
    return out


def surface_path(points: np.ndarray, surface: SurfaceMesh, step_mm: float = 2.0) -> np.ndarray:
    """A picked polyline resampled every ``step_mm`` and snapped, so it follows the surface.

    points : (K, 3) float, mm, K >= 2 — the picks in order. Returns (M, 3) float64 mm, M >= K,
    starting and ending at the snapped first and last pick.
    """
    points = _check_points(points, "points")
    if len(points) < 2:
        raise ValueError(f"points must hold at least 2 points, got {len(points)}")
    if step_mm <= 0:
        raise ValueError(f"step_mm must be positive, got {step_mm}")
    return snap(resample(points, step_mm), surface)


def resample(points: np.ndarray, step_mm: float) -> np.ndarray:
    """Insert points along each segment so that no segment is longer than ``step_mm``.

    points : (K, 3) float, mm. Returns (M, 3) float64 keeping every input point.
    """
    points = _check_points(points, "points")
    pieces = []
    for a, b in zip(points[:-1], points[1:], strict=True):
        n = max(int(np.ceil(np.linalg.norm(b - a) / step_mm)), 1)
        pieces.append(a + (b - a) * (np.arange(n)[:, None] / n))
    pieces.append(points[-1:])
    return np.concatenate(pieces)


def polyline_length(points: np.ndarray) -> float:
    """Sum of segment lengths of a (K, 3) polyline, mm (0 for K < 2)."""
    points = _check_points(points, "points")
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())


def _check_points(points: np.ndarray, name: str) -> np.ndarray:
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), got {points.shape}")
    if not np.isfinite(points).all():
        raise ValueError(f"{name} must be finite numbers")
    return points


def _by_row(index: np.ndarray, uv: np.ndarray) -> np.ndarray:
    return index[np.argsort(uv[index, 1], kind="stable")]


def _zip_strips(a: np.ndarray, b: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Triangle strip between two row-ordered vertex lists: walk down both, always advancing the one
    whose next vertex is higher in the image. Returns (F, 3) vertex indices, consistently wound."""
    rows = np.concatenate([uv[a, 1], uv[b, 1]])
    side = np.concatenate([np.zeros(len(a), np.int64), np.ones(len(b), np.int64)])
    side = side[np.argsort(rows, kind="stable")]
    ia = np.cumsum(side == 0) - 1  # index into a after each event
    ib = np.cumsum(side == 1) - 1
    t = np.arange(1, len(side))
    t = t[(ia[t - 1] >= 0) & (ib[t - 1] >= 0)]  # both strips started before the event
    third = np.where(side[t] == 0, a[ia[t]], b[ib[t]])
    return np.stack([a[ia[t - 1]], b[ib[t - 1]], third], axis=1)


def _edge_lengths(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F, 3) lengths of the edges v2-v0, v0-v1, v1-v2 of each face, mm."""
    tri = points[faces]
    return np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2)


def _surface(points: np.ndarray, faces: np.ndarray) -> SurfaceMesh:
    mesh = trimesh.Trimesh(points, faces, process=False, validate=False)
    rows = faces.reshape(-1)
    cols = np.repeat(np.arange(len(faces)), 3)
    incidence = csr_matrix((np.ones(len(rows), bool), (rows, cols)), shape=(len(points), len(faces)))
    longest = float(_edge_lengths(points, faces).max()) if len(faces) else 0.0
    return SurfaceMesh(mesh, cKDTree(points), incidence, longest)
