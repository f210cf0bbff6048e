"""The background (floor, wall) of a scan: its planes, which centres lie on them, and which pieces of
stripe one index puts on them."""

from __future__ import annotations

from functools import cached_property

import numpy as np

from . import _kernels
from .segments import label_table, link_segments, split_at_changes
from .threads import second_core
from .triangulation import depth_for_labels, intersect


def background_planes(rays: np.ndarray, planes: np.ndarray, labels: np.ndarray, tol_mm: float = 8.0,
                       max_planes: int = 4, first_share: float = 0.2, next_share: float = 0.1,
                       points: np.ndarray | None = None) -> np.ndarray | None:
    """The dominant planes (floor, wall) of the labelled cloud, (P, 4); None when no plane carries
    ``first_share`` of it (no planar background to separate from). A further plane needs ``next_share``:
    with a noisy sensor the floor's rows are labelled far less often than the wall's. Up to four: a
    weighing platform adds its front and its top to the wall and the floor.
    ``points`` : (M, 3) mm, each centre's point on its label's plane where it has one
    (``intersect(rays, planes[labels])``, ray by ray), when known."""
    from .planes import fit_plane_robust

    idx = np.nonzero(labels >= 0)[0]
    if len(idx) < 200:
        return None
    if points is None:
        pts = intersect(rays.take(idx, axis=0), planes.take(labels[idx], axis=0))
    else:
        pts = points.take(idx, axis=0)
    found: list[np.ndarray] = []
    rest = np.ones(len(idx), bool)
    rng = np.random.default_rng(0)
    for _ in range(max_planes):
        cand = np.nonzero(rest)[0]
        # too few left for the share a plane needs: no fit could be kept
        if len(cand) < max(200, (next_share if found else first_share) * len(idx)):
            break
        sub = pts if len(cand) == len(pts) else pts.take(cand, axis=0)
        plane, _ = fit_plane_robust(sub, rng, iterations=300, inlier_mm=tol_mm / 2, exact=False, refine_points=16384)
        near = np.abs(pts @ plane[:3] - plane[3]) < tol_mm
        if near[rest].sum() < (next_share if found else first_share) * len(idx):
            break
        found.append(plane)
        rest &= ~near
    return np.array(found) if found else None


class Footprints:
    """Where each background plane was seen, as cells of a grid over the viewing rays (z = 1), ``cell`` wide:
    the planes are unbounded, the surfaces are not. The front of a weighing platform is a plane parallel to
    the wall, and the animal standing on the platform lies behind that plane but nowhere behind the
    platform. The cells are computed on the first ``covers`` (most scans never ask).

    A plane with a parallel one farther from the camera (a platform's front before the wall, its top above
    the floor, a rail) is taken where the complete rows saw it (``complete`` labels), inside the seen cells
    only: growth can carry the wall between the legs onto such a plane. Any other plane (the wall, the
    floor, a platform's front with no wall behind it) is taken where any background label saw it
    (``labels``, ``complete`` if not given), filled between the seen cells of each grid row (the wall behind
    the animal, the floor around the feet), and widened by two cells."""

    def __init__(self, rays: np.ndarray, planes: np.ndarray, complete: np.ndarray, bg_planes: np.ndarray,
                 labels: np.ndarray | None = None, tol_mm: float = 8.0, cell: float = 0.01, every: int = 4,
                 parallel_cos: float = 0.98) -> None:
        self._args = (rays, planes, complete, complete if labels is None else labels, bg_planes, tol_mm, every,
                      parallel_cos)
        self.cell = cell
        ends = rays[::64, :2]  # the grid spans every ray (a subsample's extent, four cells wider)
        lo = ends.min(axis=0) - 4 * cell
        self.origin = (float(lo[0]), float(lo[1]))
        self.shape = tuple(int(v) + 1 for v in np.floor((ends.max(axis=0) + 4 * cell - lo) / cell))[::-1]

    def covers(self, rays: np.ndarray) -> np.ndarray:
        """(K, P) bool: whether each ray (K, 3) falls where plane p was seen."""
        cells = self.cells
        ix, iy = self._cell_of(rays)
        _, h, w = cells.shape
        inside = (ix >= 0) & (ix < w) & (iy >= 0) & (iy < h)
        out = np.zeros((len(rays), len(cells)), bool)
        out[inside] = cells[:, iy[inside], ix[inside]].T
        return out

    def _cell_of(self, rays: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return (np.floor((rays[:, 0] - self.origin[0]) / self.cell).astype(np.int64),
                np.floor((rays[:, 1] - self.origin[1]) / self.cell).astype(np.int64))

    @cached_property
    def cells(self) -> np.ndarray:
        """(P, H, W) bool."""
        rays, planes, complete, labels, bg_planes, tol_mm, every, parallel_cos = self._args
        dist = np.abs(bg_planes[:, 3])  # the camera's distance from each plane (|n| = 1)
        cos = np.abs(bg_planes[:, :3] @ bg_planes[:, :3].T)
        bounded = ((cos > parallel_cos) & (dist[None, :] > dist[:, None])).any(axis=1)
        h, w = self.shape
        cells = np.zeros((len(bg_planes), h, w), bool)
        for which, lab, fill in ((bounded, complete, False), (~bounded, labels, True)):
            if not which.any():
                continue
            idx = np.flatnonzero(lab >= 0)[::every]
            d = np.abs(intersect(rays.take(idx, axis=0), planes.take(lab[idx], axis=0)) @ bg_planes[:, :3].T
                       - bg_planes[:, 3])
            ix, iy = self._cell_of(rays.take(idx, axis=0))
            ix, iy = np.clip(ix, 0, w - 1), np.clip(iy, 0, h - 1)
            for p in np.flatnonzero(which):
                seen = np.zeros((h, w), bool)
                on = d[:, p] < tol_mm
                seen[iy[on], ix[on]] = True
                if fill:  # between the first and the last seen cell of each row
                    seen = np.maximum.accumulate(seen, axis=1) & np.maximum.accumulate(seen[:, ::-1], axis=1)[:, ::-1]
                # a bounded surface (a platform's front, a rail) only where it was seen all around: a point
                # of the animal seen just beside it is beside it, not behind it
                cells[p] = _widen(seen, 2) if fill else _interior(seen)
        return cells


def _interior(cells: np.ndarray) -> np.ndarray:
    """cells (H, W) bool whose four neighbours are set too (an erosion by one cell)."""
    out = cells.copy()
    out[1:] &= cells[:-1]
    out[:-1] &= cells[1:]
    out[:, 1:] &= cells[:, :-1]
    out[:, :-1] &= cells[:, 1:]
    out[0], out[-1], out[:, 0], out[:, -1] = False, False, False, False
    return out


def _widen(cells: np.ndarray, k: int) -> np.ndarray:
    """cells (H, W) bool grown by k cells in every direction (a square dilation, by shifts)."""
    out = cells.copy()
    for axis in (0, 1):
        grown = out.copy()
        for s in range(1, k + 1):
            if axis == 0:
                grown[s:] |= out[:-s]
                grown[:-s] |= out[s:]
            else:
                grown[:, s:] |= out[:, :-s]
                grown[:, :-s] |= out[:, s:]
        out = grown
    return out


def near_planes(points: np.ndarray, bg_planes: np.ndarray, tol_mm: float = 8.0) -> np.ndarray:
    """(M,) True where a point lies within ``tol_mm`` of any background plane."""
    return _below_any(np.abs(points @ bg_planes[:, :3].T - bg_planes[:, 3]), tol_mm)


def _below_any(d: np.ndarray, tol_mm: float) -> np.ndarray:
    """(K,) True where some column of the distances d (K, P) is below ``tol_mm`` (NaN never is): the
    answer of ``np.nan_to_num(d, nan=np.inf).min(axis=1) < tol_mm`` column by column, several times faster
    than a reduction along an axis of one or two."""
    out = d[:, 0] < tol_mm
    for j in range(1, d.shape[1]):
        out |= d[:, j] < tol_mm
    return out


def _near_any_plane(rays: np.ndarray, planes: np.ndarray, bg_planes: np.ndarray, tol_mm: float,
                    chunk: int = 4096) -> np.ndarray:
    """(m, N) True where ray i's point on light plane k lies within ``tol_mm`` of a background plane.

    The distance is |(ray z) . n - d|. It is screened as |z (ray . n) - d| (no (m, N, 3) points), which
    differs only by rounding; where that lies within a hair of ``tol_mm`` the points are formed after
    all, so the answer is the one the exact formula gives (with ``depth_for_labels``' depths of the rays
    that have such a case)."""
    normals = np.ascontiguousarray(bg_planes[:, :3].T)  # (3, P)
    out = np.empty((len(rays), len(planes)), bool)

    def screen(starts: range) -> None:
        for a in starts:
            r = np.ascontiguousarray(rays[a:a + chunk])
            unsure = _kernels.near_any_plane(r, planes, bg_planes, tol_mm, out[a:a + chunk])
            if len(unsure):
                i, k = np.divmod(unsure, len(planes))
                # the depths of the rays with an unsure pair only (each row of depth_for_labels comes out
                # the same whichever rows share the call): a ray or two of the chunk, not all of it
                rows, at = np.unique(i, return_inverse=True)
                z = depth_for_labels(r.take(rows, axis=0), planes)[at, k]
                out[a + i, k] = _near_exact(r[i] * z[:, None], normals, bg_planes[:, 3], tol_mm)

    starts = range(0, len(rays), chunk)
    if len(starts) < 4:
        screen(starts)
        return out
    # each chunk writes its own rows: the later half on the second core
    later = second_core().submit(screen, starts[len(starts) // 2:])
    screen(starts[:len(starts) // 2])
    later.result()
    return out


def _near_exact(points: np.ndarray, normals: np.ndarray, d: np.ndarray, tol_mm: float) -> np.ndarray:
    """(K,) True where points (K, 3) lie within ``tol_mm`` of a plane (normals (3, P), offsets (P,))."""
    return _below_any(np.abs(points @ normals - d), tol_mm)


def _plane_fractions_per_segment(rays, planes, seg, sids, bg_planes, tol_mm):
    """Per segment in ``sids`` (S,) and light plane (N,): the share of its centres whose point on that
    plane lies within ``tol_mm`` of a background plane, (S, N); and the
    centres (K,) grouped by segment in the order of ``sids``, with their group starts (S + 1,)."""
    member = np.zeros(seg.max() + 1, bool)
    member[sids] = True
    idx = np.nonzero(member[seg])[0]
    idx = idx[_kernels.stable_group_order(seg[idx], len(member))]
    starts = np.searchsorted(seg[idx], sids)
    near = _near_any_plane(rays.take(idx, axis=0), planes, bg_planes, tol_mm)
    bounds = np.r_[starts, len(idx)]
    counts = _kernels.group_counts(near, bounds)
    return counts / np.diff(bounds)[:, None], idx, bounds


LOOSE_SHARE = 0.05  # ``claim_background``: a segment this much short of the share is claimed only if it is
LOOSE_FLATNESS = 2.0  # at most this many times as far off its plane as the labelled background's median


def claim_background(c, rays, planes, seg, seg_label, long_seg, bg_planes, n, min_rows: int = 6,
                      share: float = 0.95, tol_mm: float = 5.0, flatness: float = 4.0) -> dict[int, int]:
    """Unlabelled segments that exactly one stripe index puts on a background plane (>= ``share`` of
    their points within ``tol_mm``), and as flat as the background labelled so far on the plane they are
    nearest to: the median distance of their points from it at most ``flatness`` times that of the
    labelled background's points nearest to it (``background_flatness``).
    Animal stripes are curved and fit no single plane that way; a short piece of one (a tail's stripe cut
    by fur) can still land within ``tol_mm`` of the floor at some wrong index, but not as flat as the
    floor (over the 3072 px and 1536 px benches, the claims above 4x the floor's median distance were 141
    wrong and 23 right; below it, 35 wrong and 2800 right).

    Segments of ``min_rows`` or more are weighed, as short as the segments labelling keeps at all: a floor
    stripe's first rows at the foot of the wall (a kink in the image splits them off) and slivers of floor
    between the legs are 6-14 rows long; left out, they joined the animal's pieces, put floor points 8-25 mm
    off the animal's surface into its cloud (48 of the 40-stripe clean side view's 11 820 points) and
    polluted the animal's conflict curve (the shared fox's 3072 px side view was refused; 81 % right with
    them claimed). Weighing from 6 rows instead of 15 claimed 2921 more background centres rightly on the
    326-view dump and moved no view's placement but that fox's."""
    labelled = np.zeros(seg.max() + 1, bool)
    labelled[list(seg_label)] = True
    cand = long_seg & ~labelled[seg]
    sizes = np.bincount(seg[cand], minlength=seg.max() + 1)
    sids = np.nonzero(sizes >= min_rows)[0]
    # the labelled background's flatness, on the second core while the candidates are weighed
    flatness_bg = second_core().submit(background_flatness, rays, planes, seg, seg_label, bg_planes)
    frac, idx, starts = _plane_fractions_per_segment(rays, planes, seg, sids, bg_planes, tol_mm)
    hits = frac >= share
    # no index at ``share`` but exactly one at LOOSE_SHARE less: held to LOOSE_FLATNESS instead of ``flatness``
    near = frac >= share - LOOSE_SHARE
    loose = (hits.sum(axis=1) == 0) & (near.sum(axis=1) == 1)
    one = np.nonzero((hits.sum(axis=1) == 1) | loose)[0]
    if len(one) == 0:
        flatness_bg.result()
        return {}
    loose = loose[one]
    k = np.where(loose, near[one].argmax(axis=1), hits[one].argmax(axis=1))
    # the claimed segments' median distance from each background plane at their index, judged against the
    # labelled background's noise on the plane they are nearest to
    claimed = np.zeros(len(sids), bool)
    claimed[one] = True
    members = idx[np.repeat(claimed, np.diff(starts))]  # their centres, segment by segment as in ``one``
    counts = np.diff(starts)[one]
    points = intersect(rays.take(members, axis=0), planes.take(np.repeat(k, counts), axis=0))
    dist = np.abs(points @ bg_planes[:, :3].T - bg_planes[:, 3])  # (K, P)
    medians = np.column_stack([_group_medians(dist[:, j], counts) for j in range(len(bg_planes))])
    nearest = medians.argmin(axis=1)
    most = np.where(loose, LOOSE_FLATNESS, flatness) * flatness_bg.result()[nearest]
    flat = medians[np.arange(len(one)), nearest] <= most
    return dict(zip(sids[one][flat].tolist(), k[flat].tolist(), strict=True))


def _group_medians(x: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """np.median of each run of ``x`` (K,) in turn, the runs ``counts`` (G,) long (each at least 1): one
    compiled pass instead of a call per run."""
    return _kernels.group_medians(np.ascontiguousarray(x, dtype=np.float64), counts.astype(np.int64))


def background_flatness(rays, planes, seg, seg_label: dict[int, int], bg_planes, most: int = 20000,
                         min_points: int = 200, least_mm: float = 0.1) -> np.ndarray:
    """Per background plane (P,): the noise in depth (mm) its claims are held to: the median distance from
    it of the labelled background's points (segment -> index ``seg_label``, at most ``most`` of them,
    evenly thinned) nearest to it, and at least ``least_mm``. A wall seen face-on scatters far more than a
    floor seen at a grazing angle (0.5 mm against 0.04 mm from a camera 280 mm above the floor): held to
    one median over both, a low camera's wall went unclaimed and joined the animal. The floor of the
    simulator's clean renders lies within 0.04-0.08 mm of its plane in the bright far field, while its
    stripes between the legs scatter 0.3-0.4 mm: held to its own figure unbounded, four right floor
    segments of the 40-stripe clean side view went unclaimed. A plane with fewer than ``min_points``
    labelled points gets the median over all of them; inf without any labelled point."""
    table = label_table(seg, seg_label)
    idx = np.flatnonzero(table[seg] >= 0)
    idx = idx[:: len(idx) // most + 1]
    if len(idx) == 0:
        return np.full(len(bg_planes), np.inf)
    d = np.abs(intersect(rays.take(idx, axis=0), planes.take(table[seg[idx]], axis=0)) @ bg_planes[:, :3].T
               - bg_planes[:, 3])
    nearest = d.argmin(axis=1)
    dist = np.take_along_axis(d, nearest[:, None], axis=1)[:, 0]
    counts = np.bincount(nearest, minlength=len(bg_planes))
    out = np.array([float(np.median(dist[nearest == j])) if counts[j] >= min_points else np.nan
                    for j in range(len(bg_planes))])
    if np.isnan(out).any():
        out[np.isnan(out)] = float(np.median(dist))
    return np.maximum(out, least_mm)


def background_like(rays, planes, seg, mask, bg_planes, exclude: set, share: float = 0.8) -> np.ndarray:
    """(M,) True for centres of segments (in ``mask``, not in ``exclude``) that some stripe index puts
    on a background plane for at least ``share`` of their points."""
    out = np.zeros(len(seg), bool)
    weigh = np.zeros(seg.max() + 1, bool)
    weigh[seg[mask]] = True
    weigh[np.fromiter(exclude, np.int64, len(exclude))] = False
    sids = np.flatnonzero(weigh)
    frac, idx, starts = _plane_fractions_per_segment(rays, planes, seg, sids, bg_planes, 8.0)
    like = frac.max(axis=1, initial=0.0) >= share
    out[idx[np.repeat(like, np.diff(starts))]] = True
    return out


def segments_on_planes(rays, planes, seg, seg_label: dict[int, int], bg_planes, share: float = 0.9,
                       members: tuple[np.ndarray, np.ndarray] | None = None) -> set[int]:
    """The segments of ``seg_label`` (segment -> stripe index) whose points, on their stripe's plane, lie
    on the background planes for at least ``share`` of their centres. ``members`` : the centres of each
    segment (``_kernels.group_members(seg, seg.max() + 1)``), when known: a few segments' centres are then
    gathered instead of found among all."""
    table = label_table(seg, seg_label)
    if members is None:
        idx = np.nonzero(table[seg] >= 0)[0]
    else:
        starts, by_seg = members
        idx = np.sort(np.concatenate([by_seg[starts[s]:starts[s + 1]] for s in seg_label]))
    near = near_planes(intersect(rays.take(idx, axis=0), planes.take(table[seg[idx]], axis=0)), bg_planes)
    sids = np.fromiter(seg_label.keys(), np.int64)
    on = np.bincount(seg[idx], weights=near)[sids] / np.bincount(seg[idx])[sids] >= share
    return set(sids[on].tolist())


def foreground_mask(c, seg: np.ndarray, labels: np.ndarray, on_bg: np.ndarray) -> np.ndarray:
    """(M,) bool: the centres to take off the background: unlabelled, off the background planes (``on_bg``
    (M,) false), or within 15 rows of such a labelled centre in their segment. After ``relink_foreground``
    the labels of the others are unchanged (``labels`` are whole-segment), and these have none."""
    fg = (labels < 0) | ~on_bg
    # near the junction of a merged segment the last background-looking centres are suspect too
    fg |= _rows_to_foreground(seg, c.v, fg, fg & (labels >= 0)) <= 15
    return fg


def relink_foreground(c, seg, labels, fg, link, min_rows):
    """Unlabel the centres of ``foreground_mask`` fg (M,) and re-link them into their own segments: new
    segment ids (M,), long-segment mask (M,) and segment -> label of the kept segments."""
    m = len(seg)
    fg_idx = np.nonzero(fg)[0]
    sub = c.take(fg)
    fseg = split_at_changes(sub, link_segments(sub, link)) if len(fg_idx) else np.zeros(0, np.int64)
    new = seg.copy()
    new[fg_idx] = fseg + seg.max() + 1
    long_seg = np.zeros(m, bool)
    long_seg[~fg] = np.bincount(seg[~fg])[seg[~fg]] >= min_rows if (~fg).any() else False
    if len(fg_idx):
        long_seg[fg_idx] = np.bincount(fseg)[fseg] >= min_rows
    kept = np.nonzero(~fg & (labels >= 0))[0]
    # labels are whole-segment here (a segment table masked by segment length): any centre gives its label
    sids, first = _kernels.first_of_each(new[kept], int(new.max()) + 1 if len(new) else 0)
    by_first = np.argsort(first)
    seg_label = dict(zip(sids[by_first].tolist(), labels[kept[first[by_first]]].tolist(), strict=True))
    return new, long_seg, seg_label


def _rows_to_foreground(seg: np.ndarray, v: np.ndarray, fg: np.ndarray, mixed_by: np.ndarray) -> np.ndarray:
    """(M,) rows from each centre to the nearest foreground centre of its segment, for the segments
    holding a centre in ``mixed_by``; a large number elsewhere."""
    out = np.full(len(seg), np.iinfo(np.int64).max)
    mixed = np.zeros(seg.max() + 1, bool)
    mixed[seg[mixed_by]] = True
    idx = np.nonzero(mixed[seg])[0]
    if len(idx) == 0:
        return out
    span = int(v.max()) + 1
    key = seg[idx] * span + v[idx].astype(np.int64)
    fkey = np.sort(key[fg[idx]])
    pos = np.searchsorted(fkey, key)
    gap = np.full(len(idx), np.iinfo(np.int64).max)
    for nb in (np.clip(pos - 1, 0, len(fkey) - 1), np.clip(pos, 0, len(fkey) - 1)):
        same = fkey[nb] // span == seg[idx]
        gap[same] = np.minimum(gap[same], np.abs(fkey[nb] - key)[same])
    out[idx] = gap
    return out
