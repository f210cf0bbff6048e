"""Stripe segments: centres linked from row to row, cut where a stripe passes onto another surface,
denoised (Algorithm 3) and smoothed along the stripe."""

from __future__ import annotations

import cv2
import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from .detection import Centres


def denoise(c: Centres, shape: tuple[int, int]) -> np.ndarray:
    """Algorithm 3's denoising: keep a centre when its neighbourhood (a square one average stripe width
    wide) holds at least half that many centres — a stripe contributes one per row, a speck of scattered
    light only a few. returns (M,) bool keep-mask."""
    if len(c) == 0:
        return np.zeros(0, bool)
    wdt = int(np.clip(round(float(np.median(c.width))), 3, 25))
    h, w = shape
    ui = np.clip(np.rint(c.u).astype(np.int64), 0, w - 1)
    flat = c.v.astype(np.int64) * w + ui
    mask = np.zeros(h * w, np.uint8)
    mask[flat] = 1
    # integer counts saturating at 255: the threshold is at most 12.5, so the answer is the exact count's
    counts = cv2.boxFilter(mask.reshape(h, w), cv2.CV_8U, (wdt, wdt), normalize=False,
                           borderType=cv2.BORDER_CONSTANT)
    return counts.ravel()[flat] >= 0.5 * wdt


def link_segments(c: Centres, link_px: float, order: np.ndarray | None = None) -> np.ndarray:
    """Segment id (M,) per centre: centres in consecutive rows (or one row apart) within ``link_px``
    columns, linked one-to-one (mutual nearest), then connected components. order : row_order(c), if known"""
    m = len(c)
    if m == 0:
        return np.zeros(0, np.int64)
    order = row_order(c) if order is None else order
    key = c.v[order].astype(np.float64) * 1e5 + c.u[order]
    src, dst = [], []
    for gap in (1, 2):
        tgt = key + gap * 1e5
        best, d = _nearest_key(key, tgt)
        ok = d <= link_px * gap
        a, b = np.nonzero(ok)[0], best[ok]
        # mutual: b's nearest in the row above is a
        mutual = _nearest_key(key, key[b] - gap * 1e5)[0] == a
        src.append(a[mutual])
        dst.append(b[mutual])
    s, d = np.concatenate(src), np.concatenate(dst)
    graph = csr_matrix((np.ones(len(s)), (s, d)), shape=(m, m))  # CSR: connected_components converts COO first
    _, comp = connected_components(graph, directed=False)
    seg = np.empty(m, np.int64)
    seg[order] = comp
    return seg


def _nearest_key(key: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index (T,) of the entry of sorted ``key`` (K,) nearest each target (T,) (the lower of a tie),
    and the distance (T,)."""
    hi = np.clip(_searchsorted_merge(key, target), 1, len(key) - 1)
    d_lo, d_hi = np.abs(key[hi - 1] - target), np.abs(key[hi] - target)
    upper = d_hi < d_lo
    return np.where(upper, hi, hi - 1), np.where(upper, d_hi, d_lo)


def _searchsorted_merge(key: np.ndarray, target: np.ndarray) -> np.ndarray:
    """``np.searchsorted(key, target)`` (K,) sorted, (T,): when the targets are sorted too (link_segments'
    are) by one stable merge of both (targets first, so a tie counts as not less), twice as fast as T
    binary searches over a large key."""
    if len(target) < 2 or not (target[1:] >= target[:-1]).all():
        return np.searchsorted(key, target)
    order = np.argsort(np.concatenate([target, key]), kind="stable")
    pos = np.empty(len(order), np.int64)
    pos[order] = np.arange(len(order))
    return pos[:len(target)] - np.arange(len(target))


def row_order(c: Centres) -> np.ndarray:
    """``np.lexsort((c.u, c.v))``: the centres (M,) by row, then column. One stable sort of a combined
    key (detection yields them nearly in that order already); a lexsort only when the key ties."""
    key = c.v.astype(np.float64) * 1e5 + c.u
    order = np.argsort(key, kind="stable")
    a, b = order[:-1], order[1:]
    tie = key[a] == key[b]
    # a key tie of two centres that differ (closer than the key resolves) needs the real lexsort; both
    # sorts keep equal centres (detection repeats a few) in their given order
    if ((c.u[a[tie]] != c.u[b[tie]]) | (c.v[a[tie]] != c.v[b[tie]])).any():
        return np.lexsort((c.u, c.v))
    return order


def split_at_changes(c: Centres, seg: np.ndarray, window: int = 8, ratio: float = 1.8,
                     slope_change: float = 0.35) -> np.ndarray:
    """Cut segments where a stripe passes onto another surface without a visible gap: the stripe's
    brightness above background jumps (another albedo, distance, angle) or its direction kinks. Label-
    free, so a stripe that crossed the animal's outline in the image is separated before any index is
    given. Returns new segment ids (M,)."""
    out = seg.copy()
    nxt = seg.max() + 1
    order = np.lexsort((c.v, seg))
    starts = _runs(seg[order])
    lengths = np.diff(starts)
    logc = np.log(np.maximum(c.contrast.astype(np.float64), 1.0))
    cuts: dict[int, list[int]] = {}
    long_runs = np.nonzero(lengths >= 2 * window + 2)[0]
    for group in _length_buckets(lengths[long_runs]):
        runs = long_runs[group]
        n_rows = lengths[runs]
        idx, valid = _gather(order, starts[runs], n_rows, np.arange(n_rows.max()))
        lc = np.where(valid, logc[idx], 0.0)
        u, v = np.where(valid, c.u[idx], 0.0), np.where(valid, c.v[idx].astype(np.float64), 0.0)
        cs = _padded_cumsum(lc)
        k = idx.shape[1] - 2 * window  # windows before (from column j) and after (from j + window) row j
        before = (cs[:, window:window + k] - cs[:, :k]) / window
        after = (cs[:, 2 * window:2 * window + k] - cs[:, window:window + k]) / window
        jump = np.abs(after - before)
        # slopes du/dv on each side by least squares over the window
        sums = [_padded_cumsum(x) for x in (u, v, u * v, v * v)]
        sb = _slopes(sums, 0, k, window)
        sa = _slopes(sums, window, k, window)
        kink = np.abs(sa - sb)
        i = np.arange(window, window + k)
        score = np.maximum(jump / np.log(ratio), kink / slope_change)
        inside = i[None, :] < (n_rows - window)[:, None]
        for row in np.nonzero(((score >= 1.0) & inside).any(axis=1))[0]:
            at = _greedy_cuts(score[row, :n_rows[row] - 2 * window], window)
            cuts[int(runs[row])] = [window + j for j in at]
    for run in sorted(cuts):  # new ids in segment order, as one segment at a time would hand them out
        idx = order[starts[run]:starts[run + 1]]
        for cpos in cuts[run]:
            out[idx[cpos:]] = nxt
            nxt += 1
    return out


def _greedy_cuts(score: np.ndarray, window: int) -> list[int]:
    """Positions of the cuts along one segment's scores (K,): from each score >= 1 the highest within
    ``window``, then on past it by ``window``."""
    cand = np.flatnonzero(score >= 1.0)
    out: list[int] = []
    j = 0
    while True:
        p = int(np.searchsorted(cand, j))
        if p == len(cand):
            return out
        j = int(cand[p])
        k = j + int(np.argmax(score[j:j + window]))
        out.append(k)
        j = k + window


def _slopes(sums: list[np.ndarray], start: int, k: int, window: int) -> np.ndarray:
    """Least-squares slopes du/dv (R, k) over the windows [start + j, start + j + window), j < k, of
    rows with running sums ``sums`` = _padded_cumsum of u, v, u v, v v (each (R, L + 1))."""
    lo, hi = slice(start, start + k), slice(start + window, start + window + k)
    cu, cv, cuv, cvv = sums
    n = float(window)
    su, sv = cu[:, hi] - cu[:, lo], cv[:, hi] - cv[:, lo]
    suv, svv = cuv[:, hi] - cuv[:, lo], cvv[:, hi] - cvv[:, lo]
    den = n * svv - sv * sv
    return np.where(den > 1e-9, (n * suv - su * sv) / np.maximum(den, 1e-9), 0.0)


def _runs(keys: np.ndarray) -> np.ndarray:
    """Start offsets (R + 1,) of the runs of equal values in sorted ``keys`` (K,), closed by len(keys)."""
    return np.r_[0, np.nonzero(keys[1:] != keys[:-1])[0] + 1, len(keys)]


def _length_buckets(lengths: np.ndarray):
    """Indices of runs grouped by length within a factor of two, so that each group pads into one
    (runs, longest) array without wasting much."""
    level = np.floor(np.log2(np.maximum(lengths, 1))).astype(np.int64)
    for lv in np.unique(level):
        yield np.nonzero(level == lv)[0]


def _gather(order: np.ndarray, starts: np.ndarray, lengths: np.ndarray, pos: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray]:
    """Element indices (R, K) at positions ``pos`` (K,) of runs ``order[start:start + length]``, a
    position outside a run clamped to its ends (edge padding), and where it was inside (R, K)."""
    at = np.clip(pos[None, :], 0, lengths[:, None] - 1)
    return order[starts[:, None] + at], (pos[None, :] >= 0) & (pos[None, :] < lengths[:, None])


def _padded_cumsum(x: np.ndarray) -> np.ndarray:
    """Running sums (R, L + 1) of the rows of x (R, L), each from 0: per row exactly ``np.r_[0,
    np.cumsum(row)]`` (accumulation is sequential, so the sums round as they would one run at a time)."""
    return np.cumsum(np.concatenate([np.zeros((len(x), 1)), x], axis=1), axis=1)


def row_neighbours(c: Centres, order: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Index of the left and right neighbour of each centre in its row (-1 at the row's ends).
    order : row_order(c), if known"""
    order = row_order(c) if order is None else order
    left = np.full(len(c), -1, np.int64)
    right = np.full(len(c), -1, np.int64)
    same = c.v[order][1:] == c.v[order][:-1]
    left[order[1:][same]] = order[:-1][same]
    right[order[:-1][same]] = order[1:][same]
    return left, right


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
    starts = _runs(segment[order])
    lengths = np.diff(starts)
    win = 2 * half + 1
    runs = np.nonzero(lengths >= win)[0]
    for group in _length_buckets(lengths[runs]):
        n_rows = lengths[runs[group]]
        first = starts[runs[group]]
        width = int(n_rows.max())
        ids, valid = _gather(order, first, n_rows, np.arange(width))
        padded, _ = _gather(order, first, n_rows, np.arange(-half, width + half))
        xp = c.u[padded]  # edge-padded columns, (R, width + 2 half)
        x = xp[:, half:half + width]
        med = _window_median(xp, win, width)
        bad = np.abs(x - med) > outlier_px
        good = np.where(bad, med, x)
        at = np.clip(np.arange(-half, width + half)[None, :], 0, n_rows[:, None] - 1)
        cs = _padded_cumsum(np.take_along_axis(good, at, axis=1))
        u[ids[valid]] = ((cs[:, win:win + width] - cs[:, :width]) / win)[valid]
        keep[ids[valid & bad]] = False
    return u, keep


def _window_median(xp: np.ndarray, win: int, width: int) -> np.ndarray:
    """Median (R, width) of each run of ``win`` (odd) columns of xp (R, width + win - 1)."""
    cols = [xp[:, j:j + width] for j in range(win)]
    if win != 5:
        return np.sort(np.stack(cols, axis=2), axis=2)[:, :, win // 2]
    # five values: drop the smallest and the largest of the first four, take the median of three (a
    # selection network: the result is one of the inputs, exactly as a sort would pick it)
    a, b, c, d, e = cols
    lo = np.maximum(np.minimum(a, b), np.minimum(c, d))
    hi = np.minimum(np.maximum(a, b), np.maximum(c, d))
    return np.maximum(np.minimum(lo, hi), np.minimum(np.maximum(lo, hi), e))
