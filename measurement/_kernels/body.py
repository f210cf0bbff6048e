"""Per-stripe extents of the animal cloud (``measurement.body``): every stripe group in one call instead
of a NumPy round per group. The principal direction comes from LAPACK as ``np.linalg.svd`` of the
centred points gets it (the SVD of their QR factor R, which is what dgesdd takes for a tall matrix: the
same direction to the bit and with the same sign), the medians and quantiles are the same order
statistics and interpolation; only the projections onto the direction may round differently."""

from __future__ import annotations

import numpy as np

from .jit import compiled


@compiled
def _median(x):
    """np.median of a finite x (n,), n >= 1: the middle order statistics by one selection."""
    k = len(x) // 2
    p = np.partition(x, k)
    return p[k] if len(x) % 2 else (p[:k].max() + p[k]) / 2


@compiled
def _quantile(x, q):
    """np.quantile (linear) at q of a finite x (n,), n >= 1, as ``body._quantiles`` computes it."""
    n = len(x)
    v = (n - 1) * q
    if v >= n - 1:
        return x.max()
    if v < 0:
        return x.min()
    i = int(np.floor(v))
    p = np.partition(x, i)
    a, b, t = p[i], p[i + 1:].min(), v - i
    return b - (b - a) * (1 - t) if t >= 0.5 else a + (b - a) * t


@compiled
def _direction(x, keep, c):
    """First right singular vector (3,) of x[keep] - c, x (n, 3)."""
    m = 0
    for i in range(len(x)):
        m += keep[i]
    a = np.empty((m, 3))
    j = 0
    for i in range(len(x)):
        if keep[i]:
            for d in range(3):
                a[j, d] = x[i, d] - c[d]
            j += 1
    r = np.linalg.qr(a)[1]
    return np.linalg.svd(r)[2][0].copy()


@compiled
def _centre(x, keep):
    """Column medians (3,) of x[keep], x (n, 3)."""
    c = np.empty(3)
    for d in range(3):
        c[d] = _median(x[:, d][keep])
    return c


@compiled
def _fences(x, keep, t):
    """``body._fenced`` of one group x (n, 3) float64 mm, finite: fills ``keep`` (n,) (all True on entry)
    and ``t`` (n,) and returns the centre (3,), the direction (3,) and the two fences; NaN fences when a
    pass keeps fewer than 5 points (LAPACK then takes another path than the QR: the caller falls back to
    NumPy)."""
    n = len(x)
    c = np.zeros(3)
    v = np.zeros(3)
    lo_fence, hi_fence = np.nan, np.nan
    for _ in range(2):
        if keep.sum() < 5:
            return c, v, np.nan, np.nan
        c = _centre(x, keep)
        v = _direction(x, keep, c)
        for i in range(n):
            t[i] = (x[i, 0] - c[0]) * v[0] + (x[i, 1] - c[1]) * v[1] + (x[i, 2] - c[2]) * v[2]
        tk = t[keep]
        q1, q3 = _quantile(tk, 0.25), _quantile(tk, 0.75)
        lo_fence, hi_fence = q1 - 1.5 * (q3 - q1), q3 + 1.5 * (q3 - q1)
        same = True
        for i in range(n):
            f = t[i] >= lo_fence and t[i] <= hi_fence
            same = same and f == keep[i]
            keep[i] = f
        if same:
            break
    return c, v, lo_fence, hi_fence


@compiled
def group_extent(x, trim, ends):
    """``body._extent`` of one group x (n, 3) float64 mm, finite: the robust extent (mm) along its
    principal direction, its two extreme points into ``ends`` (2, 3); NaN when a pass keeps fewer than 5
    points (LAPACK then takes another path than the QR: the caller falls back to NumPy)."""
    n = len(x)
    keep = np.ones(n, np.bool_)
    t = np.empty(n)
    c, v, lo_fence, _ = _fences(x, keep, t)
    if np.isnan(lo_fence):
        return np.nan
    tk = t[keep]
    lo, hi = _quantile(tk, trim), _quantile(tk, 1 - trim)
    for d in range(3):
        ends[0, d] = c[d] + lo * v[d]
        ends[1, d] = c[d] + hi * v[d]
    return hi - lo


@compiled
def group_extent_with(x, extra, start, trim, reach, ends):
    """``body._extent_with`` of one group x (n, 3) float64 mm, finite, and its faint ends ``extra`` (e, 3)
    (``start`` (e,): the index of each one's walk's first point): the extent, the extreme points into
    ``ends`` (2, 3) and how many extra points counted; NaN as ``group_extent``."""
    n = len(x)
    keep = np.ones(n, np.bool_)
    t = np.empty(n)
    c, v, lo_fence, hi_fence = _fences(x, keep, t)
    if np.isnan(lo_fence):
        return np.nan, 0
    tk = t[keep]
    lo0, hi0 = _quantile(tk, trim), _quantile(tk, 1 - trim)
    te = np.empty(len(extra))
    for i in range(len(extra)):
        te[i] = (extra[i, 0] - c[0]) * v[0] + (extra[i, 1] - c[1]) * v[1] + (extra[i, 2] - c[2]) * v[2]
    both = np.empty(len(tk) + len(extra))
    both[:len(tk)] = tk
    m = len(tk)
    for i in range(len(extra)):
        t0 = te[start[i]]
        if lo_fence <= te[i] <= hi_fence and lo0 - reach <= t0 <= hi0 + reach:
            both[m] = te[i]
            m += 1
    lo, hi = _quantile(both[:m], trim), _quantile(both[:m], 1 - trim)
    for d in range(3):
        ends[0, d] = c[d] + lo * v[d]
        ends[1, d] = c[d] + hi * v[d]
    return hi - lo, m - len(tk)


@compiled
def group_extents(points, first, last, trim, ends):
    """``group_extent`` of the groups points[first[g]:last[g]] (G,) of points (N, 3): extents (G,) mm,
    extreme points into ``ends`` (G, 2, 3)."""
    out = np.empty(len(first))
    for g in range(len(first)):
        out[g] = group_extent(points[first[g]:last[g]], trim, ends[g])
    return out


@compiled
def voxel_cells(points, idx, voxel):
    """Voxels of ``voxel`` mm of the points ``idx`` (K,) of points (N, 3) mm (finite), counted from their
    lowest corner: np.floor((p - p.min(axis=0)) / voxel) as ``body.isolate`` took it; returns each point's
    cell as a flat index (K,) int64 into the C-ordered grid of shape (3,) int64 that holds them all."""
    lo = np.empty(3)
    for d in range(3):
        lo[d] = points[idx[0], d]
    for i in idx:
        for d in range(3):
            lo[d] = min(lo[d], points[i, d])
    ijk = np.empty((len(idx), 3), np.int64)
    shape = np.zeros(3, np.int64)
    for q in range(len(idx)):
        for d in range(3):
            c = np.int64(np.floor((points[idx[q], d] - lo[d]) / voxel))
            ijk[q, d] = c
            shape[d] = max(shape[d], c + 1)
    flat = np.empty(len(idx), np.int64)
    for q in range(len(idx)):
        flat[q] = (ijk[q, 0] * shape[1] + ijk[q, 1]) * shape[2] + ijk[q, 2]
    return flat, shape


@compiled
def plane_distances(points, products, offsets, near_mm, finite, distance):
    """Distance (N,) mm of each point of points (N, 3) to its nearest background plane into ``distance``,
    from ``products`` (N, P) = points @ normals and the planes' ``offsets`` (P,): |product - offset|,
    the least over the planes as np.minimum takes it (NaN wins); whether the point is finite into
    ``finite`` (N,); returns the distances (K,) of the finite points within ``near_mm``, in order."""
    near = np.empty(len(points))
    k = 0
    for i in range(len(points)):
        finite[i] = np.isfinite(points[i, 0]) and np.isfinite(points[i, 1]) and np.isfinite(points[i, 2])
        d = abs(products[i, 0] - offsets[0])
        for p in range(1, len(offsets)):
            e = abs(products[i, p] - offsets[p])
            if d == d and (e != e or e < d):
                d = e
        distance[i] = d
        if finite[i] and d <= near_mm:
            near[k] = d
            k += 1
    return near[:k]
