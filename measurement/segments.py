"""Stripe segments: centres linked from row to row, cut where a stripe passes onto another surface,
denoised (Algorithm 3) and smoothed along the stripe."""

from __future__ import annotations

import cv2
import numpy as np

from . import _kernels
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
    seg = np.empty(m, np.int64)
    seg[order] = _kernels.link_components(key, float(link_px))
    return seg


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
    order = np.lexsort((c.v, seg))
    logc = np.log(np.maximum(c.contrast.astype(np.float64), 1.0))
    _kernels.change_cuts(order, _runs(seg[order]), logc, c.u, c.v.astype(np.float64), window,
                         float(np.log(ratio)), slope_change, out, int(seg.max()) + 1)
    return out


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
