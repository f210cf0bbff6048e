"""Denoising centres and matching them to stripe (light-plane) indices (section 2.3.2, Algorithm 3).

STATUS: work in progress (issue 3), not wired into any command. Background stripes (floor, wall) are
labelled correctly on the simulator; the animal's absolute offset is still wrong (typically by 3-5
stripes), because the relative labels across its segments are not yet reliable. See the issue notes.

The paper finds a "main row" holding all N centres and propagates indices up and down by nearest
column with offset tracking. On a real scene the main row lies on the floor or a wall and every stripe
jumps sideways at the animal's outline, so image continuity alone carries wrong indices into the body
(``measurement.paper`` keeps that baseline to measure it). Here:

1. centres are linked into stripe segments (small column change from row to row, one-to-one);
2. rows holding N evenly spread centres label the segments through them (segment-wide vote);
3. an unlabelled segment takes the label that makes it continue the surface of a labelled neighbour
   in 3D (adjacent stripes on one surface lie a stripe spacing apart; a wrong index moves the point by
   a whole depth step along its ray), voted over its rows;
4. an isolated cluster (e.g. the animal seen from above, cut off from the floor by its outline) gets the
   offset that the shadow geometry demands: on the side away from the projector the first stripe on the
   object is the one after the last stripe on the background in that row;
5. labels whose depth falls outside the working range are dropped, and each row is kept in left-to-right
   order.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from .detection import Centres
from .triangulation import depth_for_labels, intersect


@dataclass(frozen=True)
class MatchingParams:
    """Knobs of denoising and labelling.

    link_px          : largest column change between consecutive rows of one segment (pixels, at 3072 px)
    min_segment_rows : shorter segments are noise
    depth_range_mm   : working range along the optical axis
    continuity       : a neighbour continues the surface when its 3D gap is below this many stripe spacings
    """

    link_px: float = 2.5
    min_segment_rows: int = 6
    depth_range_mm: tuple[float, float] = (400.0, 3500.0)
    continuity: float = 1.7
    denoise: bool = True


def denoise(c: Centres, shape: tuple[int, int]) -> np.ndarray:
    """Algorithm 3's denoising: keep a centre when its neighbourhood (a square one average stripe width
    wide) holds at least half that many centres — a stripe contributes one per row, a speck of scattered
    light only a few. returns (M,) bool keep-mask."""
    if len(c) == 0:
        return np.zeros(0, bool)
    wdt = int(np.clip(round(float(np.median(c.width))), 3, 25))
    h, w = shape
    mask = np.zeros((h, w), np.float32)
    ui = np.clip(np.rint(c.u).astype(np.int64), 0, w - 1)
    mask[c.v, ui] = 1.0
    counts = cv2.boxFilter(mask, -1, (wdt, wdt), normalize=False, borderType=cv2.BORDER_CONSTANT)
    return counts[c.v, ui] >= 0.5 * wdt


def link_segments(c: Centres, link_px: float) -> np.ndarray:
    """Segment id (M,) per centre: centres in consecutive rows (or one row apart) within ``link_px``
    columns, linked one-to-one (mutual nearest), then connected components."""
    m = len(c)
    if m == 0:
        return np.zeros(0, np.int64)
    order = np.lexsort((c.u, c.v))
    key = c.v[order].astype(np.float64) * 1e5 + c.u[order]
    src, dst = [], []
    for gap in (1, 2):
        tgt = key + gap * 1e5
        idx = np.clip(np.searchsorted(key, tgt), 1, m - 1)
        cand = np.stack([idx - 1, idx], axis=1)
        dist = np.abs(key[cand] - tgt[:, None])
        best = cand[np.arange(m), dist.argmin(axis=1)]
        d = np.abs(key[best] - tgt)
        ok = d <= link_px * gap
        a, b = np.arange(m)[ok], best[ok]
        # mutual: b's nearest in the row above is a
        back_t = key[b] - gap * 1e5
        bidx = np.clip(np.searchsorted(key, back_t), 1, m - 1)
        bc = np.stack([bidx - 1, bidx], axis=1)
        bbest = bc[np.arange(len(b)), np.abs(key[bc] - back_t[:, None]).argmin(axis=1)]
        mutual = bbest == a
        src.append(a[mutual])
        dst.append(b[mutual])
    s, d = np.concatenate(src), np.concatenate(dst)
    graph = coo_matrix((np.ones(len(s)), (s, d)), shape=(m, m))
    _, comp = connected_components(graph, directed=False)
    seg = np.empty(m, np.int64)
    seg[order] = comp
    return seg


def _row_neighbours(c: Centres) -> tuple[np.ndarray, np.ndarray]:
    """Index of the left and right neighbour of each centre in its row (-1 at the row's ends)."""
    order = np.lexsort((c.u, c.v))
    left = np.full(len(c), -1, np.int64)
    right = np.full(len(c), -1, np.int64)
    same = c.v[order][1:] == c.v[order][:-1]
    left[order[1:][same]] = order[:-1][same]
    right[order[:-1][same]] = order[1:][same]
    return left, right


def main_row_labels(c: Centres, n: int) -> np.ndarray:
    """Labels (M,) from rows holding exactly n evenly spread centres, -1 elsewhere."""
    labels = np.full(len(c), -1, np.int64)
    counts = np.bincount(c.v, minlength=int(c.v.max(initial=0)) + 1)
    full = counts[c.v] == n
    idx = np.nonzero(full)[0]
    if len(idx) == 0:
        return labels
    order = idx[np.lexsort((c.u[idx], c.v[idx]))]
    grid = c.u[order].reshape(-1, n)
    gaps = np.diff(grid, axis=1)
    # spacing changes slowly along a row on a smooth surface: no gap may jump against its neighbours
    ratio = gaps[:, 1:] / np.maximum(gaps[:, :-1], 1e-6)
    regular = ((ratio > 0.6) & (ratio < 1.67)).all(axis=1) & (gaps > 2).all(axis=1)
    rows_ok = np.repeat(regular, n)
    labels[order[rows_ok]] = np.tile(np.arange(n), regular.sum())
    return labels


def _segment_vote(seg: np.ndarray, labels: np.ndarray, min_share: float = 0.8) -> dict[int, int]:
    """Segment -> label where the labelled centres of the segment agree."""
    has = labels >= 0
    if not has.any():
        return {}
    pairs = seg[has] * 100000 + labels[has]
    uniq, cnt = np.unique(pairs, return_counts=True)
    segs, labs = uniq // 100000, uniq % 100000
    out = {}
    for s in np.unique(segs):
        m = segs == s
        best = np.argmax(cnt[m])
        if cnt[m][best] >= min_share * cnt[m].sum():
            out[int(s)] = int(labs[m][best])
    return out


def label_centres(c: Centres, rays: np.ndarray, planes: np.ndarray, shape: tuple[int, int],
                  params: MatchingParams = MatchingParams(), projector_right: bool = True) -> np.ndarray:
    """Stripe index (M,) for each centre, -1 where none can be trusted.

    rays : (M, 3) viewing rays of the centres (z = 1); planes : (N, 4) light planes, left to right
    """
    n = len(planes)
    m = len(c)
    if m == 0:
        return np.zeros(0, np.int64)
    link = params.link_px * max(shape[1] / 3072.0, 0.5)
    seg = link_segments(c, link)
    long_seg = np.bincount(seg)[seg] >= params.min_segment_rows
    left, right = _row_neighbours(c)
    # 1: the background (floor, wall) from complete rows
    seg_label = _segment_vote(seg, np.where(long_seg, main_row_labels(c, n), -1))
    labels = _labels_of(seg, seg_label, long_seg)
    # 2: a stripe that continued across the animal's outline in the image carried a background index
    # onto the animal; such centres sit off the background surfaces: cut them off as foreground
    on_bg = _on_background(rays, planes, labels)
    if on_bg is not None:
        seg, long_seg, seg_label = _split_foreground(c, seg, labels, on_bg, link, params.min_segment_rows)
    spacing_mm = _stripe_spacing_mm(c, rays, planes, seg, seg_label, left)
    z_all = depth_for_labels(rays, planes)
    zmin, zmax = params.depth_range_mm
    tol = spacing_mm * params.continuity
    is_bg = np.zeros(seg.max() + 1, bool)
    is_bg[list(seg_label)] = True
    # the background grows over its own surfaces only: from a floor stripe, a wrong index can make an
    # animal stripe look like the floor's continuation, so foreground never takes labels from it
    bg_mask = long_seg & (is_bg[seg] | ~_foreground_mask(seg, is_bg, on_bg))
    _grow_all(c, rays, planes, seg, seg_label, bg_mask, left, right, tol, n)
    fg_seg = long_seg & ~np.isin(seg, list(seg_label))
    fg_labels = _isolated_clusters(c, rays, planes, seg, seg_label, fg_seg, left, right, n, projector_right,
                                   z_all, (zmin, zmax))
    fg_seeded = dict(fg_labels)
    _grow_all(c, rays, planes, seg, fg_seeded, fg_seg, left, right, tol, n)
    seg_label.update(fg_seeded)
    labels = _labels_of(seg, seg_label, long_seg)
    ok = labels >= 0
    z = np.where(ok, z_all[np.arange(m), np.clip(labels, 0, n - 1)], np.nan)
    labels[ok & ~((z > zmin) & (z < zmax))] = -1
    return _enforce_row_order(c, labels)


def _foreground_mask(seg: np.ndarray, is_bg: np.ndarray, on_bg: np.ndarray | None) -> np.ndarray:
    """Centres known to be foreground (off the background planes); none when there is no background."""
    if on_bg is None:
        return np.zeros(len(seg), bool)
    return ~is_bg[seg] & ~on_bg


def _labels_of(seg: np.ndarray, seg_label: dict[int, int], long_seg: np.ndarray) -> np.ndarray:
    lab = np.full(seg.max() + 1, -1, np.int64)
    for s, k in seg_label.items():
        lab[s] = k
    out = lab[seg]
    out[~long_seg] = -1
    return out


def _split_foreground(c, seg, labels, on_bg, link, min_rows):
    """Unlabel centres off the background and re-link them into their own segments."""
    m = len(seg)
    fg = (labels < 0) | ~on_bg
    # near the junction of a merged segment the last background-looking centres are suspect too
    mixed = np.unique(seg[fg & (labels >= 0)])
    for s in mixed:
        idx = np.nonzero(seg == s)[0]
        fv = c.v[idx][fg[idx]]
        if len(fv) == 0:
            continue
        gap = np.min(np.abs(c.v[idx][:, None].astype(np.int64) - fv[None, :].astype(np.int64)), axis=1)
        fg[idx[gap <= 15]] = True
    fg_idx = np.nonzero(fg)[0]
    fseg = link_segments(c.take(fg), link) if len(fg_idx) else np.zeros(0, np.int64)
    new = seg.copy()
    new[fg_idx] = fseg + seg.max() + 1
    long_seg = np.zeros(m, bool)
    long_seg[~fg] = np.bincount(seg[~fg])[seg[~fg]] >= min_rows if (~fg).any() else False
    if len(fg_idx):
        long_seg[fg_idx] = np.bincount(fseg)[fseg] >= min_rows
    seg_label = {int(s): int(k) for s, k in zip(new[~fg], labels[~fg], strict=True) if k >= 0}
    return new, long_seg, seg_label


def _grow_all(c, rays, planes, seg, seg_label, long_seg, left, right, tol_mm, n) -> np.ndarray:
    """Grow labels along continuous surfaces until nothing changes; returns per-centre labels."""
    for _ in range(12):
        new = _grow(c, rays, planes, seg, seg_label, long_seg, left, right, tol_mm, n)
        if not new:
            break
        seg_label.update(new)
    lab = np.full(seg.max() + 1, -1, np.int64)
    for s, k in seg_label.items():
        lab[s] = k
    out = lab[seg]
    out[~long_seg] = -1
    return out


def _on_background(rays: np.ndarray, planes: np.ndarray, labels: np.ndarray, tol_mm: float = 8.0,
                   max_planes: int = 2) -> np.ndarray | None:
    """Which labelled centres lie on the dominant planes (floor, wall) of the labelled cloud; None when
    no plane carries a fifth of it (no planar background to separate from)."""
    from .planes import fit_plane_robust

    idx = np.nonzero(labels >= 0)[0]
    if len(idx) < 200:
        return None
    pts = intersect(rays[idx], planes[labels[idx]])
    on = np.zeros(len(idx), bool)
    rest = np.ones(len(idx), bool)
    rng = np.random.default_rng(0)
    for _ in range(max_planes):
        cand = np.nonzero(rest)[0]
        if len(cand) < 200:
            break
        plane, _ = fit_plane_robust(pts[cand], rng, iterations=300, inlier_mm=tol_mm / 2)
        near = np.abs(pts @ plane[:3] - plane[3]) < tol_mm
        if near[rest].sum() < 0.2 * len(idx):
            break
        on |= near
        rest &= ~near
    if not on.any():
        return None
    out = np.zeros(len(labels), bool)
    out[idx] = on
    return out


def _stripe_spacing_mm(c, rays, planes, seg, seg_label, left) -> float:
    """Median 3D distance between labelled row neighbours with consecutive labels (mm)."""
    lab = np.array([seg_label.get(int(s), -1) for s in seg])
    have = (lab >= 0) & (left >= 0)
    have[have] &= lab[left[have]] == lab[have] - 1
    idx = np.nonzero(have)[0]
    if len(idx) < 10:
        return 15.0
    a = intersect(rays[idx], planes[lab[idx]])
    b = intersect(rays[left[idx]], planes[lab[left[idx]]])
    return float(np.median(np.linalg.norm(a - b, axis=1)))


def _grow(c, rays, planes, seg, seg_label, long_seg, left, right, tol_mm, n) -> dict[int, int]:
    """Labels for unlabelled segments that continue a labelled neighbour's surface (one round)."""
    lab = np.full(seg.max() + 1, -1, np.int64)
    for s, k in seg_label.items():
        lab[s] = k
    cl = lab[seg]
    votes: dict[int, dict[int, int]] = {}
    support: dict[int, int] = {}
    for nb, sign in ((left, 1), (right, -1)):
        idx = np.nonzero((cl < 0) & long_seg & (nb >= 0))[0]
        idx = idx[cl[nb[idx]] >= 0]
        if len(idx) == 0:
            continue
        kn = cl[nb[idx]]
        pn = intersect(rays[nb[idx]], planes[kn])
        best_k = np.full(len(idx), -1)
        best_d = np.full(len(idx), np.inf)
        for gap in (1, 2, 3):
            k = kn + sign * gap
            okk = (k >= 0) & (k < n)
            p = intersect(rays[idx], planes[np.clip(k, 0, n - 1)])
            d = np.linalg.norm(p - pn, axis=1) / gap
            better = okk & (d < best_d) & (d < tol_mm)
            best_k[better], best_d[better] = k[better], d[better]
        for s, k in zip(seg[idx], best_k, strict=True):
            support[int(s)] = support.get(int(s), 0) + 1
            if k >= 0:
                vs = votes.setdefault(int(s), {})
                vs[int(k)] = vs.get(int(k), 0) + 1
    out = {}
    for s, vs in votes.items():
        k, cnt = max(vs.items(), key=lambda kv: kv[1])
        if cnt >= 3 and cnt >= 0.6 * support[s]:
            out[s] = k
    return out


def _isolated_clusters(c, rays, planes, seg, seg_label, long_seg, left, right, n, projector_right, z_all,
                       zrange) -> dict[int, int]:
    """Offsets for clusters of unlabelled segments: relative labels from row adjacency, absolute offset
    from the shadow side (the first stripe on the object follows the last stripe on the background)."""
    lab = np.full(seg.max() + 1, -1, np.int64)
    for s, k in seg_label.items():
        lab[s] = k
    cl = lab[seg]
    free = (cl < 0) & long_seg
    if free.sum() < 20:
        return {}
    # relative labels: adjacent free segments in a row differ by the number of stripe periods between them
    a = np.nonzero(free & (right >= 0))[0]
    a = a[free[right[a]] & (seg[right[a]] != seg[a])]
    gap = c.u[right[a]] - c.u[a]
    row_med = np.zeros(int(c.v.max()) + 1)
    order = np.argsort(c.v[a])
    rows_u, starts = np.unique(c.v[a][order], return_index=True)
    meds = np.array([np.median(g) for g in np.split(gap[order], starts[1:])]) if len(a) else np.zeros(0)
    row_med[rows_u] = meds
    delta = np.clip(np.rint(gap / np.maximum(row_med[c.v[a]], 1e-6)), 1, 3).astype(np.int64)
    nseg = seg.max() + 1
    key = (seg[a] * nseg + seg[right[a]]) * 4 + delta
    uniq, cnt = np.unique(key, return_counts=True)
    pair_ids, deltas = uniq // 4, uniq % 4
    # the most frequent delta per segment pair
    best: dict[int, tuple[int, int]] = {}
    for pid, d, k in zip(pair_ids, deltas, cnt, strict=True):
        if k > best.get(int(pid), (0, 0))[1]:
            best[int(pid)] = (int(d), int(k))
    pairs = np.array([[pid // nseg, pid % nseg, d] for pid, (d, k) in best.items() if k >= 3], np.int64)
    if len(pairs) == 0:
        return {}
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(nseg, nseg))
    _, cluster = connected_components(graph, directed=False)
    rel = _relative_labels(pairs, nseg)
    out: dict[int, int] = {}
    for cid in np.unique(cluster[np.unique(seg[free])]):
        members = np.nonzero((cluster == cid) & (rel != np.iinfo(np.int64).min))[0]
        member_set = np.isin(seg, members) & free
        if member_set.sum() < 20:
            continue
        r = rel[seg]
        idx = np.nonzero(member_set)[0]
        off = _shadow_offset(c, rays, planes, seg, cl, r, idx, n)
        if off is None:
            continue
        labels = r[idx] + off
        if labels.min() < 0 or labels.max() >= n:
            continue
        z = z_all[idx, labels]
        if np.mean((z > zrange[0]) & (z < zrange[1])) < 0.9:
            continue
        for s in members:
            out[int(s)] = int(rel[s] + off)
    return out


def projector_centre(planes: np.ndarray) -> np.ndarray:
    """A point on the axis that all light planes share, at the camera's height (y = 0): the projector
    centre of a level rig. The planes alone cannot fix it along the axis; a few centimetres off only
    tilts rays by the ratio of that error to the working distance."""
    from .planes import pencil_axis

    p0, a = pencil_axis(planes)
    return p0 - a * (p0[1] / a[1]) if abs(a[1]) > 1e-6 else p0


def _shadow_offset(c, rays, planes, seg, cl, r, idx, n, tol_mm: float = 10.0) -> int | None:
    """Absolute offset of a cluster with relative labels ``r[idx]``, from the shadow it casts.

    Where stripe k is cut off on the background by the object, the background's last lit point P, the
    object's grazing point of the same stripe and the projector centre lie on one line. For each
    candidate offset, count background stripe ends whose projector ray passes within ``tol_mm`` of the
    object's reconstructed stripe of the same index (and in front of P); the best-supported offset wins.
    """
    centre = projector_centre(planes)
    bg = np.nonzero(cl >= 0)[0]
    if len(bg) == 0:
        return None
    # ends of background segments (top and bottom centre of each)
    order = bg[np.lexsort((c.v[bg], seg[bg]))]
    s_sorted = seg[order]
    first = np.r_[True, s_sorted[1:] != s_sorted[:-1]]
    last = np.r_[s_sorted[1:] != s_sorted[:-1], True]
    ends = np.unique(np.r_[order[first], order[last]])
    ek = cl[ends]
    pe = intersect(rays[ends], planes[ek])
    dirs = pe - centre
    reach = np.linalg.norm(dirs, axis=1)
    dirs /= reach[:, None]
    rr = r[idx]
    sub = idx if len(idx) <= 6000 else idx[:: len(idx) // 6000 + 1]
    rsub = r[sub]
    scores = {}
    for off in range(-int(rr.min()), n - int(rr.max())):
        k = rsub + off
        pts = intersect(rays[sub], planes[k])
        hits = 0
        for kk in np.intersect1d(np.unique(k), np.unique(ek)):
            q = pts[k == kk] - centre
            e = ek == kk
            side = np.cross(planes[kk, :3], dirs[e])  # in-plane normal of each ray
            along = q @ dirs[e].T  # (P, E)
            perp = q @ side.T
            front = (along > 0) & (along < reach[e][None] - 3 * tol_mm)
            near = (np.abs(perp) < tol_mm) & front
            # the ray must graze the object, not pass through it: front points all on one side
            both = ((perp > tol_mm) & front).any(axis=0) & ((perp < -tol_mm) & front).any(axis=0)
            hits += int((near.any(axis=0) & ~both).sum()) - 2 * int(both.sum())
        scores[off] = hits
    if not scores:
        return None
    ranked = sorted(scores.items(), key=lambda kv: -kv[1])
    best, score = ranked[0]
    runner = ranked[1][1] if len(ranked) > 1 else 0
    if score < 5 or score - runner < max(3, 0.15 * score):
        return None
    return int(best)


def _gap_offset(v: np.ndarray, cl: np.ndarray, r: np.ndarray, idx: np.ndarray, n: int,
                projector_right: bool) -> int | None:
    """Absolute offset of a cluster with relative labels ``r[idx]``.

    A foreground object intercepts a run of stripes that then miss the background: in every row the
    object's labels must be labels the background lacks in that row, and on the shadow side (away from
    the projector) the stripe just before the object's first one still lands on the background. The
    offset fitting the most rows (tight rows counting extra) wins; None if no row constrains it.
    """
    rows = np.unique(v[idx])
    row_of = np.searchsorted(rows, v)
    lab_bg = (cl >= 0) & np.isin(v, rows)
    occupied = np.zeros((len(rows), n + 2), bool)  # columns shifted by one: label -1 and n are 'free'
    occupied[row_of[lab_bg], cl[lab_bg] + 1] = True
    if not occupied.any():
        return None
    ri, rr = row_of[idx], r[idx]
    best, best_score = None, 0.0
    first = np.full(len(rows), np.iinfo(np.int64).max)
    last = np.full(len(rows), np.iinfo(np.int64).min)
    np.minimum.at(first, ri, rr)
    np.maximum.at(last, ri, rr)
    present = first != np.iinfo(np.int64).max
    for off in range(-int(rr.max()), n - int(rr.min())):
        k = rr + off
        inside = (k >= 0) & (k < n)
        conflict = np.zeros(len(rows), bool)
        np.logical_or.at(conflict, ri, ~inside | occupied[ri, np.clip(k, -1, n) + 1])
        ok_rows = present & ~conflict
        edge = (first + off) if projector_right else (last + off)
        nb = edge - 1 if projector_right else edge + 1
        tight = ok_rows & occupied[np.arange(len(rows)), np.clip(nb, -1, n) + 1]
        score = ok_rows.sum() + 0.5 * tight.sum()
        if score > best_score:
            best, best_score = off, score
    return best


def _relative_labels(pairs: np.ndarray, nseg: int) -> np.ndarray:
    """Relative label per segment from (left, right, delta) pairs by breadth-first search (a spanning
    tree; contradicting pairs are ignored). Segments in no pair get int64 min."""
    rel = np.full(nseg, np.iinfo(np.int64).min, np.int64)
    adj: dict[int, list[tuple[int, int]]] = {}
    for a, b, d in pairs:
        adj.setdefault(int(a), []).append((int(b), int(d)))
        adj.setdefault(int(b), []).append((int(a), -int(d)))
    for start in adj:
        if rel[start] != np.iinfo(np.int64).min:
            continue
        rel[start] = 0
        queue = [start]
        while queue:
            s = queue.pop(0)
            for t, d in adj[s]:
                if rel[t] == np.iinfo(np.int64).min:
                    rel[t] = rel[s] + d
                    queue.append(t)
    return rel


def _enforce_row_order(c: Centres, labels: np.ndarray) -> np.ndarray:
    """Within a row, labels must increase left to right; drop the centres that break the order (the
    minority of a longest increasing run would be better; dropping both sides of each inversion is
    simpler and loses few centres)."""
    order = np.lexsort((c.u, c.v))
    lab = labels[order]
    v = c.v[order]
    valid = lab >= 0
    idx = np.nonzero(valid)[0]
    if len(idx) < 2:
        return labels
    same_row = v[idx[1:]] == v[idx[:-1]]
    bad = same_row & (lab[idx[1:]] <= lab[idx[:-1]])
    drop = np.zeros(len(lab), bool)
    drop[idx[1:][bad]] = True
    drop[idx[:-1][bad]] = True
    out = labels.copy()
    out[order[drop]] = -1
    return out
