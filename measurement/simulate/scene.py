"""Scene surfaces (finite planes and meshes) and exact ray casting through every camera pixel."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..camera import Intrinsics, project
from .raster import rasterize

Albedo = Callable[[np.ndarray], np.ndarray]  # (N, 3) camera-frame mm -> (N,) reflectance 0..1

KIND_CODES = {"none": 0, "background": 1, "floor": 2, "wall": 3, "board": 4, "animal": 5}


@dataclass(frozen=True, eq=False)
class PlaneSurface:
    """A plane n.X = d in camera coordinates (mm), optionally bounded by ``inside(points) -> mask``."""

    normal: np.ndarray
    d: float
    kind: str
    albedo: Albedo
    inside: Callable[[np.ndarray], np.ndarray] | None = None


@dataclass(frozen=True, eq=False)
class MeshSurface:
    """A triangle mesh in camera coordinates: vertices (V, 3) mm, faces (F, 3) int."""

    vertices: np.ndarray
    faces: np.ndarray
    kind: str
    albedo: Albedo

    def face_planes(self) -> tuple[np.ndarray, np.ndarray]:
        """Unit face normals (F, 3) and offsets (F,) with n.X = d."""
        tri = self.vertices[self.faces]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
        return n, np.einsum("ij,ij->i", n, tri[:, 0])


@dataclass(frozen=True, eq=False)
class Hits:
    """What each camera pixel sees.

    points  : (H, W, 3) float64 camera-frame mm (NaN where nothing is hit)
    normals : (H, W, 3) float64 unit surface normals facing the camera
    surface : (H, W) int16 index into the scene's surfaces, -1 for none
    """

    points: np.ndarray
    normals: np.ndarray
    surface: np.ndarray


def trace(surfaces: list, intr: Intrinsics, rays_xy: np.ndarray) -> Hits:
    """Cast the ray of every pixel (normalised coordinates ``rays_xy`` (H, W, 2)) against all surfaces."""
    h, w = rays_xy.shape[:2]
    ray = np.concatenate([rays_xy, np.ones((h, w, 1))], axis=2)
    best = np.full((h, w), np.inf)
    normals = np.zeros((h, w, 3))
    surface = np.full((h, w), -1, np.int16)
    for idx, s in enumerate(surfaces):
        if isinstance(s, PlaneSurface):
            z, n = _plane_depth(s, ray)
        else:
            z, n = _mesh_depth(s, intr, ray)
        closer = z < best
        best[closer] = z[closer]
        normals[closer] = n[closer] if n.ndim == 3 else n
        surface[closer] = idx
    points = ray * best[:, :, None]
    points[surface < 0] = np.nan
    # normals face the camera
    flip = np.einsum("hwc,hwc->hw", normals, points) > 0
    normals[flip] *= -1
    return Hits(points, normals, surface)


def _plane_depth(s: PlaneSurface, ray: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    denom = ray @ s.normal
    with np.errstate(divide="ignore", invalid="ignore"):
        z = s.d / denom
    z[~(z > 0)] = np.inf
    if s.inside is not None:
        hit = np.isfinite(z)
        pts = ray[hit] * z[hit][:, None]
        ok = s.inside(pts)
        zz = z[hit]
        zz[~ok] = np.inf
        z[hit] = zz
    return z, np.asarray(s.normal, dtype=np.float64)


def _mesh_depth(s: MeshSurface, intr: Intrinsics, ray: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    h, w = ray.shape[:2]
    z = np.full((h, w), np.inf)
    normals = np.zeros((h, w, 3))
    front = s.vertices[:, 2] > 1.0
    uv = np.full((len(s.vertices), 2), -1e6)
    uv[front] = project(s.vertices[front], intr)
    faces = s.faces[front[s.faces].all(axis=1)]
    if len(faces) == 0:
        return z, normals
    tri_id = rasterize(uv[faces], s.vertices[faces][:, :, 2], (w, h))
    n, d = MeshSurface(s.vertices, faces, s.kind, s.albedo).face_planes()
    hit = tri_id >= 0
    t = tri_id[hit]
    denom = np.einsum("ij,ij->i", ray[hit], n[t])
    with np.errstate(divide="ignore", invalid="ignore"):
        zz = d[t] / denom
    zz[~(zz > 0)] = np.inf
    z[hit] = zz
    normals[hit] = n[t]
    return z, normals


def project_depth(vertices_proj: np.ndarray, faces: np.ndarray, f_px: float, size: tuple[int, int]
                  ) -> np.ndarray:
    """Depth map (H, W) mm of a mesh seen from the projector (pinhole, focal ``f_px``, centred), inf if empty."""
    w, h = size
    z = vertices_proj[:, 2]
    ok = z > 1.0
    uv = np.full((len(z), 2), -1e6)
    uv[ok] = vertices_proj[ok, :2] / z[ok, None] * f_px + [w / 2, h / 2]
    faces = faces[ok[faces].all(axis=1)]
    tri_id = rasterize(uv[faces], vertices_proj[faces][:, :, 2], (w, h))
    depth = np.full((h, w), np.inf)
    hit = tri_id >= 0
    if hit.any():
        tri = vertices_proj[faces[tri_id[hit]]]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        d = np.einsum("ij,ij->i", n, tri[:, 0])
        vv, uu = np.nonzero(hit)
        ray = np.column_stack([(uu - w / 2) / f_px, (vv - h / 2) / f_px, np.ones(len(uu))])
        with np.errstate(divide="ignore", invalid="ignore"):
            depth[hit] = d / np.einsum("ij,ij->i", n, ray)
    return depth
