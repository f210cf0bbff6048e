"""Compiled loops (numba) for the hot spots of stripe matching, each the exact loop form of a NumPy
function it replaces: the same floating-point operations in the same order (np.einsum sums three
products as (x + z) + y), or a screened formula that leaves to the exact NumPy one every case rounding
could decide, so the labels come out to the bit.

numba compiles a kernel on its first call (a few seconds for all of them) and caches the machine code
in ``__pycache__`` beside this file, else in ``NUMBA_CACHE_DIR`` or the user's cache directory; where
none is writable the kernels are compiled in memory on each start."""

from __future__ import annotations

import logging

import numpy as np
from numba import njit

_log = logging.getLogger(__name__)
_OPTIONS = {"nogil": True, "error_model": "numpy"}  # numpy: x / 0 is inf or NaN, no exception
_UNCACHED: list[str] = []  # kernels compiled without a cache


def _jit(fn):
    """``njit`` with an on-disk cache when numba finds a writable place for one."""
    try:
        return njit(cache=True, **_OPTIONS)(fn)
    except RuntimeError:  # numba: "cannot cache function ...: no locator available"
        if not _UNCACHED:
            _log.warning("numba finds no writable cache directory for %s: the kernels compile on each start "
                         "(set NUMBA_CACHE_DIR)", __file__)
        _UNCACHED.append(fn.__name__)
        return njit(**_OPTIONS)(fn)


@_jit
def _nearest_shifted(key, shift):
    """For each entry of sorted ``key`` (K,) float64, the index (K,) of the entry nearest ``key + shift``
    (the lower of a tie) and the distance (K,): ``segments._nearest_key(key, key + shift)``. The targets
    are sorted too, so one sweep finds every ``np.searchsorted(key, target)`` ('left')."""
    n = len(key)
    best = np.empty(n, np.int64)
    dist = np.empty(n)
    p = 0
    prev = -np.inf
    for i in range(n):
        t = key[i] + shift
        if t < prev:  # not sorted after all: search afresh
            p = np.searchsorted(key, t)
        prev = t
        while p < n and key[p] < t:
            p += 1
        hi = min(max(p, 1), n - 1)  # clipped as np.clip does
        lo = hi - 1 if hi > 0 else n - 1  # numpy's key[-1] when the key holds one entry
        d_lo, d_hi = abs(key[lo] - t), abs(key[hi] - t)
        if d_hi < d_lo:
            best[i], dist[i] = hi, d_hi
        else:
            best[i], dist[i] = lo, d_lo
    return best, dist


@_jit
def _root(parent, i):
    """Root of ``i`` in the union-find forest ``parent`` (M,), halving the path on the way."""
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@_jit
def link_components(key, link_px):
    """Component id (M,) per centre in row order, ``key`` (M,) = row * 1e5 + column (sorted): centres one
    or two rows apart within ``link_px`` (times the gap) columns, mutual nearest, joined; components
    numbered by their first centre, as scipy's ``connected_components`` numbers them."""
    m = len(key)
    parent = np.arange(m)
    for gap in (1, 2):
        down, d = _nearest_shifted(key, gap * 1e5)
        up, _ = _nearest_shifted(key, -gap * 1e5)
        for a in range(m):
            b = down[a]
            # within reach, and mutual: b's nearest in the row above is a
            if d[a] <= link_px * gap and up[b] == a:
                ra, rb = _root(parent, a), _root(parent, b)
                if ra != rb:
                    parent[max(ra, rb)] = min(ra, rb)
    comp = np.empty(m, np.int64)
    label = np.full(m, -1, np.int64)
    nxt = 0
    for i in range(m):
        r = _root(parent, i)
        if label[r] < 0:
            label[r] = nxt
            nxt += 1
        comp[i] = label[r]
    return comp


@_jit
def _prefix(x, a, length, out):
    """``out[:length + 1]`` = np.r_[0, np.cumsum(x[a:a + length])] (sequential sums)."""
    out[0] = 0.0
    for j in range(length):
        out[j + 1] = out[j] + x[a + j]


@_jit
def _slope(cu, cv, cuv, cvv, lo, hi, n):
    """Least-squares slope du/dv over the window [lo, hi) of running sums (``segments._slopes``)."""
    su, sv = cu[hi] - cu[lo], cv[hi] - cv[lo]
    suv, svv = cuv[hi] - cuv[lo], cvv[hi] - cvv[lo]
    den = n * svv - sv * sv
    if den > 1e-9:
        return (n * suv - su * sv) / max(den, 1e-9)
    return 0.0


@_jit
def _nan_max(a, b):
    """np.maximum(a, b) for two floats (NaN wins)."""
    if a != a:
        return a
    if b != b:
        return b
    return a if a >= b else b


@_jit
def change_cuts(order, starts, logc, u, v, window, log_ratio, slope_change, out, nxt):
    """``segments.split_at_changes``'s cuts, written into ``out`` (M,) segment ids: each run
    ``order[starts[r]:starts[r + 1]]`` (centres of one segment, top down) long enough is scored row by
    row (brightness jump over ``log_ratio``, direction kink over ``slope_change``) and cut greedily, new
    ids from ``nxt`` in run order. logc, u, v : (M,) float64 log contrast, columns, rows."""
    longest = 0
    for r in range(len(starts) - 1):
        longest = max(longest, starts[r + 1] - starts[r])
    cs = np.empty(longest + 1)
    cu = np.empty(longest + 1)
    cv = np.empty(longest + 1)
    cuv = np.empty(longest + 1)
    cvv = np.empty(longest + 1)
    x = np.empty((5, longest))
    score = np.empty(longest)
    w = window
    nf = float(window)
    for r in range(len(starts) - 1):
        a, length = starts[r], starts[r + 1] - starts[r]
        if length < 2 * w + 2:
            continue
        for j in range(length):
            i = order[a + j]
            uu, vv = u[i], v[i]
            x[0, j], x[1, j], x[2, j], x[3, j], x[4, j] = logc[i], uu, vv, uu * vv, vv * vv
        _prefix(x[0], 0, length, cs)
        _prefix(x[1], 0, length, cu)
        _prefix(x[2], 0, length, cv)
        _prefix(x[3], 0, length, cuv)
        _prefix(x[4], 0, length, cvv)
        k = length - 2 * w
        any_cut = False
        for j in range(k):
            before = (cs[w + j] - cs[j]) / w
            after = (cs[2 * w + j] - cs[w + j]) / w
            sb = _slope(cu, cv, cuv, cvv, j, w + j, nf)
            sa = _slope(cu, cv, cuv, cvv, w + j, 2 * w + j, nf)
            score[j] = _nan_max(abs(after - before) / log_ratio, abs(sa - sb) / slope_change)
            any_cut |= score[j] >= 1.0
        if not any_cut:
            continue
        j = 0
        while True:  # greedy: from each score >= 1 the highest within the window, then past it
            while j < k and not score[j] >= 1.0:
                j += 1
            if j >= k:
                break
            top = j
            for q in range(j + 1, min(j + w, k)):  # np.argmax: the first maximum, or the first NaN
                if score[top] != score[top]:
                    break
                if score[q] > score[top] or score[q] != score[q]:
                    top = q
            for q in range(a + w + top, a + length):
                out[order[q]] = nxt
            nxt += 1
            j = top + w
    return nxt


@_jit
def screened_bins(rays, planes, centre, axis, bins, margin, out):
    """``offsets._bins_on_planes_chunk`` ray by ray: into ``out`` (S, N) int64 the elevation bin of
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
        rr[i] = r0[i] * r0[i] + r1[i] * r1[i] + r2[i] * r2[i]
        ra[i] = axis[0] * r0[i] + axis[1] * r1[i] + axis[2] * r2[i]
        rc[i] = centre[0] * r0[i] + centre[1] * r1[i] + centre[2] * r2[i]
        rsize[i] = 1e-3 * (abs(r0[i]) + abs(r1[i]) + abs(r2[i]))
    unsure = np.empty(s_n * n, np.int64)
    m = 0
    floor, sure = np.empty(s_n), np.empty(s_n, np.bool_)
    for k in range(n):  # plane by plane: the unsure ones come out plane-major, as np.flatnonzero of (N, S)
        p0, p1, p2, d = planes[k, 0], planes[k, 1], planes[k, 2], planes[k, 3]
        for i in range(s_n):  # no branch: the loop runs on vector lanes (IEEE operations all the same)
            dot = p0 * r0[i] + p1 * r1[i] + p2 * r2[i]
            size = abs(dot)
            s = d / dot
            along = s * ra[i] - ca
            q2 = (s * rr[i] - 2 * rc[i]) * s + cc  # |s r - c|^2
            across2 = q2 - along * along
            f = along / (np.sqrt(across2) * bins)
            fl = np.floor(f)
            frac = f - fl
            floor[i] = fl
            sure[i] = ((size > rsize[i]) & (size > 1e-6) & (across2 > 1e-4 * (q2 + cc)) & (frac > tau)
                       & (frac < 1 - tau))
        for i in range(s_n):
            if sure[i]:
                out[i, k] = np.int64(floor[i])
            else:
                unsure[m] = k * s_n + i
                m += 1
    return unsure[:m]


@_jit
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


@_jit
def _depth(rays, i, planes, k):
    """``triangulation.depth_on`` of ray i on plane k (mm): n . r summed as np.einsum sums three terms
    ((x + z) + y), NaN where the ray is parallel to the plane."""
    denom = (rays[i, 0] * planes[k, 0] + rays[i, 2] * planes[k, 2]) + rays[i, 1] * planes[k, 1]
    s = planes[k, 3] / denom
    if abs(denom) < 1e-9:
        s = np.nan
    return rays[i, 2] * s


@_jit
def voting_pairs(own_seg, nb_seg, table, active, relabel):
    """Positions (K,) of the pairs (own segments, neighbour segments (P,)) that vote: own segment
    flagged in ``active`` (S,), unlabelled in ``table`` (S,) (labelled with ``relabel``), neighbour's
    labelled."""
    out = np.empty(len(own_seg), np.int64)
    m = 0
    for p in range(len(own_seg)):
        if active[own_seg[p]] and table[nb_seg[p]] >= 0 and (table[own_seg[p]] >= 0) == relabel:
            out[m] = p
            m += 1
    return out[:m]


@_jit
def depth_votes(rays, planes, table, cols, at, gaps, tol_mm, n, penalty_mm, step):
    """The label (K,) each voting pair ``cols[:, at]`` (``matching._Pairs`` rows) casts by depth
    continuity: the neighbour's label stepped by each gap (toward the voter) whose plane puts the voter
    nearest the neighbour's depth (extrapolated by ``step`` (K,) mm per stripe when given, else
    empty), a wider gap paying ``penalty_mm`` per extra stripe; -1 where none is within ``tol_mm``."""
    best = np.full(len(at), -1, np.int64)
    for q in range(len(at)):
        p = at[q]
        idx, nbr, sign = cols[0, p], cols[1, p], cols[2, p]
        kn = table[cols[4, p]]
        zn = _depth(rays, nbr, planes, kn)
        best_d = np.inf
        for gap in gaps:
            k = kn + sign * gap
            ref = zn + step[q] * gap if len(step) else zn
            d = abs(_depth(rays, idx, planes, min(max(k, 0), n - 1)) - ref)
            d = d + (gap - 1) * penalty_mm
            if 0 <= k < n and d < best_d and d < tol_mm:
                best[q], best_d = k, d
    return best


@_jit
def majority(voter, vote, n, min_share):
    """``matching._majority`` as arrays: segments (G,) and labels (G,) of the segments whose most frequent
    vote (the earliest cast of a tie) has at least 3 votes and ``min_share`` of their voters, in the
    order the segments first got a vote. voter : (V,) segment ids; vote : (V,) labels, -1 for none."""
    support = np.bincount(voter)
    cast = np.flatnonzero(vote >= 0)
    key = voter[cast] * (n + 1) + vote[cast]
    order = np.argsort(key, kind="mergesort")  # stable: a run's first entry was cast first
    segs = np.empty(len(cast), np.int64)
    labs = np.empty(len(cast), np.int64)
    firsts = np.empty(len(cast), np.int64)
    m = 0
    j = 0
    while j < len(order):
        seg = key[order[j]] // (n + 1)
        top_cnt, top_lab, top_first, seg_first = 0, -1, 0, len(cast)
        while j < len(order) and key[order[j]] // (n + 1) == seg:  # the runs of one segment, labels rising
            a = j
            while j < len(order) and key[order[j]] == key[order[a]]:
                j += 1
            cnt, first = j - a, order[a]
            seg_first = min(seg_first, first)
            if cnt > top_cnt or (cnt == top_cnt and first < top_first):
                top_cnt, top_lab, top_first = cnt, key[order[a]] % (n + 1), first
        if top_cnt >= 3 and top_cnt >= min_share * support[seg]:
            segs[m], labs[m], firsts[m] = seg, top_lab, seg_first
            m += 1
    by_first = np.argsort(firsts[:m])
    return segs[:m][by_first], labs[:m][by_first]


@_jit
def _median5(a, b, c, d, e):
    """The median of five floats (finite): the larger of the two smaller of the first four's pairs and
    the smaller of their larger, then the median of those two and e (the value a sort would pick)."""
    lo = max(min(a, b), min(c, d))
    hi = min(max(a, b), max(c, d))
    return max(min(lo, hi), min(max(lo, hi), e))


@_jit
def smooth_runs(order, starts, u, half, outlier_px, out, keep):
    """``segments.smooth_along_segments`` run by run: each run ``order[starts[r]:starts[r + 1]]`` (one
    segment's centres, top down) at least 2 ``half`` + 1 long gets into ``out`` (M,) its columns ``u``
    (M,) px averaged over +-``half`` rows (edges repeated), a column more than ``outlier_px`` off the
    median of its window replaced by that median and flagged False in ``keep`` (M,). The sums run as
    np.cumsum runs them over the edge-padded run, so they round alike."""
    win = 2 * half + 1
    longest = 0
    for r in range(len(starts) - 1):
        longest = max(longest, starts[r + 1] - starts[r])
    xp = np.empty(longest + 2 * half)
    good = np.empty(longest + 2 * half)
    cs = np.empty(longest + 2 * half + 1)
    for r in range(len(starts) - 1):
        a, length = starts[r], starts[r + 1] - starts[r]
        if length < win:
            continue
        for t in range(length + 2 * half):
            xp[t] = u[order[a + min(max(t - half, 0), length - 1)]]
        for j in range(length):
            if win == 5:
                med = _median5(xp[j], xp[j + 1], xp[j + 2], xp[j + 3], xp[j + 4])
            else:
                med = np.sort(xp[j:j + win])[half]
            x = xp[j + half]
            if abs(x - med) > outlier_px:
                good[j] = med
                keep[order[a + j]] = False
            else:
                good[j] = x
        cs[0] = 0.0
        for t in range(length + 2 * half):
            cs[t + 1] = cs[t] + good[min(max(t - half, 0), length - 1)]
        for j in range(length):
            out[order[a + j]] = (cs[j + win] - cs[j]) / win


@_jit
def near_any_plane(rays, planes, bg_planes, tol_mm, near):
    """Into ``near`` (m, N) bool: whether ray i's point on light plane k (N, 4) lies within ``tol_mm``
    of a background plane (P, 4), screened as |z (ray . n) - d|; returns the positions i N + k (U,),
    sorted, where rounding could decide (within 1e-6 mm of ``tol_mm``, |z| >= 1e5 or not finite),
    which the exact formula (``background._near_exact``) must settle."""
    m, n = near.shape
    unsure = np.empty(m * n, np.int64)
    u = 0
    # the planes' columns apart: each ray's loop over the planes runs on vector lanes
    p0, p1 = np.ascontiguousarray(planes[:, 0]), np.ascontiguousarray(planes[:, 1])
    p2, p3 = np.ascontiguousarray(planes[:, 2]), np.ascontiguousarray(planes[:, 3])
    d, z = np.empty(n), np.empty(n)
    for i in range(m):
        r0, r1, r2 = rays[i, 0], rays[i, 1], rays[i, 2]
        for k in range(n):
            z[k] = p3[k] / (r0 * p0[k] + r1 * p1[k] + r2 * p2[k])
            d[k] = np.inf
        for b in range(len(bg_planes)):
            along = r0 * bg_planes[b, 0] + r1 * bg_planes[b, 1] + r2 * bg_planes[b, 2]
            for k in range(n):
                g = abs(z[k] * along - bg_planes[b, 3])
                d[k] = g if g < d[k] else d[k]  # NaN skipped, as np.fmin skips it
        for k in range(n):
            near[i, k] = d[k] < tol_mm
            if not (abs(d[k] - tol_mm) > 1e-6 and abs(z[k]) < 1e5):
                unsure[u] = i * n + k
                u += 1
    return unsure[:u]


@_jit
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


@_jit
def segment_steps(seg, rays, planes, table, nb, sign, measured, tol_mm, min_rows):
    """``matching._segment_steps`` for one side: the mean depth step (S,) mm from each centre's row
    neighbour ``nb`` (M,) (-1 for none) on the next stripe toward ``sign`` to the centre, per segment
    flagged in ``measured`` (S,); NaN where fewer than ``min_rows`` rows measure one within 2 ``tol_mm``.
    The steps are summed centre by centre in index order, as np.bincount sums its weights."""
    cnt = np.zeros(len(table), np.int64)
    tot = np.zeros(len(table))
    for i in range(len(seg)):
        s = seg[i]
        f = nb[i]
        if not measured[s] or f < 0:
            continue
        k, kf = table[s], table[seg[f]]
        if kf != k - sign or kf < 0:
            continue
        step = _depth(rays, i, planes, k) - _depth(rays, f, planes, kf)
        if abs(step) < 2 * tol_mm:
            cnt[s] += 1
            tot[s] += step
    out = np.empty(len(table))
    for s in range(len(table)):
        out[s] = tot[s] / max(cnt[s], 1) if cnt[s] >= min_rows else np.nan
    return out


@_jit
def flag_beside(own_seg, nb_seg, flags):
    """(S,) the segments ``own_seg`` (P,) of the pairs whose neighbour's segment ``nb_seg`` (P,) is
    flagged in ``flags`` (S,)."""
    out = np.zeros(len(flags), np.bool_)
    for p in range(len(own_seg)):
        if flags[nb_seg[p]]:
            out[own_seg[p]] = True
    return out


@_jit
def flag_touching(seg, left, right, flags):
    """(S,) the segments flagged in ``flags`` (S,) and those with a centre beside one of theirs in its
    row (``left``, ``right`` (M,): row neighbours, -1 for none)."""
    out = flags.copy()
    for i in range(len(seg)):
        if flags[seg[i]]:
            if left[i] >= 0:
                out[seg[left[i]]] = True
            if right[i] >= 0:
                out[seg[right[i]]] = True
    return out


@_jit
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


@_jit
def neighbour_pairs(seg, mask, left, right):
    """``matching._neighbour_pairs``' rows (7, K): for each centre in ``mask`` (M,) whose row neighbour
    on a side (``left``, then ``right`` (M,), -1 for none) lies in another segment, the centre, that
    neighbour, the sign of the label step toward the centre (1 from the left, -1 from the right), the
    segments of both, and the neighbour's own neighbour further out with its segment (-1 where none);
    the left side's pairs first, each side's in centre order."""
    count = 0
    for i in range(len(seg)):
        if mask[i]:
            count += (left[i] >= 0 and seg[left[i]] != seg[i]) + (right[i] >= 0 and seg[right[i]] != seg[i])
    cols = np.empty((7, count), np.int64)
    p = 0
    for side in range(2):
        nb = left if side == 0 else right
        for i in range(len(seg)):
            f = nb[i]
            if mask[i] and f >= 0 and seg[f] != seg[i]:
                far = nb[f]
                cols[0, p], cols[1, p], cols[2, p] = i, f, 1 - 2 * side
                cols[3, p], cols[4, p] = seg[i], seg[f]
                cols[5, p], cols[6, p] = far, seg[far] if far >= 0 else -1
                p += 1
    return cols


@_jit
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


@_jit
def grow_by_depth(rays, planes, table, cols, tol_mm, n, gaps, penalty_mm, min_share, rounds):
    """``matching._grow_all`` by depth continuity alone (no slope, no plane test): rounds of
    ``depth_votes`` and ``majority`` by the pairs ``cols`` (``matching._Pairs`` rows) of the segments
    beside one labelled the round before, until none joins; updates ``table`` (S,) and returns the
    segments (G,) and labels (G,) in the order they joined."""
    newly = table >= 0
    out_seg = np.empty(len(table), np.int64)
    out_lab = np.empty(len(table), np.int64)
    m = 0
    no_step = np.zeros(0)
    for _ in range(rounds):
        # only segments beside a newly labelled one can vote differently from the round before
        active = flag_beside(cols[3], cols[4], newly)
        at = voting_pairs(cols[3], cols[4], table, active, False)
        if len(at) == 0:
            break
        best = depth_votes(rays, planes, table, cols, at, gaps, tol_mm, n, penalty_mm, no_step)
        segs, labs = majority(cols[3][at], best, n, min_share)
        if len(segs) == 0:
            break
        newly[:] = False
        for g in range(len(segs)):
            table[segs[g]] = labs[g]
            newly[segs[g]] = True
            out_seg[m], out_lab[m] = segs[g], labs[g]
            m += 1
    return out_seg[:m], out_lab[:m]


@_jit
def gapped_rows(u, order, m, n, window, slack, labels):
    """``matching._gapped_rows`` row by row: the rows ``order`` (R m,) (m centres each, left to right,
    columns ``u`` (M,) px) whose gaps are each one or two local spacings (the median gap of the odd
    ``window`` around it, the row's end gaps repeated), within ``slack``, adding up to n - 1, with a
    smoothly changing spacing per stripe, get their labels (0, then the running sum of the steps)
    written into ``labels`` (M,)."""
    pad = window // 2
    gaps, r, k, per = np.empty(m - 1), np.empty(m - 1), np.empty(m - 1), np.empty(m - 1)
    win = np.empty(window)
    for row in range(len(order) // m):
        at = order[row * m:(row + 1) * m]
        for j in range(m - 1):
            gaps[j] = u[at[j + 1]] - u[at[j]]
        ok = True
        total = 0.0
        for j in range(m - 1):
            for t in range(window):  # an insertion sort: a handful of values
                g = gaps[min(max(j - pad + t, 0), m - 2)]
                q = t
                while q > 0 and win[q - 1] > g:
                    win[q] = win[q - 1]
                    q -= 1
                win[q] = g
            r[j] = gaps[j] / max(win[pad], 1e-6)  # the median: the middle value of an odd window
            k[j] = np.rint(r[j])
            per[j] = gaps[j] / max(k[j], 1.0)
            total += k[j]
            ok &= k[j] >= 1 and k[j] <= 2 and abs(r[j] - k[j]) < slack and gaps[j] > 2
        for j in range(m - 2):
            ratio = per[j + 1] / max(per[j], 1e-6)
            ok &= ratio > 0.7 and ratio < 1.43
        if ok and total == n - 1:
            lab = 0
            labels[at[0]] = 0
            for j in range(m - 1):
                lab += np.int64(k[j])
                labels[at[j + 1]] = lab


@_jit
def _point(rays, i, planes, k, j):
    """Coordinate j of ``triangulation.intersect`` of ray i with plane k (mm)."""
    denom = (rays[i, 0] * planes[k, 0] + rays[i, 2] * planes[k, 2]) + rays[i, 1] * planes[k, 1]
    s = planes[k, 3] / denom
    if abs(denom) < 1e-9:
        s = np.nan
    return rays[i, j] * s


@_jit
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
