"""Points and depths on light planes, summed as ``np.einsum`` sums them (``measurement.triangulation``)."""

from __future__ import annotations

import numpy as np

from .jit import compiled


@compiled
def _depth(rays, i, planes, k):
    """``triangulation.depth_on`` of ray i on plane k (mm): n . r summed as np.einsum sums three terms
    ((x + z) + y), NaN where the ray is parallel to the plane."""
    denom = (rays[i, 0] * planes[k, 0] + rays[i, 2] * planes[k, 2]) + rays[i, 1] * planes[k, 1]
    s = planes[k, 3] / denom
    if abs(denom) < 1e-9:
        s = np.nan
    return rays[i, 2] * s


@compiled
def _point(rays, i, planes, k, j):
    """Coordinate j of ``triangulation.intersect`` of ray i with plane k (mm)."""
    denom = (rays[i, 0] * planes[k, 0] + rays[i, 2] * planes[k, 2]) + rays[i, 1] * planes[k, 1]
    s = planes[k, 3] / denom
    if abs(denom) < 1e-9:
        s = np.nan
    return rays[i, j] * s


@compiled
def intersect(rays, planes, out):
    """``triangulation.intersect``: into ``out`` (M, 3) the points mm where rays (M, 3) meet planes
    (M, 4) [n, d]; NaN where |ray . n| < 1e-9. ray . n sums as np.einsum sums it."""
    for i in range(len(rays)):
        denom = (rays[i, 0] * planes[i, 0] + rays[i, 2] * planes[i, 2]) + rays[i, 1] * planes[i, 1]
        s = planes[i, 3] / denom
        if abs(denom) < 1e-9:
            s = np.nan
        for j in range(3):
            out[i, j] = rays[i, j] * s
    return out


@compiled
def depth_screen(rays, planes, k, lo, hi, out):
    """``triangulation.depth_in_range``'s screen: into ``out`` (M,) whether lo < z < hi for the depth z
    of each ray (M, 3) on its plane ``planes[k]`` (N, 4) formed ray by ray (sums as np.einsum sums
    them); returns the rays (U,) whose z lies within 1000 times its rounding of a bound, or is not
    finite, for the exact (M, N) formula to decide."""
    unsure = np.empty(len(rays), np.int64)
    u = 0
    for i in range(len(rays)):
        p = planes[k[i]]
        dot = (rays[i, 0] * p[0] + rays[i, 2] * p[2]) + rays[i, 1] * p[1]
        size = (abs(rays[i, 0]) * abs(p[0]) + abs(rays[i, 2]) * abs(p[2])) + abs(rays[i, 1]) * abs(p[1])
        z = p[3] / dot
        margin = abs(z) * 1e-12 * (1 + size / abs(dot))
        out[i] = z > lo and z < hi
        a, b = abs(z - lo), abs(z - hi)
        near = a if a != a or a < b else b  # np.minimum: NaN wins
        if not near > margin:
            unsure[u] = i
            u += 1
    return unsure[:u]


@compiled
def neighbour_distances(rays, planes, lab, left, idx):
    """3-D distance (K,) mm between each centre ``idx`` (K,) on its plane ``lab`` (M,) and its left row
    neighbour ``left`` (M,) on that one's: np.linalg.norm of the difference of ``intersect``'s points,
    the squares summed (x + y) + z as it sums them."""
    out = np.empty(len(idx))
    for q in range(len(idx)):
        i = idx[q]
        f = left[i]
        sq = 0.0
        for j in range(3):
            d = _point(rays, i, planes, lab[i], j) - _point(rays, f, planes, lab[f], j)
            sq = d * d if j == 0 else sq + d * d
        out[q] = np.sqrt(sq)
    return out


@compiled
def rays_at(u, v, flat, w, out):
    """``triangulation.rays_at`` into ``out`` (M, 3): the rays through columns u (M,) of rows v (M,),
    interpolated along the row of the ray table ``flat`` (H * W, 2) float32 in float64 as numpy does it."""
    for i in range(len(u)):
        u0 = min(max(np.int64(np.floor(u[i])), 0), w - 2)
        f = u[i] - u0
        g = 1 - f
        at = np.int64(v[i]) * w + u0
        if at < 0 or at + 1 >= len(flat):
            raise IndexError("rays_at: a centre lies outside the ray table")
        out[i, 0] = np.float64(flat[at, 0]) * g + np.float64(flat[at + 1, 0]) * f
        out[i, 1] = np.float64(flat[at, 1]) * g + np.float64(flat[at + 1, 1]) * f
        out[i, 2] = 1.0
    return out
