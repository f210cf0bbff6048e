"""Vectorised z-buffer rasteriser for triangle meshes: which triangle does each pixel see?"""

from __future__ import annotations

import numpy as np

_CHUNK = 8_000_000  # candidate (triangle, pixel) pairs per batch, bounds memory to a few hundred MB


def rasterize(tri_uv: np.ndarray, tri_depth: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Index of the nearest triangle covering each pixel centre, -1 where none.

    tri_uv    : (T, 3, 2) float64, pixel coordinates (u, v) of each triangle's vertices
    tri_depth : (T, 3) float64, positive depth of each vertex (any unit); 1/depth is interpolated
    size      : (width, height)
    returns   : (H, W) int32 triangle index
    """
    w, h = size
    best_z = np.full(h * w, np.inf)
    best_t = np.full(h * w, -1, dtype=np.int64)
    lo = np.floor(tri_uv.min(axis=1) - 0.5).astype(np.int64) + 1
    hi = np.floor(tri_uv.max(axis=1) - 0.5).astype(np.int64) + 1
    lo = np.maximum(lo, 0)
    hi = np.minimum(hi, [w, h])
    nx = np.maximum(hi[:, 0] - lo[:, 0], 0)
    ny = np.maximum(hi[:, 1] - lo[:, 1], 0)
    counts = nx * ny
    keep = np.nonzero(counts > 0)[0]
    start = 0
    while start < len(keep):
        csum = np.cumsum(counts[keep[start:]])
        stop = start + max(1, int(np.searchsorted(csum, _CHUNK)))
        _raster_batch(keep[start:stop], tri_uv, tri_depth, lo, nx, counts, w, best_z, best_t)
        start = stop
    return best_t.reshape(h, w).astype(np.int32)


def _raster_batch(tris, tri_uv, tri_depth, lo, nx, counts, w, best_z, best_t) -> None:
    c = counts[tris]
    t = np.repeat(tris, c)
    offs = np.arange(c.sum()) - np.repeat(np.cumsum(c) - c, c)
    px = lo[t, 0] + offs % nx[t]
    py = lo[t, 1] + offs // nx[t]
    a, b, cc = tri_uv[t, 0], tri_uv[t, 1], tri_uv[t, 2]
    # barycentric coordinates of the pixel centre
    v0 = b - a
    v1 = cc - a
    det = v0[:, 0] * v1[:, 1] - v0[:, 1] * v1[:, 0]
    ok = np.abs(det) > 1e-12
    dx = px - a[:, 0]
    dy = py - a[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        l1 = (dx * v1[:, 1] - dy * v1[:, 0]) / det
        l2 = (v0[:, 0] * dy - v0[:, 1] * dx) / det
    l0 = 1 - l1 - l2
    eps = -1e-9
    inside = ok & (l0 >= eps) & (l1 >= eps) & (l2 >= eps)
    t, px, py = t[inside], px[inside], py[inside]
    inv_z = l0[inside] / tri_depth[t, 0] + l1[inside] / tri_depth[t, 1] + l2[inside] / tri_depth[t, 2]
    z = 1.0 / inv_z
    pix = py * w + px
    order = np.lexsort((z, pix))
    pix, z, t = pix[order], z[order], t[order]
    first = np.ones(len(pix), bool)
    first[1:] = pix[1:] != pix[:-1]
    pix, z, t = pix[first], z[first], t[first]
    better = z < best_z[pix]
    best_z[pix[better]] = z[better]
    best_t[pix[better]] = t[better]
