"""Isolating the animal and its automatic measurements (section 2.3.3): per-stripe extents give the body
height (or width seen from above), the first and last stripe groups give the body length, and an
oriented box of the cloud is a cross-check. Every measurement keeps the points it came from."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _kernels
from .threads import second_core


@dataclass(frozen=True)
class BodyParams:
    """Knobs of isolation and measurement.

    min_group     : stripe groups with fewer animal points are ignored
    trim          : robust extreme quantile
    background_mm : points within this distance of a floor/wall plane estimate the planes' noise; the
                    background margin never exceeds it
    background_sigmas, min_background_mm : points within max(min_background_mm, background_sigmas x that
                    noise) of a plane are background (a foot standing on the floor keeps all but its
                    lowest few mm; a fixed 12 mm cut the lowest 12 mm of every leg)
    cluster_mm    : neighbour radius (voxel size) of the connectivity that picks the animal
    rival_share, max_planar : clusters holding at least ``rival_share`` of the largest one's points are
                    rivals for the animal; a rival lying on three planes for more than ``max_planar`` of its
                    points (``planar_share``: a box, a trough, a board) is not the animal
    """

    min_group: int = 10
    trim: float = 0.01
    background_mm: float = 12.0
    background_sigmas: float = 10.0
    min_background_mm: float = 3.0
    cluster_mm: float = 25.0
    rival_share: float = 0.25
    max_planar: float = 0.85


def background_margin(distance: np.ndarray, params: BodyParams = BodyParams()) -> float:
    """Distance (mm) from the background planes under which a point is background: ``background_sigmas``
    robust standard deviations of the points near the planes (mostly floor and wall: 0.2-0.35 mm on
    the simulator), clipped to [min_background_mm, background_mm].

    distance : (N,) float64 distance of each point to its nearest background plane, mm
    """
    near = distance[distance <= params.background_mm]
    if len(near) < 100:
        return params.background_mm
    sigma = 1.4826 * float(np.median(near))  # |d| of a zero-mean normal: median = 0.6745 sigma
    return float(np.clip(params.background_sigmas * sigma, params.min_background_mm, params.background_mm))


def isolate(points: np.ndarray, background: np.ndarray | None, params: BodyParams = BodyParams()) -> np.ndarray:
    """(N,) bool mask of the animal: off the background planes (by ``background_margin``), then the
    largest cluster of points connected through occupied voxels of ``cluster_mm`` (26-neighbourhood) that
    is not a box (``planar_share``)."""
    return isolate_with_margin(points, background, params)[0]


def isolate_with_margin(points: np.ndarray, background: np.ndarray | None, params: BodyParams = BodyParams()
                        ) -> tuple[np.ndarray, float]:
    """``isolate``'s mask (N,) and the distance (mm) from the background planes under which it took a point
    for background (``background_margin``; 0 without planes)."""
    from scipy import ndimage

    margin = 0.0

    if background is not None and len(background) and points.dtype == background.dtype == np.float64:
        # in one compiled pass: finite points, each point's least |n . p - d| over the planes and those
        # near them (for the margin)
        keep, d = np.empty(len(points), bool), np.empty(len(points))
        near = _kernels.plane_distances(points, _plane_products(points, background[:, :3].T),
                                        np.ascontiguousarray(background[:, 3]), params.background_mm, keep, d)
        margin = background_margin(near, params)
        keep &= d > margin
    else:
        keep = np.isfinite(points[:, 0]) & np.isfinite(points[:, 1]) & np.isfinite(points[:, 2])
        if background is not None and len(background):
            d = np.abs(_plane_products(points, background[:, :3].T) - background[:, 3])
            d = np.minimum.reduce(list(d.T)) if d.shape[1] > 1 else d[:, 0]  # faster than min(axis=1) over 2
            margin = background_margin(d[keep], params)
            keep &= d > margin
    idx = np.nonzero(keep)[0]
    if len(idx) < params.min_group:
        return np.zeros(len(points), bool), margin
    cells, shape = _voxel_cells(points, idx, params.cluster_mm)
    if np.prod(shape) > 60_000_000:  # absurdly spread cloud: fall back to one cluster
        out = np.zeros(len(points), bool)
        out[idx] = True
        return out, margin
    grid = np.zeros(int(np.prod(shape)), bool)
    grid[cells] = True
    labels, _ = ndimage.label(grid.reshape(shape), structure=np.ones((3, 3, 3), bool))
    lab = labels.ravel()[cells]
    sizes = np.bincount(lab)
    biggest = int(np.argmax(sizes[1:])) + 1
    rivals = np.flatnonzero(sizes >= params.rival_share * sizes[biggest])
    rivals = rivals[rivals > 0]
    if len(rivals) > 1:  # a feed box or a board beside the animal: keep the largest cluster that is no box
        curved = [int(k) for k in rivals if planar_share(points[idx[lab == k]]) < params.max_planar]
        if curved:
            biggest = max(curved, key=lambda k: (sizes[k], -k))
    out = np.zeros(len(points), bool)
    out[idx[lab == biggest]] = True
    return out, margin


def beside(animal: np.ndarray, points: np.ndarray, background: np.ndarray | None, margin_mm: float,
           voxel_mm: float) -> np.ndarray:
    """(K,) bool: which of ``points`` (K, 3) mm ``isolate`` would have taken with the ``animal`` (N, 3) mm:
    finite, more than ``margin_mm`` off every background plane (P, 4), and in a voxel of ``voxel_mm`` that
    is one of the animal's or touches one (26-neighbourhood)."""
    out = np.isfinite(points).all(axis=1)
    if len(points) == 0 or len(animal) == 0:
        return out & False
    if background is not None and len(background):
        out &= np.abs(points @ background[:, :3].T - background[:, 3]).min(axis=1) > margin_mm
    from scipy import ndimage

    origin = animal.min(axis=0) - voxel_mm  # one spare cell on each side of the animal's voxels
    cells = np.floor((animal - origin) / voxel_mm).astype(np.int64)
    grid = np.zeros(tuple(cells.max(axis=0) + 3), bool)
    grid[tuple(cells.T)] = True
    grid = ndimage.binary_dilation(grid, structure=np.ones((3, 3, 3), bool))  # the animal's and beside it
    at = np.floor((np.nan_to_num(points) - origin) / voxel_mm).astype(np.int64)
    inside = ((at >= 0) & (at < grid.shape)).all(axis=1)
    out[inside] &= grid[tuple(at[inside].T)]
    return out & inside


def planar_share(points: np.ndarray, planes: int = 3, tol_mm: float = 2.0, most: int = 3000) -> float:
    """Share of the points (K, 3) mm within ``tol_mm`` of ``planes`` planes fitted one after another (RANSAC
    on what the previous ones left; an even subsample of about ``most`` points). A box's three visible faces
    give 1.0; an animal's curved body 0.17-0.58 on the simulator's renders (procedural quadruped, cow, horse,
    fox, dog, bunny; side and top views)."""
    from .planes import fit_plane_robust

    rng = np.random.default_rng(0)
    rest = np.asarray(points, np.float64)[::max(1, len(points) // most)]
    total = len(rest)
    for _ in range(planes):
        if len(rest) < 30:
            break
        plane, _ = fit_plane_robust(rest, rng, iterations=100, inlier_mm=tol_mm, exact=False)
        rest = rest[np.abs(rest @ plane[:3] - plane[3]) >= tol_mm]
    return 1.0 - len(rest) / total if total else 0.0


def _voxel_cells(points: np.ndarray, idx: np.ndarray, voxel: float) -> tuple[np.ndarray, tuple[int, ...]]:
    """Voxel (flat index (K,) into a C-ordered grid) of each point ``idx`` (K,) of points (N, 3) mm, cells of
    ``voxel`` mm counted from the points' lowest corner, and the grid's shape (3 ints)."""
    if points.dtype == np.float64 and points.ndim == 2 and points.shape[1] == 3:
        flat, shape = _kernels.voxel_cells(points, idx, float(voxel))
        return flat, tuple(int(n) for n in shape)
    kept = points[idx]
    ijk = np.floor((kept - kept.min(axis=0)) / voxel).astype(np.int64)
    grid_shape = tuple(int(n) for n in ijk.max(axis=0) + 1)
    return np.ravel_multi_index(tuple(ijk.T), grid_shape), grid_shape


_PRODUCT_ROWS = 4096


def _plane_products(points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """points (N, 3) @ normals (3, P), in blocks of rows: each block stays below OpenBLAS's threading
    threshold (M N K < 262144), and the same kernel gives the same products (to the bit) while a threaded
    product of the whole cloud sometimes waited ~40 ms for its second thread on a busy machine."""
    out = np.empty((len(points), normals.shape[1]), np.result_type(points, normals))
    for a in range(0, len(points), _PRODUCT_ROWS):
        np.matmul(points[a:a + _PRODUCT_ROWS], normals, out=out[a:a + _PRODUCT_ROWS])
    return out


def _extents(points: np.ndarray, first: np.ndarray, last: np.ndarray, trim: float
             ) -> tuple[np.ndarray, np.ndarray]:
    """``_extent`` of each group points[first[g]:last[g]] (G,) of points (N, 3) mm: extents (G,) mm and
    extreme points (G, 2, 3) mm. Compiled, all groups in one call; NumPy where a point is not finite or a
    pass keeps under 5 points."""
    ends = np.zeros((len(first), 2, 3))
    finite = bool(np.isfinite(points).all())
    ext = _kernels.group_extents(points, first, last, trim, ends) if finite else np.full(len(first), np.nan)
    for g in np.flatnonzero(np.isnan(ext)):
        ext[g], ends[g] = _extent(points[first[g]:last[g]], trim)
    return ext, ends


ENDS_WEIGHED = 0.85  # groups whose extent without the faint ends is at least this share of the largest
ENDS_STEP_MM = 8.0  # a faint end's first point lies this close to its group's extremes, or it is not read


def _with_ends(grouped: np.ndarray, first: np.ndarray, last: np.ndarray, ks: np.ndarray,
               ends: tuple[np.ndarray, ...], trim: float, exts: np.ndarray,
               all_ends: np.ndarray) -> int:
    """The extents (in ``exts`` and ``all_ends``, in place) of the groups that may be the largest (at least
    ``ENDS_WEIGHED`` of it), read with their stripes' faint ends ``ends`` (points (E, 3) mm, stripe (E,),
    the walk (E,) each came from, its points in order). Returns how many end points were read."""
    used = 0
    for g in np.flatnonzero(exts >= ENDS_WEIGHED * np.nanmax(exts)):
        mine = ends[1] == ks[g]
        if not mine.any():
            continue
        extra, walk = ends[0][mine], ends[2][mine]
        walks, start_of = np.unique(walk, return_index=True)
        start = start_of[np.searchsorted(walks, walk)]
        x = grouped[first[g]:last[g]]
        e, n = np.nan, 0
        if np.isfinite(x).all() and np.isfinite(extra).all():
            e, n = _kernels.group_extent_with(x, np.ascontiguousarray(extra, np.float64), start, trim,
                                              ENDS_STEP_MM, all_ends[g])
        if np.isnan(e):
            e, all_ends[g], n = _extent_with(x, extra, start, trim)
        exts[g] = e
        used += int(n)
    return used


def _extent_with(points: np.ndarray, extra: np.ndarray, start: np.ndarray, trim: float
                 ) -> tuple[float, np.ndarray, int]:
    """``_extent`` of points (K, 3) with the ``extra`` points (E, 3) that fall within its fences: the
    group's direction and fences are its own points' (extra points extend its extremes, they cannot change
    which part of a stripe counts). ``start`` (E,): the index in ``extra`` of the first point of the walk
    each came from; a walk counts only if its first point lies within ``ENDS_STEP_MM`` of the group's own
    trimmed extremes (the end of a stray bit of stripe past them, a few points the trim left out, extends
    nothing). Returns the extent, the two extreme points (2, 3) and how many extra points were read."""
    c, axis, t, keep, lo_f, hi_f = _fenced(points)
    lo0, hi0 = _quantiles(t[keep], (trim, 1 - trim))
    te = (extra - c) @ axis
    t0 = te[start]
    inside = (te >= lo_f) & (te <= hi_f) & (t0 >= lo0 - ENDS_STEP_MM) & (t0 <= hi0 + ENDS_STEP_MM)
    lo, hi = _quantiles(np.r_[t[keep], te[inside]], (trim, 1 - trim))
    return float(hi - lo), np.array([c + lo * axis, c + hi * axis]), int(inside.sum())


def _fenced(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float, float]:
    """``_extent``'s fencing: the centre (3,), principal direction (3,), each point's coordinate along it
    (K,), the points within Tukey's fences (K,) bool, and the fences."""
    keep = np.ones(len(points), bool)
    lo_f, hi_f = -np.inf, np.inf
    for _ in range(2):
        c = _column_medians(points[keep])
        _, _, vt = np.linalg.svd(points[keep] - c, full_matrices=False)
        t = (points - c) @ vt[0]
        q1, q3 = _quantiles(t[keep], (0.25, 0.75))
        lo_f, hi_f = q1 - 1.5 * (q3 - q1), q3 + 1.5 * (q3 - q1)
        fenced = (t >= lo_f) & (t <= hi_f)
        if (fenced == keep).all():  # nothing dropped: another pass would repeat this one exactly
            break
        keep = fenced
    return c, vt[0], t, keep, lo_f, hi_f


def _extent(points: np.ndarray, trim: float) -> tuple[float, np.ndarray]:
    """Robust extent of a group along its principal direction and its two extreme points (2, 3).
    Specks beyond Tukey's fences (1.5 interquartile ranges) are dropped before the extremes are taken."""
    c, axis, t, keep, _, _ = _fenced(points)
    lo, hi = _quantiles(t[keep], (trim, 1 - trim))
    return float(hi - lo), np.array([c + lo * axis, c + hi * axis])


def _column_medians(x: np.ndarray) -> np.ndarray:
    """np.median(x, axis=0) of a (n, d) x, n >= 1, from one partition: the same order statistics and the
    same mean of the middle two, without np.median's overhead (``_extent`` calls it per stripe group)."""
    n = len(x)
    if not np.isfinite(x).all():  # np.median's NaN handling
        return np.median(x, axis=0)
    k = n // 2
    if n % 2:
        return np.partition(x, k, axis=0)[k]
    s = np.partition(x, [k - 1, k], axis=0)
    return (s[k - 1] + s[k]) / 2


def _quantiles(x: np.ndarray, qs: tuple[float, ...]) -> list[float]:
    """np.quantile(x, qs) of a finite 1-D x with the same (linear) interpolation and arithmetic, without
    its overhead: the measurement calls it thrice per stripe group."""
    n = len(x)
    where = [(n - 1) * q for q in qs]
    kth = sorted({min(max(int(np.floor(v)) + j, 0), n - 1) for v in where for j in (0, 1)})
    s = np.partition(x, kth)
    out = []
    for v in where:
        if v >= n - 1 or v < 0:
            out.append(float(s[-1] if v >= n - 1 else s[0]))
            continue
        i = int(np.floor(v))
        a, b, t = float(s[i]), float(s[i + 1]), v - i
        out.append(b - (b - a) * (1 - t) if t >= 0.5 else a + (b - a) * t)
    return out


def measure(points: np.ndarray, stripe: np.ndarray, rows: np.ndarray, view: str,
            params: BodyParams = BodyParams(), ends: tuple[np.ndarray, ...] | None = None,
            wide: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
            past_ends: tuple[np.ndarray, np.ndarray] | None = None) -> dict:
    """Automatic measurements of an isolated animal cloud.

    points (N, 3) mm, stripe (N,) index, rows (N,) image row of each point.
    ends : points (E, 3) mm, stripe indices (E,), walks (E,) and, optionally, image rows (E,) of the stripes'
           faint ends (``ends``): the per-stripe extents (height, or width from above) read them with the
           group's points; the groups (at least ``min_group`` points of the cloud) and the extents are the
           cloud's alone. With their rows, the length reads those of stripes that neither the cloud nor
           ``wide`` make a group of, as it reads ``wide`` (a tail tip seen from above, its outermost stripe
           8 rows in the cloud and 14 faint ones: the 50-stripe clean top view of seed 10, -7.6 -> +0.6 %).
    wide : points (W, 3) mm, stripe indices (W,) and rows (W,) of the animal's labelled centres the cloud
           leaves out (wide or one-sided peaks, ``detection.reliable``, and centres off the median along
           their stripe, ``segments.smooth_along_stripes``). The length reads those of the
           stripes the cloud holds too few points of to make a group: where a stripe crosses a thin or
           grazing part (the tail's tip seen from above, a snout from the side) it is detected as wide, dim
           peaks, and without it the length's first or last group is the next stripe's, 7-9 % short. Their
           positions are off by 1-3 px, mostly in depth along the stripe's plane, which barely moves a
           distance between the body's two ends; the groups the cloud makes are left as they are (more rows
           there would move the length's 10-row rule).
    past_ends : points (X, 3) mm and stripe indices (X,) of such left-out centres that lie beyond their stripe's
           first or last row in the cloud: the per-stripe extents read them as they read the faint ends (each
           point a walk of its own, so within ``ENDS_STEP_MM`` of the group's trimmed extremes); the length and
           the groups do not. The pipeline passes them from above, where a stripe crossing the flank at grazing
           incidence ends in wide or one-sided peaks and the body's width ran 1-3 % short.
    """
    out: dict = {"view": view, "point_count": int(len(points))}
    ks, counts = _stripe_counts(stripe)
    groups = [int(k) for k, n in zip(ks, counts, strict=True) if n >= params.min_group]
    out["stripes_detected"] = len(groups)
    out["body_height_mm"] = None
    out["body_length_mm"] = None
    if not groups:
        return out
    # the cross-check and the length need only the points and their rows: beside the extents
    box = second_core().submit(_box, points)
    lp, ls, lr, lg = points, stripe, rows, groups
    if wide is not None and len(wide[1]):  # only stripes the cloud makes no group of
        lp, ls, lr, lg = _thin_joined((lp, ls, lr, lg), wide[0], wide[1], wide[2], params.min_group)
        if lg != groups:
            out["length_wide_groups"] = sorted(set(lg) - set(groups))
    if ends is not None and len(ends) > 3 and len(ends[1]):
        # the stripes' faint ends, with their rows, for stripes neither the cloud nor the wide peaks make a group
        # of (walked past a group's true end they run on in the blur's halo, and its rows would move the mean)
        before = lg
        lp, ls, lr, lg = _thin_joined((lp, ls, lr, lg), ends[0], ends[1], ends[3], params.min_group)
        if lg != before:
            out["length_faint_groups"] = sorted(set(lg) - set(before))
    length_job = second_core().submit(_length, lp, ls, lr, lg, params.min_group)
    # each group's points in their original order (one stable sort instead of a mask per group)
    order = _stable_order(stripe)
    ks_sorted, ks_arr = stripe[order], np.array(groups)
    first, last = np.searchsorted(ks_sorted, ks_arr), np.searchsorted(ks_sorted, ks_arr, side="right")
    grouped = np.asarray(points[order], np.float64)
    exts, all_ends = _extents(grouped, first, last, params.trim)
    ext_ends = _ends_and_past(ends, past_ends)
    if ext_ends is not None:
        out["faint_end_points"] = _with_ends(grouped, first, last, ks_arr, ext_ends, params.trim, exts, all_ends)
    best = max(range(len(groups)), key=lambda g: exts[g])  # the first of equals, as max() of the groups
    ext, extremes, k_best = float(exts[best]), all_ends[best], groups[best]
    name = "body_width" if view == "top" else "body_height"
    out["body_height_mm"] = round(ext, 2)
    out[name] = {"value_mm": round(ext, 2), "stripe": k_best, "points": extremes.tolist()}
    out["body_height_is"] = name
    length = length_job.result()
    if length is not None:
        out["body_length_mm"] = round(length["value_mm"], 2)
        out["body_length"] = length
    out["oriented_box_mm"] = box.result()
    return out


def _ends_and_past(ends: tuple[np.ndarray, ...] | None, past: tuple[np.ndarray, np.ndarray] | None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The faint ends' points, stripes and walks (``measure``'s ``ends``) with the ``past_ends`` points and stripes
    joined, each of those a walk of its own; None when there are neither."""
    if ends is not None and len(ends[1]) == 0:
        ends = None
    if past is None or len(past[1]) == 0:
        return (ends[0], ends[1], ends[2]) if ends is not None else None
    base = int(ends[2].max()) + 1 if ends is not None else 0
    walks = base + np.arange(len(past[1]), dtype=np.int64)
    if ends is None:
        return past[0], past[1], walks
    return (np.concatenate([ends[0], past[0]]), np.concatenate([ends[1], past[1]]),
            np.concatenate([ends[2], walks]))


def _thin_joined(length_input: tuple, extra: np.ndarray, extra_stripe: np.ndarray, extra_rows: np.ndarray,
                 min_group: int) -> tuple:
    """The length's points (N, 3), stripes (N,), rows (N,) and groups with the ``extra`` points (E, 3), their
    stripes (E,) and rows (E,) of stripes that are no group yet joined, and the groups counted again."""
    lp, ls, lr, lg = length_input
    thin = ~np.isin(extra_stripe, lg)
    if not thin.any():
        return length_input
    lp = np.concatenate([lp, extra[thin]])
    ls, lr = np.concatenate([ls, extra_stripe[thin]]), np.concatenate([lr, extra_rows[thin]])
    k2, c2 = _stripe_counts(ls)
    return lp, ls, lr, [int(k) for k, n in zip(k2, c2, strict=True) if n >= min_group]


def _stable_order(stripe: np.ndarray) -> np.ndarray:
    """``np.argsort(stripe, kind="stable")`` of stripe indices (N,): a counting sort when they are small
    non-negative integers (as the pipeline's are)."""
    if len(stripe) and stripe.dtype.kind in "iu" and stripe.min() >= 0 and stripe.max() <= 1_000_000:
        return _kernels.stable_group_order(stripe.astype(np.int64, copy=False), int(stripe.max()) + 1)
    return np.argsort(stripe, kind="stable")


def _stripe_counts(stripe: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """np.unique(stripe, return_counts=True) of stripe indices (N,), by one count per index when they are
    small non-negative integers (as the pipeline's are)."""
    if len(stripe) == 0 or stripe.dtype.kind not in "iu" or stripe.min() < 0 or stripe.max() > 1_000_000:
        return np.unique(stripe, return_counts=True)
    counts = np.bincount(stripe)
    ks = np.flatnonzero(counts)
    return ks.astype(stripe.dtype), counts[ks]


def _length(points, stripe, rows, groups, min_rows) -> dict | None:
    """Mean distance between the first and last stripe groups over the image rows both have; if they
    share fewer than ``min_rows`` rows, the outermost pair that does (largest index span, then most
    shared rows)."""
    has, top = _row_table(stripe, rows, groups)
    for span in range(len(groups) - 1, 0, -1):
        counts = np.count_nonzero(has[:-span] & has[span:], axis=1)  # shared rows of each pair this far apart
        ok = np.flatnonzero(counts >= min_rows)
        if len(ok) == 0:
            continue
        a_i = int(ok[np.argmax(counts[ok])])  # the first of the most
        a, b = groups[a_i], groups[a_i + span]
        shared = np.flatnonzero(has[a_i] & has[a_i + span]) + top
        ma, mb = stripe == a, stripe == b
        pa = _per_row(points[ma], rows[ma], shared)
        pb = _per_row(points[mb], rows[mb], shared)
        d = np.linalg.norm(pa - pb, axis=1)
        i = int(np.argmin(np.abs(d - np.median(d))))
        outermost = span == len(groups) - 1
        note = None if outermost else (
            f"the outermost groups (stripes {groups[0]} and {groups[-1]}) share fewer than {min_rows} rows; "
            f"stripes {a} and {b} were used")
        return {"value_mm": float(np.mean(d)), "stripes": [int(a), int(b)], "rows": int(len(shared)),
                "points": [pa[i].tolist(), pb[i].tolist()], "note": note}
    return None


def _row_table(stripe: np.ndarray, rows: np.ndarray, groups: list[int]) -> tuple[np.ndarray, int]:
    """(G, R) bool: whether group g (stripe ``groups[g]``, ascending) has a point in image row top + r,
    and top, the first row of any point."""
    top = int(rows.min())
    has = np.zeros((len(groups), int(rows.max()) - top + 1), bool)
    ks = np.array(groups)
    g = np.minimum(np.searchsorted(ks, stripe), len(ks) - 1)
    mine = ks[g] == stripe
    has[g[mine], rows[mine] - top] = True
    return has, top


def _per_row(points: np.ndarray, rows: np.ndarray, shared: np.ndarray) -> np.ndarray:
    order = np.argsort(rows, kind="stable")
    r, p = rows[order], points[order]
    first = np.searchsorted(r, shared)
    return p[first]


def _box(points: np.ndarray) -> dict:
    c = points.mean(axis=0)
    x = points - c
    # the SVD of the QR factor R: np.linalg.svd's own first step for a tall matrix (the same axes to the
    # bit), without forming the (N, 3) left singular vectors
    _, _, vt = np.linalg.svd(np.linalg.qr(x, mode="r")) if len(points) >= 5 else \
        np.linalg.svd(x, full_matrices=False)
    # np.quantile(t, [0.01, 0.99], axis=0), a contiguous column at a time
    lo, hi = np.array([_quantiles(col, (0.01, 0.99)) for col in (x @ vt.T).T.copy()]).T
    size = hi - lo
    return {"length_mm": round(float(size[0]), 2), "width_mm": round(float(size[2]), 2),
            "height_mm": round(float(size[1]), 2), "axes": vt.tolist(), "centre": c.tolist()}
