"""Elevation bins and projector cells of a piece's offsets (``measurement.offsets``)."""

from __future__ import annotations

import numpy as np

from .jit import compiled


@compiled
def screened_bins(rays, planes, centre, axis, bins, margin, out):
    """``offsets._bins_on_planes``' screen ray by ray: into ``out`` (S, N) int64 the elevation bin of
    each ray (S, 3) on every light plane (N, 4) by the screened formula, and returns the positions
    k S + i (U,) int64, sorted, where it is not sure (within ``margin`` of a bin's edge, an ill-conditioned ray or point):
    those the exact formula must decide. centre (3,) mm, axis (3,) unit: the projector's frame."""
    s_n, n = out.shape
    cc = centre[0] * centre[0] + centre[1] * centre[1] + centre[2] * centre[2]
    ca = centre[0] * axis[0] + centre[1] * axis[1] + centre[2] * axis[2]
    tau = margin / bins
    # the rays' columns apart (unit-stride loads for the vector lanes) and their per-ray terms
    r0, r1, r2 = np.empty(s_n), np.empty(s_n), np.empty(s_n)
    rr, ra, rc, rsize = np.empty(s_n), np.empty(s_n), np.empty(s_n), np.empty(s_n)
    for i in range(s_n):
        r0[i], r1[i], r2[i] = rays[i, 0], rays[i, 1], rays[i, 2]
        rr[i], ra[i], rc[i], rsize[i] = _ray_terms(r0[i], r1[i], r2[i], centre, axis)
    unsure = np.empty(s_n * n, np.int64)
    m = 0
    floor, sure = np.empty(s_n), np.empty(s_n, np.bool_)
    for k in range(n):  # plane by plane: the unsure ones come out plane-major, as np.flatnonzero of (N, S)
        p0, p1, p2, d = planes[k, 0], planes[k, 1], planes[k, 2], planes[k, 3]
        for i in range(s_n):  # no branch: the loop runs on vector lanes (IEEE operations all the same)
            dot = p0 * r0[i] + p1 * r1[i] + p2 * r2[i]
            floor[i], sure[i] = _screened_bin(dot, d, rr[i], ra[i], rc[i], rsize[i], cc, ca, bins, tau)
        for i in range(s_n):
            if sure[i]:
                out[i, k] = np.int64(floor[i])
            else:
                unsure[m] = k * s_n + i
                m += 1
    return unsure[:m]


@compiled
def distinct_cells(rel, rows, sub, offsets, n, deep, most):
    """``offsets._distinct_cells`` for centres with relative stripes ``rel`` (S,) at each offset of
    ``offsets`` (W,): per offset the number of distinct projector cells (stripe rel + offset in [0, n),
    elevation bin ``rows[sub, stripe]``) and how many of them are keys of the sorted ``deep``
    (stripe * 1e6 + bin). rows : (R, N) int64 elevation bins, sub : (S,) the centres' rows (``BinTable``). Returns
    cells (W,), hits (W,) and False (nothing counted) when a bitmap of the cells of every offset would
    take more than ``most`` bytes."""
    w_n = len(offsets)
    cells = np.zeros(w_n, np.int64)
    hits = np.zeros(w_n, np.int64)
    if w_n == 0 or len(sub) == 0:
        return cells, hits, True
    first, last = offsets.min(), offsets.max()
    # the bins' range over each centre's stripes from the first to the last offset (a superset when the
    # offsets skip some: it only sizes the bitmap); runs along a table row are read in one sweep
    lo, hi = np.iinfo(np.int64).max, np.iinfo(np.int64).min
    for i in range(len(sub)):
        row = rows[sub[i]]
        for k in range(max(rel[i] + first, 0), min(rel[i] + last + 1, n)):
            lo = min(lo, row[k])
            hi = max(hi, row[k])
    if hi < lo:
        return cells, hits, True
    span = hi - lo + 1
    if not (lo > -400_000 and hi < 400_000) or w_n * n * span > most:
        return cells, hits, False
    in_deep = np.zeros(n * span, np.bool_)
    for key in deep:
        dk = (key + 500_000) // 1_000_000  # keys of bins within +-5e5 split back into stripe and bin
        de = key - dk * 1_000_000 - lo
        if 0 <= dk < n and 0 <= de < span:
            in_deep[dk * span + de] = True
    which = np.full(last - first + 1, -1, np.int64)  # offset - first -> its position in offsets
    for w in range(w_n):
        which[offsets[w] - first] = w
    mark = np.zeros((w_n, n * span), np.bool_)  # the cells of each offset
    for i in range(len(sub)):
        row = rows[sub[i]]
        for k in range(max(rel[i] + first, 0), min(rel[i] + last + 1, n)):
            w = which[k - rel[i] - first]
            if w >= 0:
                cell = k * span + row[k] - lo
                if not mark[w, cell]:
                    mark[w, cell] = True
                    cells[w] += 1
                    hits[w] += in_deep[cell]
    return cells, hits, True


@compiled
def screened_bins_at(rays, planes, k, centre, axis, bins, margin, out):
    """``screened_bins`` for one light plane per ray: into ``out`` (S,) int64 the elevation bin of ray i
    (S, 3) on plane ``k[i]`` by the screened formula (the same operations in the same order), and returns
    the rays (U,), ascending, where it is not sure, for the exact formula to decide."""
    cc = centre[0] * centre[0] + centre[1] * centre[1] + centre[2] * centre[2]
    ca = centre[0] * axis[0] + centre[1] * axis[1] + centre[2] * axis[2]
    tau = margin / bins
    unsure = np.empty(len(rays), np.int64)
    m = 0
    for i in range(len(rays)):
        r0, r1, r2 = rays[i, 0], rays[i, 1], rays[i, 2]
        rr, ra, rc, rsize = _ray_terms(r0, r1, r2, centre, axis)
        p0, p1, p2, d = planes[k[i], 0], planes[k[i], 1], planes[k[i], 2], planes[k[i], 3]
        fl, sure = _screened_bin(p0 * r0 + p1 * r1 + p2 * r2, d, rr, ra, rc, rsize, cc, ca, bins, tau)
        if sure:
            out[i] = np.int64(fl)
        else:
            unsure[m] = i
            m += 1
    return unsure[:m]


@compiled
def _ray_terms(r0, r1, r2, centre, axis):
    """A ray's terms of the screened elevation: |r|^2, r . axis, r . centre, and 1e-3 of the sum of its
    components' sizes (the least |ray . normal| the screen trusts)."""
    rr = r0 * r0 + r1 * r1 + r2 * r2
    ra = axis[0] * r0 + axis[1] * r1 + axis[2] * r2
    rc = centre[0] * r0 + centre[1] * r1 + centre[2] * r2
    return rr, ra, rc, 1e-3 * (abs(r0) + abs(r1) + abs(r2))


@compiled
def _screened_bin(dot, d, rr, ra, rc, rsize, cc, ca, bins, tau):
    """The screened elevation bin of a ray (its ``_ray_terms``) on a plane with ray . normal ``dot`` and
    offset ``d``, and whether it is sure (no branch: vector lanes). cc, ca : |centre|^2 and centre . axis."""
    size = abs(dot)
    s = d / dot
    along = s * ra - ca
    q2 = (s * rr - 2 * rc) * s + cc  # |s r - c|^2
    across2 = q2 - along * along
    f = along / (np.sqrt(across2) * bins)
    fl = np.floor(f)
    frac = f - fl
    return fl, ((size > rsize) & (size > 1e-6) & (across2 > 1e-4 * (q2 + cc)) & (frac > tau) & (frac < 1 - tau))


@compiled
def merge_distinct(a, b):
    """The sorted union (K,) of two sorted arrays of distinct values a (A,) and b (B,), each value once: one
    merge (``offsets.union_sorted``)."""
    out = np.empty(len(a) + len(b), a.dtype)
    i, j, k = 0, 0, 0
    while i < len(a) and j < len(b):
        if a[i] < b[j]:
            out[k] = a[i]
            i += 1
        elif b[j] < a[i]:
            out[k] = b[j]
            j += 1
        else:  # in both: once
            out[k] = a[i]
            i += 1
            j += 1
        k += 1
    while i < len(a):
        out[k] = a[i]
        i += 1
        k += 1
    while j < len(b):
        out[k] = b[j]
        j += 1
        k += 1
    return out[:k].copy()
