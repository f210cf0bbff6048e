"""Background-plane screening per segment (``measurement.background``)."""

from __future__ import annotations

import numpy as np

from .jit import compiled


@compiled
def near_any_plane(rays, planes, bg_planes, tol_mm, near):
    """Into ``near`` (m, N) bool: whether ray i's point on light plane k (N, 4) lies within ``tol_mm``
    of a background plane (P, 4), screened as |z (ray . n) - d|; returns the positions i N + k (U,),
    sorted, where rounding could decide (within 1e-6 mm of ``tol_mm``, |z| >= 1e8 or not finite),
    which the exact formula (``background._near_exact``) must settle. Up to |z| = 1e8 mm both formulas
    round by under 1e-7 mm (a few ulp of 1e8); a ray nearly parallel to a light plane (|z| of 1e5-1e8, a
    third of the screened pairs at a fan's edge) needs no exact form."""
    m, n = near.shape
    unsure = np.empty(m * n, np.int64)
    u = 0
    # the planes' columns apart: each ray's loop over the planes runs on vector lanes
    p0, p1 = np.ascontiguousarray(planes[:, 0]), np.ascontiguousarray(planes[:, 1])
    p2, p3 = np.ascontiguousarray(planes[:, 2]), np.ascontiguousarray(planes[:, 3])
    d, z = np.empty(n), np.empty(n)
    bad = np.empty(n, np.bool_)
    for i in range(m):
        r0, r1, r2 = rays[i, 0], rays[i, 1], rays[i, 2]
        for k in range(n):
            z[k] = p3[k] / (r0 * p0[k] + r1 * p1[k] + r2 * p2[k])
            d[k] = np.inf
        for b in range(len(bg_planes)):
            along = r0 * bg_planes[b, 0] + r1 * bg_planes[b, 1] + r2 * bg_planes[b, 2]
            off = bg_planes[b, 3]
            for k in range(n):
                g = abs(z[k] * along - off)
                d[k] = g if g < d[k] else d[k]  # NaN skipped, as np.fmin skips it
        # the answers and the unsure flags without a branch (vector lanes), the rare unsure ones listed after
        row = near[i]
        n_bad = 0
        for k in range(n):
            row[k] = d[k] < tol_mm
            flag = not ((abs(d[k] - tol_mm) > 1e-6) & (abs(z[k]) < 1e8))
            bad[k] = flag
            n_bad += flag
        if n_bad:
            for k in range(n):
                if bad[k]:
                    unsure[u] = i * n + k
                    u += 1
    return unsure[:u]


@compiled
def group_counts(flags, starts):
    """Per group (G,) of rows ``starts[g]:starts[g + 1]`` of ``flags`` (K, N) bool: the True count per
    column, (G, N) int64 (``np.add.reduceat`` with the rows' end closing the last group)."""
    g_n, n = len(starts) - 1, flags.shape[1]
    out = np.zeros((g_n, n), np.int64)
    for g in range(g_n):
        for i in range(starts[g], starts[g + 1]):
            for k in range(n):
                out[g, k] += flags[i, k]
    return out


@compiled
def inlier_counts(sample, normals, offsets, tol_mm):
    """Per candidate plane (C,) of ``normals`` (C, 3) and ``offsets`` (C,): how many of the points
    ``sample`` (K, 3) lie within ``tol_mm`` of it (RANSAC's score, without the (K, C) distance matrix;
    the dot product summed x, y, z in order, so a point within a rounding of ``tol_mm`` may count
    differently than through BLAS)."""
    out = np.zeros(len(normals), np.int64)
    # the points' columns apart: the loop over them runs on vector lanes (the same operations)
    x, y, z = np.ascontiguousarray(sample[:, 0]), np.ascontiguousarray(sample[:, 1]), np.ascontiguousarray(sample[:, 2])
    for j in range(len(normals)):
        n0, n1, n2, d = normals[j, 0], normals[j, 1], normals[j, 2], offsets[j]
        count = 0
        for i in range(len(x)):
            count += abs(x[i] * n0 + y[i] * n1 + z[i] * n2 - d) < tol_mm
        out[j] = count
    return out


@compiled
def group_medians(x, counts):
    """np.median of each run of ``x`` (K,) in turn, the runs ``counts`` (G,) long (each at least 1): each run
    sorted on its own (NaN last, as np.sort and np.lexsort put it), the middle two averaged."""
    out = np.empty(len(counts))
    a = 0
    for g in range(len(counts)):
        c = counts[g]
        s = np.sort(x[a:a + c])
        out[g] = (s[(c - 1) // 2] + s[c // 2]) / 2
        a += c
    return out


@compiled
def first_of_each(values, size):
    """For ids ``values`` (K,) in [0, size): the ids present, ascending (G,), and the position (G,) of each
    one's first occurrence (``np.unique(values, return_index=True)``)."""
    first = np.full(size, -1, np.int64)
    for i in range(len(values)):
        if first[values[i]] < 0:
            first[values[i]] = i
    count = 0
    for s in range(size):
        count += first[s] >= 0
    ids = np.empty(count, np.int64)
    pos = np.empty(count, np.int64)
    g = 0
    for s in range(size):
        if first[s] >= 0:
            ids[g], pos[g] = s, first[s]
            g += 1
    return ids, pos

