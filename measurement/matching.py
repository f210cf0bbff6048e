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

import logging
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from .detection import Centres
from .triangulation import depth_for_labels, intersect

_log = logging.getLogger(__name__)
_TRACE: list | None = None  # tests and benchmarks may collect the foreground clusters here


@dataclass(frozen=True)
class MatchingParams:
    """Knobs of denoising and labelling.

    link_px          : largest column change between consecutive rows of one segment (pixels, at 3072 px)
    min_segment_rows : shorter segments are noise
    depth_range_mm   : working range along the optical axis
    continuity       : a neighbour continues the surface when its depth differs by less than this many stripe
                       spacings (mm)
    """

    link_px: float = 2.5
    min_segment_rows: int = 6
    depth_range_mm: tuple[float, float] = (400.0, 3500.0)
    continuity: float = 1.3
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


def split_at_changes(c: Centres, seg: np.ndarray, window: int = 8, ratio: float = 1.8,
                     slope_change: float = 0.35) -> np.ndarray:
    """Cut segments where a stripe passes onto another surface without a visible gap: the stripe's
    brightness above background jumps (another albedo, distance, angle) or its direction kinks. Label-
    free, so a stripe that crossed the animal's outline in the image is separated before any index is
    given. Returns new segment ids (M,)."""
    out = seg.copy()
    nxt = seg.max() + 1
    order = np.lexsort((c.v, seg))
    s_sorted = seg[order]
    starts = np.r_[0, np.nonzero(s_sorted[1:] != s_sorted[:-1])[0] + 1, len(order)]
    logc = np.log(np.maximum(c.contrast.astype(np.float64), 1.0))
    for a, b in zip(starts[:-1], starts[1:], strict=True):
        if b - a < 2 * window + 2:
            continue
        idx = order[a:b]
        lc = logc[idx]
        u, v = c.u[idx], c.v[idx].astype(np.float64)
        cs = np.r_[0.0, np.cumsum(lc)]
        i = np.arange(window, len(idx) - window)
        before = (cs[i] - cs[i - window]) / window
        after = (cs[i + window] - cs[i]) / window
        jump = np.abs(after - before)
        # slopes du/dv on each side by least squares over the window
        sb = _slopes(u, v, i - window, i)
        sa = _slopes(u, v, i, i + window)
        kink = np.abs(sa - sb)
        score = np.maximum(jump / np.log(ratio), kink / slope_change)
        cuts = []
        j = 0
        while j < len(i):
            if score[j] >= 1.0:
                k = j + int(np.argmax(score[j:j + window]))
                cuts.append(i[k])
                j = k + window
            else:
                j += 1
        for cpos in cuts:
            out[idx[cpos:]] = nxt
            nxt += 1
    return out


def _slopes(u: np.ndarray, v: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    cu, cv = np.r_[0.0, np.cumsum(u)], np.r_[0.0, np.cumsum(v)]
    cuv, cvv = np.r_[0.0, np.cumsum(u * v)], np.r_[0.0, np.cumsum(v * v)]
    n = (hi - lo).astype(np.float64)
    su, sv = cu[hi] - cu[lo], cv[hi] - cv[lo]
    suv, svv = cuv[hi] - cuv[lo], cvv[hi] - cvv[lo]
    den = n * svv - sv * sv
    return np.where(den > 1e-9, (n * suv - su * sv) / np.maximum(den, 1e-9), 0.0)


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


@dataclass(frozen=True, eq=False)
class Labels:
    """Stripe index per centre and the background found on the way.

    stripe     : (M,) int64 light-plane index, -1 where none can be trusted
    background : (P, 4) planes [n, d] of the floor / wall (mm), or None
    """

    stripe: np.ndarray
    background: np.ndarray | None
    segment: np.ndarray | None = None


def smooth_along_segments(c: Centres, segment: np.ndarray, labels: np.ndarray, half: int = 2,
                          outlier_px: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Average each centre's column with its neighbours along its stripe segment (+-``half`` rows; the
    surface is smooth over a couple of millimetres along a stripe, fur noise is not) and flag centres
    more than ``outlier_px`` off the median of their neighbourhood (specks of scattered light).

    returns : smoothed u (M,) float64, keep mask (M,) bool
    """
    u = c.u.copy()
    keep = labels >= 0
    idx = np.nonzero(keep)[0]
    if len(idx) == 0:
        return u, keep
    order = idx[np.lexsort((c.v[idx], segment[idx]))]
    s_sorted = segment[order]
    starts = np.r_[0, np.nonzero(s_sorted[1:] != s_sorted[:-1])[0] + 1, len(order)]
    win = 2 * half + 1
    for a, b in zip(starts[:-1], starts[1:], strict=True):
        if b - a < win:
            continue
        ids = order[a:b]
        x = c.u[ids]
        pad = np.pad(x, half, mode="edge")
        stack = np.lib.stride_tricks.sliding_window_view(pad, win)
        med = np.median(stack, axis=1)
        bad = np.abs(x - med) > outlier_px
        good = np.where(bad, med, x)
        cs = np.r_[0.0, np.cumsum(np.pad(good, half, mode="edge"))]
        u[ids] = (cs[win:] - cs[:-win]) / win
        keep[ids[bad]] = False
    return u, keep


def label_centres(c: Centres, rays: np.ndarray, planes: np.ndarray, shape: tuple[int, int],
                  params: MatchingParams = MatchingParams(), intr=None) -> Labels:
    """Stripe index (M,) for each centre, -1 where none can be trusted.

    rays : (M, 3) viewing rays of the centres (z = 1); planes : (N, 4) light planes, left to right
    """
    n = len(planes)
    m = len(c)
    if m == 0:
        return Labels(np.zeros(0, np.int64), None)
    link = params.link_px * max(shape[1] / 3072.0, 0.5)
    seg = split_at_changes(c, link_segments(c, link))
    long_seg = np.bincount(seg)[seg] >= params.min_segment_rows
    left, right = _row_neighbours(c)
    # 1: the background (floor, wall) from complete rows
    seg_label = _segment_vote(seg, np.where(long_seg, main_row_labels(c, n), -1))
    labels = _labels_of(seg, seg_label, long_seg)
    # 2: a stripe that continued across the animal's outline in the image carried a background index
    # onto the animal; such centres sit off the background surfaces: cut them off as foreground
    bg_planes = _background_planes(rays, planes, labels)
    if bg_planes is not None:
        on_bg = _near_planes(intersect(rays, planes[np.clip(labels, 0, n - 1)]), bg_planes) & (labels >= 0)
        seg, long_seg, seg_label = _split_foreground(c, seg, labels, on_bg, link, params.min_segment_rows)
    spacing_mm = _stripe_spacing_mm(c, rays, planes, seg, seg_label, left)
    tol = spacing_mm * params.continuity
    # 3: the background grows over its own surfaces; a segment joins it only if it then lies on them
    _grow_all(c, rays, planes, seg, seg_label, long_seg, left, right, 1.7 * spacing_mm, n, bg_planes)
    # 3b: unlabelled pieces of floor or wall (between the legs, beside the outline) are claimed by the
    # one label that puts them on a background plane
    if bg_planes is not None:
        seg_label.update(_claim_background(c, rays, planes, seg, seg_label, long_seg, bg_planes, n))
    # 4: foreground clusters: relative labels by growing from a seed, offset from the shadow they cast
    z_all = depth_for_labels(rays, planes)
    fg_labels = _foreground(c, rays, planes, seg, seg_label, long_seg, left, right, tol, n, z_all,
                            params.depth_range_mm, intr, bg_planes, shape)
    if fg_labels:
        # pieces of the animal without shadow evidence of their own continue a labelled piece's surface
        is_bg = np.zeros(seg.max() + 1, bool)
        is_bg[list(seg_label)] = True
        fg_mask = long_seg & ~is_bg[seg]
        if bg_planes is not None:  # leave alone what some index would put on the floor or wall
            fg_mask &= ~_background_like(rays, planes, seg, fg_mask, bg_planes, set(fg_labels))
        _grow_all(c, rays, planes, seg, fg_labels, fg_mask, left, right, tol, n, None, depth_only=True,
                  gaps=(1,), min_share=0.8)
    seg_label.update(fg_labels)
    labels = _labels_of(seg, seg_label, long_seg)
    ok = labels >= 0
    zmin, zmax = params.depth_range_mm
    z = np.where(ok, z_all[np.arange(m), np.clip(labels, 0, n - 1)], np.nan)
    labels[ok & ~((z > zmin) & (z < zmax))] = -1
    return Labels(_enforce_row_order(c, labels), bg_planes, seg)


def _claim_background(c, rays, planes, seg, seg_label, long_seg, bg_planes, n, min_rows: int = 15,
                      share: float = 0.95, tol_mm: float = 5.0) -> dict[int, int]:
    """Unlabelled segments that exactly one stripe index puts on a background plane (>= ``share`` of
    their points within ``tol_mm``); animal stripes are curved and fit no single plane that way."""
    labelled = np.zeros(seg.max() + 1, bool)
    labelled[list(seg_label)] = True
    cand = long_seg & ~labelled[seg]
    sizes = np.bincount(seg[cand], minlength=seg.max() + 1)
    out = {}
    for sid in np.nonzero(sizes >= min_rows)[0]:
        frac = _on_plane_fractions(rays[seg == sid], planes, bg_planes, tol_mm)
        hits = np.nonzero(frac >= share)[0]
        if len(hits) == 1:
            out[int(sid)] = int(hits[0])
    return out


def _on_plane_fractions(rays: np.ndarray, planes: np.ndarray, bg_planes: np.ndarray, tol_mm: float
                        ) -> np.ndarray:
    """(N,) share of the rays (m, 3) whose point on light plane k lies within ``tol_mm`` of a background
    plane, for every k at once."""
    z = depth_for_labels(rays, planes)  # (m, N)
    pts = rays[:, None, :] * z[:, :, None]  # (m, N, 3)
    d = np.abs(pts @ bg_planes[:, :3].T - bg_planes[:, 3]).min(axis=2)
    return (np.nan_to_num(d, nan=np.inf) < tol_mm).mean(axis=0)


def _foreground(c, rays, planes, seg, seg_label, long_seg, left, right, tol, n, z_all, zrange, intr=None,
                bg_planes=None, shape=(0, 0)) -> dict[int, int]:
    """Labels for the segments the background did not claim, cluster by cluster."""
    out: dict[int, int] = {}
    labelled = np.zeros(seg.max() + 1, bool)
    labelled[list(seg_label)] = True
    remaining = long_seg & ~labelled[seg]
    cl = _labels_of(seg, seg_label, long_seg)
    mid = n // 2
    biggest = 0
    while remaining.sum() >= 50:
        sizes = np.bincount(seg[remaining], minlength=seg.max() + 1)
        seed = int(np.argmax(sizes))
        if sizes[seed] < 30:  # only specks and stubs are left: too short to seed a piece of the animal
            break
        trial = {seed: mid}
        _grow_all(c, rays, planes, seg, trial, remaining, left, right, tol, n, None, depth_only=True)
        _refine(c, rays, planes, seg, trial, remaining & np.isin(seg, list(trial)), left, right, tol, n)
        members = np.array(sorted(trial))
        in_cluster = np.isin(seg, members) & remaining
        remaining &= ~in_cluster
        biggest = max(biggest, int(in_cluster.sum()))
        if in_cluster.sum() < max(50, 0.1 * biggest):  # small pieces carry too little shadow evidence
            continue
        idx = np.nonzero(in_cluster)[0]
        rel = np.full(seg.max() + 1, 0, np.int64)
        for sid, k in trial.items():
            rel[sid] = k - mid
        off = _occlusion_offset(rays, planes, cl, rel[seg], idx, n, _projector_right(planes))
        if _TRACE is not None:
            _TRACE.append((idx, rel[seg[idx]], off))
        if off is None:
            continue
        lab = rel[seg[idx]] + off
        inside = (lab >= 0) & (lab < n)
        z = z_all[idx[inside], lab[inside]]
        if inside.mean() < 0.8 or np.mean((z > zrange[0]) & (z < zrange[1])) < 0.9:
            continue
        for sid in members:
            if 0 <= rel[sid] + off < n:
                out[int(sid)] = int(rel[sid] + off)
    return out


def _foreground_mask(seg: np.ndarray, is_bg: np.ndarray, on_bg: np.ndarray | None) -> np.ndarray:
    """Centres known to be foreground (off the background planes); none when there is no background."""
    if on_bg is None:
        return np.zeros(len(seg), bool)
    return ~is_bg[seg] & ~on_bg


def _labels_of(seg: np.ndarray, seg_label: dict[int, int], long_seg: np.ndarray) -> np.ndarray:
    """Per-centre labels (M,) from a segment -> label map; -1 for short segments and unlabelled ones."""
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
    sub = c.take(fg)
    fseg = split_at_changes(sub, link_segments(sub, link)) if len(fg_idx) else np.zeros(0, np.int64)
    new = seg.copy()
    new[fg_idx] = fseg + seg.max() + 1
    long_seg = np.zeros(m, bool)
    long_seg[~fg] = np.bincount(seg[~fg])[seg[~fg]] >= min_rows if (~fg).any() else False
    if len(fg_idx):
        long_seg[fg_idx] = np.bincount(fseg)[fseg] >= min_rows
    seg_label = {int(s): int(k) for s, k in zip(new[~fg], labels[~fg], strict=True) if k >= 0}
    return new, long_seg, seg_label


def _grow_all(c, rays, planes, seg, seg_label, long_seg, left, right, tol_mm, n, bg_planes=None,
              depth_only=False, avoid_planes=None, gaps=(1, 2, 3), min_share=0.6) -> np.ndarray:
    """Grow labels along continuous surfaces until nothing changes; returns per-centre labels.
    With ``bg_planes`` a segment only joins when its points then lie on those planes; with
    ``avoid_planes`` only when they do not."""
    for _ in range(40):
        new = _grow(c, rays, planes, seg, seg_label, long_seg, left, right, tol_mm, n, depth_only,
                    min_share=min_share, gaps=gaps)
        if bg_planes is not None and new:
            new = {s: k for s, k in new.items() if _segment_on_planes(rays, planes, seg, s, k, bg_planes)}
        if avoid_planes is not None and new:
            new = {s: k for s, k in new.items()
                   if not _segment_on_planes(rays, planes, seg, s, k, avoid_planes, share=0.5)}
        if not new:
            break
        seg_label.update(new)
    return _labels_of(seg, seg_label, long_seg)


def _background_planes(rays: np.ndarray, planes: np.ndarray, labels: np.ndarray, tol_mm: float = 8.0,
                       max_planes: int = 2) -> np.ndarray | None:
    """The dominant planes (floor, wall) of the labelled cloud, (P, 4); None when no plane carries a fifth
    of it (no planar background to separate from)."""
    from .planes import fit_plane_robust

    idx = np.nonzero(labels >= 0)[0]
    if len(idx) < 200:
        return None
    pts = intersect(rays[idx], planes[labels[idx]])
    found = []
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
        found.append(plane)
        rest &= ~near
    return np.array(found) if found else None


def _near_planes(points: np.ndarray, bg_planes: np.ndarray, tol_mm: float = 8.0) -> np.ndarray:
    """(M,) True where a point lies within ``tol_mm`` of any background plane."""
    d = np.abs(points @ bg_planes[:, :3].T - bg_planes[:, 3])
    return np.nan_to_num(d, nan=np.inf).min(axis=1) < tol_mm


def _background_like(rays, planes, seg, mask, bg_planes, exclude: set, share: float = 0.8) -> np.ndarray:
    """(M,) True for centres of segments (in ``mask``, not in ``exclude``) that some stripe index puts
    on a background plane for at least ``share`` of their points."""
    out = np.zeros(len(seg), bool)
    for sid in np.unique(seg[mask]):
        if int(sid) in exclude:
            continue
        idx = np.nonzero(seg == sid)[0]
        if _on_plane_fractions(rays[idx], planes, bg_planes, 8.0).max() >= share:
            out[idx] = True
    return out


def _segment_on_planes(rays, planes, seg, sid, k, bg_planes, share: float = 0.9) -> bool:
    idx = np.nonzero(seg == sid)[0]
    pts = intersect(rays[idx], planes[np.full(len(idx), k)])
    return bool(_near_planes(pts, bg_planes).mean() >= share)


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


def _grow(c, rays, planes, seg, seg_label, long_seg, left, right, tol_mm, n, depth_only=False,
          relabel=False, min_share=0.6, gaps=(1, 2, 3)) -> dict[int, int]:
    """Labels for unlabelled segments that continue a labelled neighbour's surface (one round). With
    ``relabel`` the labelled segments in ``long_seg`` are re-voted by their neighbours instead."""
    cl = _labels_of(seg, seg_label, np.ones(len(seg), bool))
    votes: dict[int, dict[int, int]] = {}
    support: dict[int, int] = {}
    for nb, sign in ((left, 1), (right, -1)):
        target = (cl >= 0) if relabel else (cl < 0)
        idx = np.nonzero(target & long_seg & (nb >= 0))[0]
        idx = idx[(cl[nb[idx]] >= 0) & (seg[nb[idx]] != seg[idx])]
        if len(idx) == 0:
            continue
        kn = cl[nb[idx]]
        pn = intersect(rays[nb[idx]], planes[kn])
        best_k = np.full(len(idx), -1)
        best_d = np.full(len(idx), np.inf)
        for gap in gaps:
            k = kn + sign * gap
            okk = (k >= 0) & (k < n)
            p = intersect(rays[idx], planes[np.clip(k, 0, n - 1)])
            if depth_only:
                # on a curved body, depth continuity separates a right index (median 3 mm on the simulated
                # fox, 99 % under 36) from a wrong one (a whole depth step, 35-75 mm) better than 3-D gaps
                d = np.abs(p[:, 2] - pn[:, 2])
            else:  # on flat backgrounds the 3-D gap per stripe is the sharper test
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
        if cnt >= 3 and cnt >= min_share * support[s]:
            out[s] = k
    return out


def _refine(c, rays, planes, seg, seg_label, mask, left, right, tol_mm, n, rounds: int = 3) -> None:
    """Re-vote each labelled segment in ``mask`` by its neighbours; a clear majority for another label
    (a growth step that took the wrong gap) replaces it. Updates ``seg_label`` in place."""
    for _ in range(rounds):
        votes = _grow(c, rays, planes, seg, seg_label, mask, left, right, tol_mm, n, depth_only=True,
                      relabel=True, min_share=0.7)
        changed = {s: k for s, k in votes.items() if seg_label.get(s) != k}
        if not changed:
            break
        seg_label.update(changed)


def projector_centre(planes: np.ndarray) -> np.ndarray:
    """A point on the axis that all light planes share, at the camera's height (y = 0): the projector
    centre of a level rig. The planes alone cannot fix it along the axis; a few centimetres off only
    tilts rays by the ratio of that error to the working distance."""
    from .planes import pencil_axis

    p0, a = pencil_axis(planes)
    return p0 - a * (p0[1] / a[1]) if abs(a[1]) > 1e-6 else p0


def _projector_right(planes: np.ndarray) -> bool:
    """Whether the projector sits right of the camera (positive x), from the planes' shared axis."""
    return bool(projector_centre(planes)[0] > 0)


def _projector_elevation(points: np.ndarray, planes: np.ndarray) -> np.ndarray:
    """Elevation of each point (M, 3) as seen from the projector along its stripe: tan of the angle
    between the ray and the plane perpendicular to the shared axis (the projector's row coordinate)."""
    from .planes import pencil_axis

    centre = projector_centre(planes)
    _, a = pencil_axis(planes)
    q = points - centre
    along = q @ a
    across = np.linalg.norm(q - along[:, None] * a, axis=1)
    return along / np.maximum(across, 1e-9)


def _occlusion_offset(rays, planes, cl, r, idx, n, projector_right: bool = True, bins: float = 0.002,
                      free: float = 0.01) -> int | None:
    """Absolute offset of a cluster with relative labels ``r[idx]``, from the projector's point of view.

    A background point lit by stripe k at projector elevation e proves that nothing stood in front of it
    on that projector ray: the object must not occupy cell (k, e). Cells well inside a lit run (lit two
    bins either side too) count, so the shadow's own edges do not. Offsets that slide the object onto lit
    background conflict; those sliding it toward background the camera cannot see (behind the object)
    do not, so the right offset is the conflict-free one nearest the conflicts: the lowest with the
    projector right of the camera, the highest with it on the left.
    """
    bg = np.nonzero(cl >= 0)[0]
    if len(bg) < 100:
        return None
    pb = intersect(rays[bg], planes[cl[bg]])
    eb = np.floor(_projector_elevation(pb, planes) / bins).astype(np.int64)
    lit = np.unique(cl[bg] * 1_000_000 + eb)
    deep = lit[np.isin(lit - 2, lit) & np.isin(lit + 2, lit) & np.isin(lit - 1, lit) & np.isin(lit + 1, lit)]
    rr = r[idx]
    sub = idx if len(idx) <= 20000 else idx[:: len(idx) // 20000 + 1]
    rs = r[sub]
    conflicts = {}
    for off in range(-int(rr.max()), n - int(rr.min())):
        k = rs + off
        inside = (k >= 0) & (k < n)
        if inside.mean() < 0.8:
            continue
        p = intersect(rays[sub][inside], planes[k[inside]])
        e = np.floor(_projector_elevation(p, planes) / bins).astype(np.int64)
        cells = np.unique(k[inside] * 1_000_000 + e)
        conflicts[off] = float(np.isin(cells, deep).mean())
    if not conflicts:
        return None
    _log.debug("occlusion conflicts %s", sorted(conflicts.items()))
    offs = sorted(conflicts)
    vals = np.array([conflicts[o] for o in offs])
    if not projector_right:  # mirror, so the conflicts always rise toward lower offsets
        offs, vals = offs[::-1], vals[::-1]
    if len(vals) < 5:
        return None
    roll = np.array([np.median(vals[i:i + 4]) for i in range(len(vals) - 3)])
    plateau = float(roll.min())
    limit = max(2 * plateau, free)
    j = int(np.argmin(roll))
    i = j + int(np.argmin(vals[j:j + 4]))
    while i > 0 and vals[i - 1] <= limit:  # walk toward the conflicts while still conflict-free
        i -= 1
    if i == 0 or vals[i - 1] < 2 * max(plateau, 0.005):
        return None
    best = offs[i]
    # one conflict-free stretch only: a second one (the object could sit elsewhere too) is ambiguous
    low = vals <= max(4 * plateau, 0.03)  # a second valley, even a shallower one, makes it ambiguous
    runs = np.flatnonzero(np.diff(np.r_[0, low.astype(np.int8), 0]) == 1)
    if len(runs) > 1:
        return None
    return int(best)


def _shadow_cells(c: Centres, cl: np.ndarray, bg: np.ndarray, obj: np.ndarray, planes: np.ndarray, intr,
                  bg_planes: np.ndarray, shape: tuple[int, int], bins: float, step_mm: float = 4.0) -> np.ndarray:
    """Projector cells where the background should show a stripe, the camera sees the background, and no
    stripe was detected: the object's shadow. Returns cell keys k * 1e6 + elevation bin."""
    from .camera import project

    h, w = shape
    # where the object is in the image (dilated), to leave out background the camera cannot see
    scale = 8
    mask = np.zeros((h // scale + 1, w // scale + 1), np.uint8)
    mask[c.v[obj] // scale, np.clip(np.rint(c.u[obj]).astype(np.int64) // scale, 0, w // scale)] = 1
    mask = np.asarray(cv2.dilate(mask, np.ones((7, 7), np.uint8)), np.uint8)
    mask = np.asarray(cv2.morphologyEx(mask, cv2.MORPH_CLOSE, np.ones((15, 15), np.uint8)), np.uint8)
    # detected background stripes by (label, row) for the lit test
    seen = set(zip(cl[bg].tolist(), c.v[bg].tolist(), strict=True))
    cells = []
    centre = projector_centre(planes)
    for k in np.unique(cl[bg]):
        rows_k = c.v[bg][cl[bg] == k]
        for plane in bg_planes:
            d = np.cross(planes[k, :3], plane[:3])
            if np.linalg.norm(d) < 1e-6:
                continue
            d /= np.linalg.norm(d)
            A = np.vstack([planes[k, :3], plane[:3], d])
            p0 = np.linalg.solve(A, np.array([planes[k, 3], plane[3], 0.0]))
            t = np.arange(-3000.0, 3000.0, step_mm)
            pts = p0 + t[:, None] * d
            pts = pts[pts[:, 2] > 100]
            # keep the part of the line no other background plane hides from the projector
            q = pts - centre
            others = [o for o in bg_planes if o is not plane]
            for o in others:
                s_hit = (o[3] - centre @ o[:3]) / (q @ o[:3])
                pts = pts[~((s_hit > 0) & (s_hit < 0.999))]
                q = pts - centre
            if len(pts) == 0:
                continue
            uv = project(pts, intr)
            ui, vi = np.rint(uv[:, 0]).astype(np.int64), np.rint(uv[:, 1]).astype(np.int64)
            ok = (ui >= 0) & (ui < w) & (vi >= 0) & (vi < h)
            ok &= (vi >= rows_k.min()) & (vi <= rows_k.max())  # within the stripe's observed extent
            ok[ok] &= mask[vi[ok] // scale, ui[ok] // scale] == 0
            dark = np.array([ok_ and not any((int(k), int(v + dv)) in seen for dv in (-1, 0, 1))
                             for ok_, v in zip(ok, vi, strict=True)])
            if dark.any():
                e = np.floor(_projector_elevation(pts[dark], planes) / bins).astype(np.int64)
                cells.append(int(k) * 1_000_000 + e)
    return np.unique(np.concatenate(cells)) if cells else np.zeros(0, np.int64)


def _segment_ends(c: Centres, seg: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Indices of the first and last centre (by row) of each segment among ``idx``."""
    order = idx[np.lexsort((c.v[idx], seg[idx]))]
    s_sorted = seg[order]
    first = np.r_[True, s_sorted[1:] != s_sorted[:-1]]
    last = np.r_[s_sorted[1:] != s_sorted[:-1], True]
    return np.unique(np.r_[order[first], order[last]])


def _shadow_offset(c, rays, planes, seg, cl, r, idx, n, cap_mm: float = 30.0) -> int | None:
    """Absolute offset of a cluster with relative labels ``r[idx]``, from the shadow it casts.

    Where the object cuts stripe k off the background, the background stripe's end, the object's grazing
    point (an end of the object's stripe k) and the projector centre are collinear. For each candidate
    offset, each background stripe end costs the distance from its projector ray to the nearest object
    stripe end of the same index in front of it (capped); the cheapest offset wins.
    """
    centre = projector_centre(planes)
    bg = np.nonzero(cl >= 0)[0]
    if len(bg) == 0:
        return None
    ends = _segment_ends(c, seg, bg)
    ek = cl[ends]
    pe = intersect(rays[ends], planes[ek])
    dirs = pe - centre
    reach = np.linalg.norm(dirs, axis=1)
    dirs /= reach[:, None]
    obj_ends = _segment_ends(c, seg, idx)
    ro = r[obj_ends]
    costs = {}
    for off in range(-int(r[idx].min()), n - int(r[idx].max())):
        k = ro + off
        pts = intersect(rays[obj_ends], planes[k]) - centre
        d = np.full(len(ends), cap_mm)
        for kk in np.intersect1d(np.unique(k), np.unique(ek)):
            q = pts[k == kk]
            e = np.nonzero(ek == kk)[0]
            along = q @ dirs[e].T
            perp = np.linalg.norm(q[:, None, :] - along[:, :, None] * dirs[e][None], axis=2)
            perp[(along <= 0) | (along > reach[e][None] - cap_mm)] = cap_mm
            d[e] = np.minimum(perp.min(axis=0), cap_mm)
        costs[off] = float(d.mean())
    if not costs:
        return None
    ranked = sorted(costs.items(), key=lambda kv: kv[1])
    _log.debug("shadow costs %s", ranked[:5])
    best, cost = ranked[0]
    runner = ranked[1][1] if len(ranked) > 1 else cap_mm
    if runner - cost < 0.02 * cap_mm:  # no offset explains the shadow clearly better than the next
        return None
    return int(best)

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
