"""Segment linking, change cuts and smoothing along segments (``measurement.segments``)."""

from __future__ import annotations

import numpy as np

from .jit import compiled


@compiled
def _nearest_shifted(key, shift):
    """For each entry of sorted ``key`` (K,) float64, the index (K,) of the entry nearest ``key + shift``
    (the lower of a tie) and the distance (K,): np.searchsorted(key, target) clipped to [1, K - 1], then
    the nearer of the entries either side (the lower when equally near). The targets
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


@compiled
def _root(parent, i):
    """Root of ``i`` in the union-find forest ``parent`` (M,), halving the path on the way."""
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@compiled
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


@compiled
def _prefix(x, a, length, out):
    """``out[:length + 1]`` = np.r_[0, np.cumsum(x[a:a + length])] (sequential sums)."""
    out[0] = 0.0
    for j in range(length):
        out[j + 1] = out[j] + x[a + j]


@compiled
def _slope(cu, cv, cuv, cvv, lo, hi, n):
    """Least-squares slope du/dv over the window [lo, hi) of running sums cu, cv, cuv, cvv (0 where
    the rows' spread is under 1e-9)."""
    su, sv = cu[hi] - cu[lo], cv[hi] - cv[lo]
    suv, svv = cuv[hi] - cuv[lo], cvv[hi] - cvv[lo]
    den = n * svv - sv * sv
    if den > 1e-9:
        return (n * suv - su * sv) / max(den, 1e-9)
    return 0.0


@compiled
def _nan_max(a, b):
    """np.maximum(a, b) for two floats (NaN wins)."""
    if a != a:
        return a
    if b != b:
        return b
    return a if a >= b else b


@compiled
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


@compiled
def _median5(a, b, c, d, e):
    """The median of five floats (finite): the larger of the two smaller of the first four's pairs and
    the smaller of their larger, then the median of those two and e (the value a sort would pick)."""
    lo = max(min(a, b), min(c, d))
    hi = min(max(a, b), max(c, d))
    return max(min(lo, hi), min(max(lo, hi), e))


@compiled
def smooth_runs(order, starts, v, u, half, reach, outlier_px, out, keep):
    """``segments.smooth_along_stripes`` run by run: each run ``order[starts[r]:starts[r + 1]]`` (one
    stripe's chained segments, top down, rows ``v`` (M,)) at least 2 ``half`` + 1 long gets into ``out`` (M,) its
    columns ``u`` (M,) px as a straight line fitted by least squares to the run's centres within ``reach``
    rows of it (fewer at the run's ends: the line is not pulled there as an average of repeated end values
    was) gives them at its row. First a column more than ``outlier_px`` off the median of the 2 ``half`` + 1
    around it (the run's end values repeated) is replaced by that median in the fit and flagged False in
    ``keep`` (M,)."""
    win = 2 * half + 1
    longest = 0
    for r in range(len(starts) - 1):
        longest = max(longest, starts[r + 1] - starts[r])
    xp = np.empty(longest + 2 * half)
    good = np.empty(longest + 2 * half)
    rows = np.empty(longest, np.int64)
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
        # the line through the centres within reach rows of centre j: sums over the window [lo, hi), rows
        # and columns counted from the run's first centre, slid down the run
        v_first, u_first = v[order[a]], good[0]
        for t in range(length):
            rows[t] = v[order[a + t]] - v_first
        lo, hi = 0, 0
        s0, s1, s2, su, sdu = 0.0, 0.0, 0.0, 0.0, 0.0
        for j in range(length):
            while hi < length and rows[hi] <= rows[j] + reach:
                d, x = float(rows[hi]), good[hi] - u_first
                s0 += 1.0
                s1 += d
                s2 += d * d
                su += x
                sdu += d * x
                hi += 1
            while rows[lo] < rows[j] - reach:
                d, x = float(rows[lo]), good[lo] - u_first
                s0 -= 1.0
                s1 -= d
                s2 -= d * d
                su -= x
                sdu -= d * x
                lo += 1
            det = s0 * s2 - s1 * s1
            if hi - lo >= 3 and det > 0.5:  # (a whole number: 0 when all the window's rows are one)
                dj = float(rows[j])
                slope = (s0 * sdu - s1 * su) / det
                out[order[a + j]] = u_first + (su - slope * s1) / s0 + slope * dj
            else:
                out[order[a + j]] = u_first + su / s0


@compiled
def run_scatter(order, starts, u, smooth, keep, least):
    """Per run ``order[starts[r]:starts[r + 1]]`` (R,): the median distance (px) of its kept (``keep`` (M,))
    columns ``u`` (M,) from their smoothed ones ``smooth`` (M,); 0 for a run with fewer than ``least`` kept
    (``segments.smooth_along_stripes``' noisy runs)."""
    out = np.zeros(len(starts) - 1)
    longest = 0
    for r in range(len(starts) - 1):
        longest = max(longest, starts[r + 1] - starts[r])
    d = np.empty(longest)
    for r in range(len(starts) - 1):
        n = 0
        for t in range(starts[r], starts[r + 1]):
            i = order[t]
            if keep[i]:
                d[n] = abs(u[i] - smooth[i])
                n += 1
        if n >= least:
            out[r] = np.median(d[:n])
    return out


@compiled
def crowded(row, col, h, size):
    """Whether each centre's pixel (``row``, ``col``) (M,) int64 has at least ``size / 2`` marked pixels in
    the ``size`` x ``size`` square OpenCV's unnormalised ``boxFilter`` sums there (anchor ``size // 2``,
    zero border) over a mask of ``h`` rows marking every centre's pixel once: the same counts, read off
    a column histogram of the marked pixels in the square's rows, which slides down the frame (each row's
    marks enter and leave it once)."""
    m = len(row)
    if m == 0:
        return np.zeros(0, np.bool_)
    half = size // 2
    start = np.zeros(h + 1, np.int64)
    for i in range(m):
        start[row[i] + 1] += 1
    for r in range(h):
        start[r + 1] += start[r]
    who = np.empty(m, np.int64)  # the centres row by row
    fill = start[:h].copy()
    for i in range(m):
        who[fill[row[i]]] = i
        fill[row[i]] += 1
    # a pixel counts once: ``first`` marks the first centre of each (row, column) in the row's list
    width = col.max() + 1
    seen = np.full(width, -1, np.int64)
    first = np.zeros(m, np.bool_)
    for r in range(h):
        for j in range(start[r], start[r + 1]):
            x = col[who[j]]
            if seen[x] != r:
                seen[x] = r
                first[j] = True
    hist = np.zeros(width + size, np.int64)  # marks per column in the square's rows, offset by half
    n = np.zeros(m, np.int64)
    lo, hi = 0, 0  # rows [lo, hi) are in the histogram
    for v in range(h):
        if start[v] == start[v + 1]:
            continue
        a, b = max(v - half, 0), min(v - half + size, h)
        while hi < b:
            for j in range(start[hi], start[hi + 1]):
                if first[j]:
                    hist[col[who[j]] + half] += 1
            hi += 1
        while lo < a:
            for j in range(start[lo], start[lo + 1]):
                if first[j]:
                    hist[col[who[j]] + half] -= 1
            lo += 1
        for j in range(start[v], start[v + 1]):
            # columns col - half .. col - half + size - 1 sit at col .. col + size - 1 in hist
            x = col[who[j]]
            total = 0
            for k in range(x, x + size):
                total += hist[k]
            n[who[j]] = total
    return 2 * n >= size


@compiled
def group_members(keys, n_keys):
    """The positions of each key's entries among integer ``keys`` (K,) in [0, ``n_keys``), ascending: group
    starts (n_keys + 1,) and positions (K,) (a stable counting sort)."""
    starts = np.zeros(n_keys + 1, np.int64)
    for i in range(len(keys)):
        starts[keys[i] + 1] += 1
    for s in range(n_keys):
        starts[s + 1] += starts[s]
    fill = starts[:-1].copy()
    members = np.empty(len(keys), np.int64)
    for i in range(len(keys)):
        members[fill[keys[i]]] = i
        fill[keys[i]] += 1
    return starts, members


@compiled
def stable_group_order(keys, n_keys):
    """``np.argsort(keys, kind="stable")`` for integer keys (K,) in [0, ``n_keys``): a counting sort."""
    return group_members(keys, n_keys)[1]


@compiled
def segment_row_order(seg, v):
    """``np.lexsort((v, seg))`` for non-negative segment ids ``seg`` (M,) and integer rows ``v`` (M,): the
    centres by segment, then row, ties in index order. Two stable counting sorts (by row, then by
    segment) instead of a comparison sort."""
    if len(seg) == 0:
        return np.empty(0, np.int64)
    v_lo = v.min()
    by_row = stable_group_order(v.astype(np.int64) - v_lo, np.int64(v.max()) - v_lo + 1)
    return by_row[stable_group_order(seg[by_row], seg.max() + 1)]


@compiled
def row_order_breaks(order, v, labels):
    """``matching._enforce_row_order``'s drops (M,) bool: along ``order`` (the centres by row, then column),
    each pair of consecutive labelled centres (labels (M,) >= 0) in one row (v (M,)) whose labels do not
    increase marks both."""
    drop = np.zeros(len(labels), np.bool_)
    prev = -1
    for j in range(len(order)):
        i = order[j]
        if labels[i] < 0:
            continue
        if prev >= 0 and v[prev] == v[i] and labels[i] <= labels[prev]:
            drop[i] = True
            drop[prev] = True
        prev = i
    return drop


@compiled
def walk_ends(pool_key, pool_u, pool_v, pool_lab, span, u, v, slope, step, lab, link, rows, gaps):
    """``ends.faint_ends``' walks, all in step: each walk (W,) at column u, row v, with the stripe's
    slope du/dv, moving ``step`` (+-1) rows at a time, label ``lab``, steps to the nearest peak of the
    pool (sorted by ``pool_key`` = v * span + u) in the next row (or up to ``gaps`` rows on) within
    ``link`` of u + slope * the rows moved, not taken before and labelled -1 or ``lab``; two walks
    reaching the same peak both stop there (and it is taken). Up to ``rows`` steps. Returns the peaks'
    columns, rows, labels and walks (E,), step by step, each step's walks ascending."""
    n_w = len(u)
    u = u.copy()
    v = v.copy()
    slope = slope.copy()
    taken = np.zeros(len(pool_key), np.bool_)
    claim = np.full(len(pool_key), -1, np.int64)  # in a step: the walk that reached a peak (-2: two did)
    active = np.ones(n_w, np.bool_)
    best = np.full(n_w, -1, np.int64)
    out_u = np.empty(n_w * rows)
    out_v = np.empty(n_w * rows, np.int64)
    out_k = np.empty(n_w * rows, np.int64)
    out_w = np.empty(n_w * rows, np.int64)
    e = 0
    for _ in range(rows):
        moving = 0
        for w in range(n_w):
            best[w] = -1
            if not active[w]:
                continue
            for gap in range(1, gaps + 1):
                want_u = u[w] + slope[w] * step[w] * gap
                key = (v[w] + step[w] * gap) * span + want_u
                lo = np.searchsorted(pool_key, key - link)
                hi = np.searchsorted(pool_key, key + link, side="right")
                best_d = np.inf
                for j in range(lo, hi):
                    if taken[j] or (pool_lab[j] >= 0 and pool_lab[j] != lab[w]):
                        continue
                    d = abs(pool_u[j] - want_u)
                    if d < best_d:
                        best_d = d
                        best[w] = j
                if best[w] >= 0:
                    break
            if best[w] >= 0:
                claim[best[w]] = w if claim[best[w]] == -1 else -2
                moving += 1
        if moving == 0:
            break
        for w in range(n_w):
            if not active[w]:
                continue
            j = best[w]
            if j < 0 or claim[j] == -2:
                active[w] = False
                continue
            moved = pool_v[j] - v[w]
            slope[w] = 0.5 * slope[w] + 0.5 * (pool_u[j] - u[w]) / moved
            u[w], v[w] = pool_u[j], pool_v[j]
            out_u[e], out_v[e], out_k[e], out_w[e] = u[w], v[w], lab[w], w
            e += 1
        for w in range(n_w):
            if best[w] >= 0:
                taken[best[w]] = True
                claim[best[w]] = -1
    return out_u[:e], out_v[:e], out_k[:e], out_w[:e]


@compiled
def walk_stops(walk, near, other, run_rows, keep):
    """``ends.end_points``' stops: along the walks' points (E,) listed step by step (``walk`` (E,) the walk of
    each; within a step every walk at most once), clears ``keep`` (E,) bool from the first point ``near``
    (E,) a background plane on, and from the point ``run_rows`` + 1 into a run of points that one other
    light plane ``other`` (E,) (-1: none) puts on a background plane. Point by point in order: the same as
    the NumPy form step by step, since no walk appears twice in a step."""
    if len(walk) == 0:
        return keep
    n_w = walk.max() + 1
    stopped = np.zeros(n_w, np.bool_)
    last_other = np.full(n_w, -1, np.int64)
    run = np.zeros(n_w, np.int64)
    for j in range(len(walk)):
        w, o = walk[j], other[j]
        if o >= 0 and o == last_other[w]:
            run[w] += 1
        else:
            run[w] = 1 if o >= 0 else 0
        end = near[j] or run[w] > run_rows
        keep[j] = keep[j] and not stopped[w] and not end
        if end:
            stopped[w] = True
        last_other[w] = o
    return keep


@compiled
def chain_runs(by_label, label, v0, u0, v1, u1, gap, jump):
    """The run each run goes on from (R,) int64, -1 for none: runs ``by_label`` (R,) (their order by label,
    then first row), each from (``v0``, ``u0``) to (``v1``, ``u1``), row and column of its first and last
    centre, with ``label`` (R,). A run goes on from the earlier run of its label that ends at most ``gap``
    rows before it starts, within ``jump`` px per row of its first centre's column, the nearest such in
    column; each run goes on into one run at most (``segments.smooth_along_stripes``)."""
    r = len(by_label)
    parent = np.full(r, -1, np.int64)
    taken = np.zeros(r, np.bool_)
    first = 0  # where the current label's runs start in by_label
    for i in range(r):
        s = by_label[i]
        if i > 0 and label[s] != label[by_label[i - 1]]:
            first = i
        best, best_du = -1, np.inf
        for j in range(first, i):
            t = by_label[j]
            rows = v0[s] - v1[t]
            if taken[t] or rows < 1 or rows > gap + 1:
                continue
            du = abs(u0[s] - u1[t])
            if du <= jump * rows and du < best_du:
                best, best_du = t, du
        if best >= 0:
            parent[s] = best
            taken[best] = True
    return parent
