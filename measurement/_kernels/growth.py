"""Label growth by depth continuity, its votes and majorities, and the main rows (``measurement.matching``)."""

from __future__ import annotations

import numpy as np

from .jit import compiled
from .offsets import merge_distinct
from .rays import _depth, _point
from .segments import group_members


@compiled
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


@compiled
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


@compiled
def majority(voter, vote, n, min_share):
    """``matching._majority`` as arrays: segments (G,) and labels (G,) of the segments whose most frequent
    vote (the earliest cast of a tie) has at least 3 votes and ``min_share`` of their voters, in the
    order the segments first got a vote. voter : (V,) segment ids; vote : (V,) labels, -1 for none.

    Counted, not sorted: the voting segments numbered in the order of their first cast vote, and a
    count and a first cast per (segment, label), in O(V + segments x (n + 1)). (A stable sort of the
    (segment, label) keys did the same; numba's mergesort took 5 ms on 50 000 votes, a growth's
    majorities most of its time.)"""
    support = np.bincount(voter)
    w = n + 1
    number = np.full(len(support), -1, np.int64)  # each voting segment's place in the order of first votes
    segs_in_order = np.empty(len(vote), np.int64)
    g_count = 0
    for j in range(len(vote)):
        if vote[j] >= 0 and number[voter[j]] < 0:
            number[voter[j]] = g_count
            segs_in_order[g_count] = voter[j]
            g_count += 1
    cnt = np.zeros(g_count * w, np.int64)
    first = np.empty(g_count * w, np.int64)
    c = 0  # the position among the cast votes, as the sort's stable order counts it
    for j in range(len(vote)):
        if vote[j] >= 0:
            key = number[voter[j]] * w + vote[j]
            if cnt[key] == 0:
                first[key] = c
            cnt[key] += 1
            c += 1
    segs = np.empty(g_count, np.int64)
    labs = np.empty(g_count, np.int64)
    m = 0
    for g in range(g_count):
        top_cnt, top_lab, top_first = 0, -1, 0
        for lab in range(w):  # labels rising, as the sorted keys ran
            k = cnt[g * w + lab]
            if k > 0 and (k > top_cnt or (k == top_cnt and first[g * w + lab] < top_first)):
                top_cnt, top_lab, top_first = k, lab, first[g * w + lab]
        seg = segs_in_order[g]
        if top_cnt >= 3 and top_cnt >= min_share * support[seg]:
            segs[m], labs[m] = seg, top_lab
            m += 1
    return segs[:m], labs[:m]


@compiled
def grow_by_depth(rays, planes, table, cols, tol_mm, n, gaps, penalty_mm, min_share, rounds):
    """``matching._grow_all`` by depth continuity alone (no slope, no plane test): rounds of
    ``depth_votes`` and ``majority`` by the pairs ``cols`` (``matching._Pairs`` rows) of the segments
    beside one labelled the round before, until none joins; updates ``table`` (S,) and returns the
    segments (G,) and labels (G,) in the order they joined. The voting pairs of a round are found
    from the segments that joined in the last (``_voters``), not by a pass over all pairs."""
    by_nb = group_members(cols[4], len(table))
    by_own = group_members(cols[3], len(table))
    return _grow_rounds(rays, planes, table, cols, by_nb, by_own, np.flatnonzero(table >= 0), tol_mm, n, gaps,
                        penalty_mm, min_share, rounds, 0.0)


@compiled
def _grow_rounds(rays, planes, table, cols, by_nb, by_own, newly, tol_mm, n, gaps, penalty_mm, min_share, rounds,
                 cover):
    """``grow_by_depth``'s rounds with the pairs grouped (``pair_groups``), from the segments ``newly`` (G,)
    labelled last; updates ``table`` and returns the segments and labels that joined, in that order.

    With ``cover`` > 0 the best-supported join first: of a round's majorities only the segments with votes
    cast (a labelled neighbour) for at least ``cover`` of their pairs whose neighbour may still take part
    (-1 or labelled) join, unless none has (then all do); the others wait, and are voted on again in each
    later round, as their other neighbours join."""
    out_seg = np.empty(len(table), np.int64)
    out_lab = np.empty(len(table), np.int64)
    m = 0
    no_step = np.zeros(0)
    pending = np.zeros(0, np.int64)
    own_starts, own_pairs = by_own
    for _ in range(rounds):
        # only segments beside a newly labelled one can vote differently from the round before
        at = _voters(cols, table, newly, by_nb, by_own)
        if cover > 0 and len(pending):
            at = merge_distinct(at, _pairs_of(cols, table, pending, by_own))
        if len(at) == 0:
            break
        best = depth_votes(rays, planes, table, cols, at, gaps, tol_mm, n, penalty_mm, no_step)
        segs, labs = majority(cols[3][at], best, n, min_share)
        if len(segs) == 0:
            break
        if cover > 0:
            keep = np.zeros(len(segs), np.bool_)
            for g in range(len(segs)):
                vot, pot = 0, 0
                for j in range(own_starts[segs[g]], own_starts[segs[g] + 1]):
                    t = table[cols[4, own_pairs[j]]]
                    if t >= 0:
                        vot += 1
                    if t >= -1:
                        pot += 1
                keep[g] = vot >= cover * pot
            if keep.any():
                pending = np.unique(np.concatenate((pending, segs[~keep])))
                segs, labs = segs[keep], labs[keep]
        m = _join(table, segs, labs, out_seg, out_lab, m)
        if cover > 0 and len(pending):
            pending = pending[table[pending] == -1]
        newly = segs
    return out_seg[:m], out_lab[:m]


@compiled
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


@compiled
def flag_beside(own_seg, nb_seg, flags):
    """(S,) the segments ``own_seg`` (P,) of the pairs whose neighbour's segment ``nb_seg`` (P,) is
    flagged in ``flags`` (S,)."""
    out = np.zeros(len(flags), np.bool_)
    for p in range(len(own_seg)):
        if flags[nb_seg[p]]:
            out[own_seg[p]] = True
    return out


@compiled
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


@compiled
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


@compiled
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
        ok = True
        for j in range(m - 1):
            gaps[j] = u[at[j + 1]] - u[at[j]]
            ok &= gaps[j] > 2
        total = 0.0
        # a row that fails a test gets no labels: it is left at its first failure (the same rows pass)
        for j in range(m - 1):
            if not ok:
                break
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
            if not ok:
                break
            ratio = per[j + 1] / max(per[j], 1e-6)
            ok &= ratio > 0.7 and ratio < 1.43
        if ok and total == n - 1:
            lab = 0
            labels[at[0]] = 0
            for j in range(m - 1):
                lab += np.int64(k[j])
                labels[at[j + 1]] = lab


@compiled
def _slope_step(rays, planes, table, cols, p, zn, tol_mm):
    """For pair ``p`` (``matching._Pairs`` rows ``cols``): whether its neighbour's outer neighbour is on
    the next stripe (``has``), whether the step measured there is usable (evenly spaced, within 2
    ``tol_mm``), and that step, mm (``matching._slope_steps``' first part)."""
    idx, nbr, sign, far, far_seg = cols[0, p], cols[1, p], cols[2, p], cols[5, p], cols[6, p]
    kn = table[cols[4, p]]
    kf = table[far_seg] if far_seg >= 0 else -1
    if not (kf == kn - sign and kf >= 0):
        return False, False, 0.0
    zf = _depth(rays, far, planes, kf)
    near_dx = abs(rays[idx, 0] - rays[nbr, 0])
    far_dx = abs(rays[nbr, 0] - rays[far, 0])
    even = near_dx < 1.3 * far_dx and far_dx < 1.3 * near_dx
    valid = abs(zn - zf) < 2 * tol_mm and even
    return True, valid, (zn - zf) if valid else 0.0


@compiled
def _steps_of(s, starts, members, seg, rays, planes, table, nb, sign, tol_mm, min_rows):
    """``segment_steps``' value for the one segment ``s``, from its own centres (in index order)."""
    cnt = 0
    tot = 0.0
    k = table[s]
    for j in range(starts[s], starts[s + 1]):
        i = members[j]
        f = nb[i]
        if f < 0:
            continue
        kf = table[seg[f]]
        if kf != k - sign or kf < 0:
            continue
        step = _depth(rays, i, planes, k) - _depth(rays, f, planes, kf)
        if abs(step) < 2 * tol_mm:
            cnt += 1
            tot += step
    return tot / max(cnt, 1) if cnt >= min_rows else np.nan


@compiled
def grow_by_slope(rays, planes, table, cols, seg, left, right, tol_mm, n, gaps, penalty_mm, min_share, rounds,
                  min_rows):
    """``matching._grow_all`` with ``slope`` (depth only, no plane test) as one loop: rounds of
    ``segment_steps`` (both sides; after the first round only for the segments touching the last round's
    joins, from their own centres), the voting pairs' extrapolated steps (``matching._slope_steps``),
    ``depth_votes`` and ``majority`` among the segments beside one labelled the round before, until none
    joins. Updates ``table`` (S,) and returns the segments (G,) and labels (G,) in the order they joined."""
    n_seg = len(table)
    labelled = table >= 0
    by_nb = group_members(cols[4], n_seg)
    by_own = group_members(cols[3], n_seg)
    joined = np.flatnonzero(labelled)
    out_seg = np.empty(n_seg, np.int64)
    out_lab = np.empty(n_seg, np.int64)
    m = 0
    starts, members = group_members(seg, n_seg)
    steps_l = segment_steps(seg, rays, planes, table, left, 1, labelled, tol_mm, min_rows)
    steps_r = segment_steps(seg, rays, planes, table, right, -1, labelled, tol_mm, min_rows)
    cnt = np.zeros(2 * n_seg, np.int64)
    tot = np.zeros(2 * n_seg)
    touched = np.zeros(n_seg, np.bool_)
    for _ in range(rounds):
        at = _voters(cols, table, joined, by_nb, by_own)
        if len(at) == 0:
            break
        k_at = len(at)
        step = np.zeros(k_at)
        has = np.zeros(k_at, np.bool_)
        for q in range(k_at):
            p = at[q]
            key = cols[4, p] if cols[2, p] > 0 else cols[4, p] + n_seg
            cnt[key] = 0
            tot[key] = 0.0
        for q in range(k_at):
            p = at[q]
            zn = _depth(rays, cols[1, p], planes, table[cols[4, p]])
            h, valid, st = _slope_step(rays, planes, table, cols, p, zn, tol_mm)
            has[q] = h
            step[q] = st
            if h and valid:
                key = cols[4, p] if cols[2, p] > 0 else cols[4, p] + n_seg
                cnt[key] += 1
                tot[key] += st
        for q in range(k_at):
            p = at[q]
            if has[q]:
                continue
            key = cols[4, p] if cols[2, p] > 0 else cols[4, p] + n_seg
            if cnt[key] >= 3:
                step[q] = tot[key] / max(cnt[key], 1)
            if step[q] == 0.0:
                own = steps_l[cols[4, p]] if cols[2, p] > 0 else steps_r[cols[4, p]]
                if np.isfinite(own):
                    step[q] = own
        best = depth_votes(rays, planes, table, cols, at, gaps, tol_mm, n, penalty_mm, step)
        segs, labs = majority(cols[3][at], best, n, min_share)
        if len(segs) == 0:
            break
        m = _join(table, segs, labs, out_seg, out_lab, m)
        joined = segs
        # the steps of the segments touching a new one (``flag_touching``), measured again
        touched[:] = False
        for g in range(len(segs)):
            sg = segs[g]
            touched[sg] = True
            for j in range(starts[sg], starts[sg + 1]):
                i = members[j]
                if left[i] >= 0:
                    touched[seg[left[i]]] = True
                if right[i] >= 0:
                    touched[seg[right[i]]] = True
        for sg in range(n_seg):
            if touched[sg]:
                if table[sg] >= 0:
                    steps_l[sg] = _steps_of(sg, starts, members, seg, rays, planes, table, left, 1, tol_mm, min_rows)
                    steps_r[sg] = _steps_of(sg, starts, members, seg, rays, planes, table, right, -1, tol_mm,
                                            min_rows)
                else:
                    steps_l[sg] = np.nan
                    steps_r[sg] = np.nan
    return out_seg[:m], out_lab[:m]


@compiled
def _voters(cols, table, newly, by_nb, by_own):
    """``voting_pairs(cols[3], cols[4], table, flag_beside(cols[3], cols[4], flags of newly), False)`` from
    the pairs grouped by neighbour segment ``by_nb`` and by own segment ``by_own`` (``group_members`` of
    cols[4] and cols[3]): the positions (K,), ascending, of the pairs whose own segment is unlabelled (-1
    in ``table``; -2 marks a segment that takes no part) and beside a segment in ``newly`` (G,), and whose
    neighbour is labelled."""
    nb_starts, nb_pairs = by_nb
    seen = np.zeros(len(table), np.bool_)
    active = np.empty(len(table), np.int64)
    n_active = 0
    for g in range(len(newly)):
        s = newly[g]
        for j in range(nb_starts[s], nb_starts[s + 1]):
            a = cols[3, nb_pairs[j]]
            if not seen[a] and table[a] == -1:
                seen[a] = True
                active[n_active] = a
                n_active += 1
    return _pairs_of(cols, table, active[:n_active], by_own)


@compiled
def gap_votes(rays, planes, table, cols, at, gaps, tol_mm, n):
    """The label (K,) each voting pair ``cols[:, at]`` (``matching._Pairs`` rows) casts by the 3-D gap per
    stripe: the neighbour's label stepped by each gap (toward the voter) whose plane puts the voter's
    point nearest the neighbour's, that distance divided by the gap, the first of equals; -1 where none
    is within ``tol_mm``. The distance is np.linalg.norm's ((0 + x^2) + y^2) + z^2 under a square root."""
    best = np.full(len(at), -1, np.int64)
    for q in range(len(at)):
        p = at[q]
        idx, nbr, sign = cols[0, p], cols[1, p], cols[2, p]
        kn = table[cols[4, p]]
        x0 = _point(rays, nbr, planes, kn, 0)
        y0 = _point(rays, nbr, planes, kn, 1)
        z0 = _point(rays, nbr, planes, kn, 2)
        best_d = np.inf
        for gap in gaps:
            k = kn + sign * gap
            kc = min(max(k, 0), n - 1)
            dx = _point(rays, idx, planes, kc, 0) - x0
            dy = _point(rays, idx, planes, kc, 1) - y0
            dz = _point(rays, idx, planes, kc, 2) - z0
            d = np.sqrt(((0.0 + dx * dx) + dy * dy) + dz * dz) / gap
            if 0 <= k < n and d < best_d and d < tol_mm:
                best[q], best_d = k, d
    return best


@compiled
def _pairs_of(cols, table, segs, by_own):
    """The positions (K,), ascending, of the pairs of the own segments ``segs`` (G,) (grouped in ``by_own``)
    whose neighbour is labelled in ``table``: ``voting_pairs(cols[3], cols[4], table, everyone, True)``
    when only ``segs`` are labelled (a trial's re-vote), and the voters of ``_voters``' active segments."""
    trial = segs
    own_starts, own_pairs = by_own
    count = 0
    for g in range(len(trial)):
        count += own_starts[trial[g] + 1] - own_starts[trial[g]]
    out = np.empty(count, np.int64)
    k = 0
    for g in range(len(trial)):
        a = trial[g]
        for j in range(own_starts[a], own_starts[a + 1]):
            p = own_pairs[j]
            if table[cols[4, p]] >= 0:
                out[k] = p
                k += 1
    return _ascending(out[:k], cols.shape[1])


@compiled
def _ascending(values, size):
    """Distinct integers ``values`` (K,) in [0, ``size``) in ascending order: sorted when few, read off a bitmap
    of ``size`` when many (numba's sort took 2.9 ms on 50 000 pair positions, the bitmap of 140 000 0.1 ms)."""
    if len(values) * 16 <= size:
        values.sort()
        return values
    mark = np.zeros(size, np.bool_)
    for v in values:
        mark[v] = True
    out = np.empty(len(values), np.int64)
    k = 0
    for p in range(size):
        if mark[p]:
            out[k] = p
            k += 1
    return out


@compiled
def grow_piece(rays, planes, cols, by_nb, by_own, state, seed, mid, tol_mm, n, gaps, penalty_mm, min_share,
               rounds, refine_gaps, refine_share, refine_rounds, cover=0.0):
    """``matching._pieces``' trial for one seed: growth by depth continuity (``grow_by_depth``, best-supported
    first with ``cover``: ``_grow_rounds``) from segment ``seed`` at label ``mid`` over the segments that
    ``state`` (S,) marks -1 (the others, -2, take no part), then up to ``refine_rounds`` re-votes of its
    members by the same continuity. Returns the trial's segments (G,) (the seed, then in the order they
    joined) and their labels (G,)."""
    table = state.copy()
    table[seed] = mid
    joined, _ = _grow_rounds(rays, planes, table, cols, by_nb, by_own, np.array([seed]), tol_mm, n, gaps,
                             penalty_mm, min_share, rounds, cover)
    no_step = np.zeros(0)
    trial = np.concatenate((np.array([seed]), joined))
    m = len(trial)
    for _ in range(refine_rounds):
        at = _pairs_of(cols, table, trial, by_own)
        if len(at) == 0:
            break
        best = depth_votes(rays, planes, table, cols, at, refine_gaps, tol_mm, n, penalty_mm, no_step)
        segs, labs = majority(cols[3][at], best, n, refine_share)
        any_change = False
        for g in range(len(segs)):
            if table[segs[g]] != labs[g]:
                table[segs[g]] = labs[g]
                any_change = True
        if not any_change:
            break
    labels = np.empty(m, np.int64)
    for g in range(m):
        labels[g] = table[trial[g]]
    return trial, labels


@compiled
def pair_groups(cols, n_seg):
    """The pairs (``matching._Pairs`` rows ``cols``) grouped by neighbour segment and by own segment
    (``group_members`` of cols[4] and cols[3]), for ``_voters``."""
    return group_members(cols[4], n_seg), group_members(cols[3], n_seg)


@compiled
def _join(table, segs, labs, out_seg, out_lab, m):
    """Write a round's joins (segments ``segs``, labels ``labs``) into ``table`` and append them to
    ``out_seg``/``out_lab`` after their first ``m`` entries; returns the new count."""
    for g in range(len(segs)):
        table[segs[g]] = labs[g]
        out_seg[m], out_lab[m] = segs[g], labs[g]
        m += 1
    return m

