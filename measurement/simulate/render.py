"""Shading: room light, projector stripes (defocus, foreshortening, falloff, shadows), fur and sensor noise."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .rig import Rig
from .scene import KIND_CODES, Hits, MeshSurface, project_depth

PROJ_F_PX = 1600.0
PROJ_SIZE = (2400, 1400)


@dataclass(frozen=True)
class Lighting:
    """Everything about one exposure that is not geometry.

    ambient       : room light, gray levels on a white surface at the frame centre
    stripes_on    : projector on or off
    gradient      : relative change of room light across the frame (left to right, half that top to bottom)
    vignetting    : relative fall-off of brightness at the frame corners
    blur_px       : camera point-spread sigma in pixels at 3072 px width (scaled with the image)
    read_noise    : gray levels (sigma); gain: gray levels per electron (shot noise variance = gain * signal)
    fur           : fur effects on the animal (patchy albedo lives in the animal's albedo)
    """

    ambient: float = 60.0
    stripes_on: bool = True
    gradient: float = 0.3
    vignetting: float = 0.3
    blur_px: float = 0.8
    read_noise: float = 1.5
    gain: float = 0.25
    fur: bool = True


def stripe_irradiance(hits: Hits, rig: Rig, surfaces: list) -> tuple[np.ndarray, np.ndarray]:
    """Projector irradiance reaching each pixel's surface point, and the stripe index of each lit pixel.

    returns : (H, W) float64 gray levels on a white surface; (H, W) int32 nearest stripe, -1 if unlit
    """
    proj = rig.projector
    pts = hits.points
    valid = hits.surface >= 0
    p = proj.to_proj(np.where(valid[:, :, None], pts, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        xp = p[:, :, 0] / p[:, :, 2]
        yp = p[:, :, 1] / p[:, :, 2]
    spacing = float(np.mean(np.diff(proj.stripe_x))) if len(proj.stripe_x) > 1 else 1.0
    k = np.rint((xp - proj.stripe_x[0]) / spacing)
    k = np.clip(np.nan_to_num(k, nan=-1), -1, len(proj.stripe_x)).astype(np.int32)
    sigma = np.sqrt(proj.sigma**2 + (proj.defocus_per_mm * (p[:, :, 2] - proj.focus_mm)) ** 2)
    profile = np.zeros(xp.shape)
    for dk in (-1, 0, 1):  # the nearest stripe and its neighbours' tails
        kk = k + dk
        ok = (kk >= 0) & (kk < len(proj.stripe_x))
        dx = xp - proj.stripe_x[np.clip(kk, 0, len(proj.stripe_x) - 1)]
        profile += np.where(ok, np.exp(-0.5 * (dx / sigma) ** 2), 0.0)
    profile *= np.clip((proj.half_height - np.abs(yp)) / 0.004, 0, 1)
    to_proj = proj.centre_cam - pts
    dist = np.linalg.norm(to_proj, axis=2)
    cos = np.einsum("hwc,hwc->hw", hits.normals, to_proj) / dist
    irr = proj.power * profile * np.clip(cos, 0, 1) * (1000.0 / dist) ** 2
    irr *= ~_shadowed(p, surfaces, rig)
    irr[~valid] = 0
    lit = valid & (irr > 0) & (k >= 0) & (k < len(proj.stripe_x))
    return np.nan_to_num(irr), np.where(lit, k, -1)


def _shadowed(p: np.ndarray, surfaces: list, rig: Rig) -> np.ndarray:
    """True where a mesh lies between the projector and the surface point (depth test in projector view)."""
    out = np.zeros(p.shape[:2], bool)
    meshes = [s for s in surfaces if isinstance(s, MeshSurface)]
    if not meshes:
        return out
    w, h = PROJ_SIZE
    depth = np.full((h, w), np.inf)
    for m in meshes:
        depth = np.minimum(depth, project_depth(rig.projector.to_proj(m.vertices), m.faces, PROJ_F_PX, PROJ_SIZE))
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.rint(p[:, :, 0] / p[:, :, 2] * PROJ_F_PX + w / 2)
        v = np.rint(p[:, :, 1] / p[:, :, 2] * PROJ_F_PX + h / 2)
    ok = np.isfinite(u) & np.isfinite(v) & (u >= 0) & (u < w) & (v >= 0) & (v < h) & (p[:, :, 2] > 0)
    uu, vv = u[ok].astype(np.int64), v[ok].astype(np.int64)
    # a tolerance of a few mm absorbs the depth map's discretisation on oblique surfaces
    out[ok] = depth[vv, uu] < p[:, :, 2][ok] - 2.0 - 0.004 * p[:, :, 2][ok]
    return out


def albedo_map(hits: Hits, surfaces: list) -> np.ndarray:
    """(H, W) reflectance of what each pixel sees (0 where nothing is hit)."""
    out = np.zeros(hits.surface.shape)
    for idx, s in enumerate(surfaces):
        mask = hits.surface == idx
        if mask.any():
            out[mask] = s.albedo(hits.points[mask])
    return out


def kind_map(hits: Hits, surfaces: list) -> np.ndarray:
    """(H, W) uint8 surface kind code (see scene.KIND_CODES)."""
    codes = np.array([KIND_CODES[s.kind] for s in surfaces] + [0], np.uint8)
    return codes[hits.surface]


def expose(hits: Hits, surfaces: list, rig: Rig, light: Lighting, rng: np.random.Generator,
           irradiance: np.ndarray | None = None) -> np.ndarray:
    """Render one 8-bit exposure, (H, W) uint8."""
    h, w = hits.surface.shape
    scale = w / 3072.0
    albedo = albedo_map(hits, surfaces)
    vv, uu = np.mgrid[0:h, 0:w].astype(np.float32)
    room = light.ambient * (1 + light.gradient * (uu / w - 0.5) + 0.5 * light.gradient * (vv / h - 0.5))
    stripes = np.zeros((h, w)) if irradiance is None or not light.stripes_on else irradiance
    if light.stripes_on and light.fur:
        stripes = _fur(stripes, kind_map(hits, surfaces) == KIND_CODES["animal"], scale, rng)
    radiance = albedo * (room + stripes)
    r2 = ((uu - w / 2) ** 2 + (vv - h / 2) ** 2) / ((w / 2) ** 2 + (h / 2) ** 2)
    radiance *= 1 - light.vignetting * r2
    sigma = max(light.blur_px * scale, 0.35)
    radiance = cv2.GaussianBlur(radiance.astype(np.float32), (0, 0), sigma)
    noisy = radiance + rng.standard_normal((h, w)).astype(np.float32) * np.sqrt(
        light.gain * np.maximum(radiance, 0) + light.read_noise**2)
    return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)


def _fur(stripes: np.ndarray, animal: np.ndarray, scale: float, rng: np.random.Generator) -> np.ndarray:
    """Light on fur: scattered halo around each stripe, glints (speckle), dark dropouts, bright specks."""
    if not animal.any():
        return stripes
    h, w = stripes.shape
    s = stripes.astype(np.float32)
    halo = cv2.GaussianBlur(s, (0, 0), 3.0 * max(scale, 0.3))
    fur = 0.55 * s + 0.45 * halo * 1.6
    speck = cv2.GaussianBlur(rng.gamma(3.0, 1 / 3.0, (h, w)).astype(np.float32), (0, 0), 0.7 * max(scale, 0.5))
    fur *= speck
    small = (max(h // 24, 4), max(w // 24, 4))
    blobs = cv2.resize(rng.standard_normal(small).astype(np.float32), (w, h), interpolation=cv2.INTER_CUBIC)
    fur *= np.where(blobs > 1.8, 0.2, 1.0).astype(np.float32)
    n_specks = int(400 * scale * scale) + 20
    ys = rng.integers(0, h, n_specks)
    xs = rng.integers(0, w, n_specks)
    hit = animal[ys, xs]
    fur[ys[hit], xs[hit]] += rng.uniform(60, 160, hit.sum()).astype(np.float32)
    return np.where(animal, fur, s)


def stripe_truth(hits: Hits, stripe: np.ndarray, rig: Rig, surfaces: list) -> dict[str, np.ndarray]:
    """Exact points where each light plane crosses the visible, lit surface, one per stripe per image row.

    Crossings are found between horizontally adjacent pixels on the same surface with no depth step,
    by linear interpolation of the signed plane distance. Returns arrays
    points (M, 3) mm, stripe (M,), uv (M, 2) px, kind (M,) uint8.
    """
    planes = rig.projector.planes_cam()
    k = stripe
    kind = kind_map(hits, surfaces)
    kl, kr = k[:, :-1], k[:, 1:]
    pl, pr = hits.points[:, :-1], hits.points[:, 1:]
    same = (kl >= 0) & (kl == kr) & (hits.surface[:, :-1] == hits.surface[:, 1:])
    same &= np.abs(pl[:, :, 2] - pr[:, :, 2]) < 0.02 * pl[:, :, 2]
    kk = np.clip(kl, 0, len(planes) - 1)
    n, d = planes[kk, :3], planes[kk, 3]
    sl = np.einsum("hwc,hwc->hw", pl, n) - d
    sr = np.einsum("hwc,hwc->hw", pr, n) - d
    cross = same & (np.sign(sl) != np.sign(sr)) & np.isfinite(sl) & np.isfinite(sr)
    v, u = np.nonzero(cross)
    f = sl[v, u] / (sl[v, u] - sr[v, u])
    pts = pl[v, u] + f[:, None] * (pr[v, u] - pl[v, u])
    return {
        "points": pts,
        "stripe": kl[v, u].astype(np.int32),
        "uv": np.column_stack([u + f, v]).astype(np.float64),
        "kind": kind[v, u],
    }
