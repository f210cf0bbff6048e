"""Stripe segments: centres linked from row to row, cut where a stripe passes onto another surface,
denoised (Algorithm 3) and smoothed along the stripe."""

from __future__ import annotations

import numpy as np

from . import _kernels
from .detection import Centres
from .threads import second_core


def denoise(c: Centres, shape: tuple[int, int]) -> np.ndarray:
    """Algorithm 3's denoising: keep a centre when its neighbourhood (a square one average stripe width
    wide) holds at least half that many centres — a stripe contributes one per row, a speck of scattered
    light only a few. returns (M,) bool keep-mask."""
    if len(c) == 0:
        return np.zeros(0, bool)
    wdt = int(np.clip(round(c.median_width), 3, 25))
    h, w = shape
    ui = np.clip(np.rint(c.u).astype(np.int64), 0, w - 1)
    v = c.v.astype(np.int64)
    # the counts a full-frame box filter over a mask of the centres gives, taken at the centres only; in
    # raster order (as detection lists them) the upper half of the rows is counted on the second core
    # from the centres within reach of them
    if len(v) < 20_000 or (np.diff(v) < 0).any():
        return _kernels.crowded(v, ui, h, wdt)
    # a centre in row r counts rows r - wdt // 2 .. r - wdt // 2 + wdt - 1: the centres of the rows before
    # mid (the upper half) need those before row mid - wdt // 2 + wdt, the others those from mid - wdt // 2
    mid = int(v[len(v) // 2])
    below = int(np.searchsorted(v, mid - wdt // 2))
    above = int(np.searchsorted(v, mid - wdt // 2 + wdt))
    upper = second_core().submit(_kernels.crowded, v[:above], ui[:above], h, wdt)
    lower = _kernels.crowded(v[below:], ui[below:], h, wdt)
    cut = int(np.searchsorted(v, mid))
    return np.concatenate([upper.result()[:cut], lower[cut - below:]])


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
    # detection lists the centres so already (then the stable sort is the identity)
    order = np.arange(len(key)) if (key[1:] >= key[:-1]).all() else np.argsort(key, kind="stable")
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
    order = segment_rows(seg, c.v)
    logc = np.log(np.maximum(c.contrast.astype(np.float64), 1.0))
    _kernels.change_cuts(order, runs(seg[order]), logc, c.u, c.v.astype(np.float64), window,
                         float(np.log(ratio)), slope_change, out, int(seg.max()) + 1)
    return out


def segment_rows(seg: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``np.lexsort((v, seg))``: the centres (M,) by segment id (>= 0), then row, ties in index order; by
    counting sorts when the rows are integers (a tenth of the time on 10^5 centres)."""
    if len(seg) and np.issubdtype(v.dtype, np.integer) and seg.min() >= 0:
        if (v[1:] >= v[:-1]).all():  # already by row (detection lists centres so): one stable sort by segment
            return _kernels.stable_group_order(seg, seg.max() + 1)
        return _kernels.segment_row_order(seg, v)
    return np.lexsort((v, seg))


def runs(keys: np.ndarray) -> np.ndarray:
    """Start offsets (R + 1,) of the runs of equal values in sorted ``keys`` (K,), closed by len(keys)."""
    return np.r_[0, np.nonzero(keys[1:] != keys[:-1])[0] + 1, len(keys)]


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


def smooth_along_stripes(c: Centres, segment: np.ndarray, labels: np.ndarray, jump_px: float, half: int = 2,
                         outlier_px: float = 1.0, reach: int = 6, gap: int = 3, order: np.ndarray | None = None,
                         noisy: tuple[float, int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Each labelled centre's column (``c.position``: the shaded centroid where detection measured it)
    smoothed along its stripe: the value at its row of a straight line fitted to the centres of its run
    within ``reach`` rows (the surface is smooth over a couple of millimetres along a stripe, fur noise is
    not; a line, unlike an average, follows a slanted stripe to its ends), after flagging centres more than
    ``outlier_px`` off the median of the 2 ``half`` + 1 around them (specks of scattered light), which the fit
    reads as that median. A run is a linked segment's centres of one label, and the runs of that label it
    goes on into: one that starts at most ``gap`` rows after it ends, within ``jump_px`` per row of its last
    centre's column (linking cuts a stripe where its brightness jumps, as at fur's dark dropouts, and left a
    fifth of a fur side view's segments too short to smooth: points beyond 2 mm 0.77 -> 0.47 %, seed 4, 40
    stripes). Runs under 2 ``half`` + 1 centres are left as they are. With ``noisy`` (px, rows), a run whose
    kept centres lie a median of more than that many px off its line is smoothed again over that many rows
    (``pipeline.NOISY_RUN_PX``: fur's centres scatter about their stripe, a clean surface's hardly do).

    segment : (M,) linked segment id; labels : (M,) stripe index, -1 unlabelled (left as it is, flagged False)
    order : ``segment_rows(segment, c.v)`` (M,), when known
    returns : smoothed u (M,) float64, keep mask (M,) bool
    """
    position = c.position
    u = position.copy()
    keep = labels >= 0
    if not keep.any():
        return u, keep
    if order is None:
        idx = np.flatnonzero(keep)
        order = idx[segment_rows(segment[idx], c.v[idx])]
    else:  # the order of all the centres restricted to the labelled ones is theirs
        order = order[keep[order]]
    lab = labels[order]
    part = runs(segment[order] * (int(labels.max()) + 1) + lab)  # one label's centres of one segment
    first, last = order[part[:-1]], order[part[1:] - 1]
    parent = _kernels.chain_runs(np.lexsort((c.v[first], labels[first])), labels[first], c.v[first], c.u[first],
                                 c.v[last], c.u[last], gap, jump_px)
    root = np.arange(len(parent))
    while True:  # every run's chain: the run it goes on from, followed to the first
        up = np.where(parent[root] >= 0, parent[root], root)
        if (up == root).all():
            break
        root = up
    by_chain = np.lexsort((c.v[first], root))
    count = np.diff(part)[by_chain]
    chained = order[spans(part[:-1][by_chain], count)]
    chain_starts = np.r_[0, np.flatnonzero(root[by_chain][1:] != root[by_chain][:-1]) + 1, len(by_chain)]
    starts = np.r_[0, np.cumsum(count)][chain_starts]
    _kernels.smooth_runs(chained, starts, c.v, position, half, reach, outlier_px, u, keep)
    if noisy is not None:
        scatter = _kernels.run_scatter(chained, starts, position, u, keep, 2 * half + 1)
        loud = np.flatnonzero(scatter > noisy[0])
        if len(loud):  # those runs' centres laid out one run after another, smoothed over the longer reach
            count = np.diff(starts)[loud]
            sub = chained[spans(starts[:-1][loud], count)]
            _kernels.smooth_runs(sub, np.r_[0, np.cumsum(count)], c.v, position, half, noisy[1], outlier_px, u,
                                 keep.copy())
    return u, keep


def label_table(seg: np.ndarray, seg_label: dict[int, int]) -> np.ndarray:
    """Label (S,) of every segment id up to seg.max(), -1 where ``seg_label`` (segment -> label) has none."""
    table = np.full(seg.max() + 1, -1, np.int64)
    if seg_label:
        table[np.fromiter(seg_label.keys(), np.int64)] = np.fromiter(seg_label.values(), np.int64)
    return table


def segment_mask(seg: np.ndarray, keys) -> np.ndarray:
    """True (S,) for every segment id up to seg.max() among ``keys`` (a dict of segment -> label, or ids)."""
    mask = np.zeros(seg.max() + 1, bool)
    if len(keys):
        mask[np.fromiter(keys, np.int64, len(keys))] = True
    return mask


def spans(start: np.ndarray, count: np.ndarray) -> np.ndarray:
    """The ranges start[j] .. start[j] + count[j] - 1 one after another (count.sum(),): the positions of
    groups laid out by their starts, without a Python loop."""
    return np.arange(count.sum()) - np.repeat(np.cumsum(count) - count - start, count)
