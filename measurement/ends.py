"""Faint stripe ends: where a stripe grazes the animal's outline (the flank seen from above, the back of a
dark coat seen from the side) its last rows fade under the detector's contrast threshold, and every
per-stripe extent (the body height, or width from above) came out short by them: 2-5 % from above on the
simulator's renders. The measurement follows each animal stripe past its last confident centre over the
faint peaks (``detection.detect_centres_and_faint``) and the centres labelling left unlabelled, one row at
a time along the stripe, and reads the extents to where the stripe ends.

These points stay out of the cloud: a fading peak at a grazing outline is biased by 1-6 px, which is mostly
depth along its light plane and barely moves an extent, but would put the cloud's points millimetres off
the surface. Labelling never sees them either (more centres shift the animal's stripe offset on some
views: ``DetectionParams.weak_contrast``)."""

from __future__ import annotations

import numpy as np

from . import _kernels
from .detection import Centres
from .segments import runs, segment_rows
from .triangulation import intersect, rays_at

MAX_ROWS = 36  # rows (at a 2048-row image) a stripe is followed past its last confident centre
SLOPE_ROWS = 6  # rows over which a segment's end slope is taken
ROW_GAP = 3  # a step may skip up to two rows without a peak (dark fur cuts a faint stripe)
MERGE_ROWS = 3  # rows (at a 2048-row image) a stripe's end is followed along a floor or wall stripe
OTHER_STRIPE_MM = 1.5  # a peak some other light plane puts this close to the floor or wall is that stripe's
# a walk ends at its first point this close to the floor or wall (or within the cloud's background margin,
# if wider): a hoof's last rows above the floor are the animal's, the contact below them is not told apart
FLOOR_STOP_MM = 5.0


def faint_ends(c: Centres, labels: np.ndarray, segment: np.ndarray, cloud: np.ndarray, scene: np.ndarray,
               faint: Centres, link_px: float, image_rows: int, over_background: bool = False,
               order: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The rows past each animal segment's ends that its stripe still crosses: u (E,) float64 and v (E,)
    int64 pixels and the stripe index (E,) of each, and the walk (E,) int64 it came from (its points in
    order, from the segment's end outward).

    c, labels, segment : the centres (M,), their stripe labels (-1: none) and segment ids
    cloud : indices (K,) into c of the animal's points; each of their segments is followed from both ends
    scene : indices into c of every point of the scene (the animal's among them): none is stepped on
    faint : the faint peaks of the same image
    link_px : largest column change per row from the stripe's course (its slope over the last rows)
    over_background : the scene's points off the animal (the floor's and wall's) may be stepped on too
    order : ``segments.segment_rows(segment, c.v)`` (M,), when known (``cloud`` then ascending)

    A step goes to the nearest peak in the next row (or up to ``ROW_GAP`` on) within ``link_px`` of where the
    stripe's course leads: a faint peak or a centre with no label or with the walk's own, never one a
    labelled point of the scene holds (that stripe is another's), but with ``over_background`` the
    floor's and wall's: seen from above, where the animal's stripe ends at the flank it merges with the
    floor's stripe four or five over (the depth alias), and labelling gives the merged rows to the floor's
    segment; the walk would stop one to five rows short of the stripe's end (``end_points`` stops it three
    rows into such a merge). Two walks reaching the same peak both stop there."""
    none = (np.zeros(0), np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64))
    if len(cloud) == 0:
        return none
    in_scene = np.zeros(len(c), bool)
    in_scene[cloud if over_background else scene] = True
    # what a walk may step on: with the faint peaks, the centres outside the scene's points (the animal's,
    # with ``over_background``), within reach of the animal's rows and columns
    reach = max(1, int(round(MAX_ROWS * image_rows / 2048.0))) + ROW_GAP
    v_lo, v_hi = int(c.v[cloud].min()) - reach, int(c.v[cloud].max()) + reach
    u_lo, u_hi = float(c.u[cloud].min()) - 4 * reach, float(c.u[cloud].max()) + 4 * reach
    free = np.flatnonzero(~in_scene & (c.v >= v_lo) & (c.v <= v_hi) & (c.u >= u_lo) & (c.u <= u_hi))
    near = (faint.v >= v_lo) & (faint.v <= v_hi) & (faint.u >= u_lo) & (faint.u <= u_hi)
    faint = faint.take(near)
    pool_u = np.r_[c.u[free], faint.u]
    pool_v = np.r_[c.v[free].astype(np.int64), faint.v.astype(np.int64)]
    free_lab = labels[free]
    if over_background:  # the floor's and wall's points are stepped on as unlabelled
        on_scene = np.zeros(len(c), bool)
        on_scene[scene] = True
        free_lab = np.where(on_scene[free], -1, free_lab)
    pool_lab = np.r_[free_lab, np.full(len(faint), -1, np.int64)]
    span = 4.0 * (max(float(pool_u.max(initial=0.0)), float(c.u.max())) + link_px + 2.0)
    pool_key = pool_v * span + pool_u
    by_key = np.argsort(pool_key, kind="stable")
    pool_u, pool_v, pool_lab, pool_key = pool_u[by_key], pool_v[by_key], pool_lab[by_key], pool_key[by_key]
    # each animal segment's two ends and the stripe's slope there (du/dv over the last SLOPE_ROWS rows)
    if order is None:
        by_seg = cloud[segment_rows(segment[cloud], c.v[cloud])]
    else:  # the order of all the centres restricted to the cloud's (distinct, ascending) is theirs
        in_cloud = np.zeros(len(c), bool)
        in_cloud[cloud] = True
        by_seg = order[in_cloud[order]]
    st = runs(segment[by_seg])
    first, last = by_seg[st[:-1]], by_seg[st[1:] - 1]
    near_first = by_seg[np.minimum(st[:-1] + SLOPE_ROWS, st[1:] - 1)]
    near_last = by_seg[np.maximum(st[1:] - 1 - SLOPE_ROWS, st[:-1])]
    u = np.r_[c.u[first], c.u[last]]
    v = np.r_[c.v[first], c.v[last]].astype(np.int64)
    dv = np.r_[c.v[first] - c.v[near_first], c.v[last] - c.v[near_last]].astype(np.float64)
    du = np.r_[c.u[first] - c.u[near_first], c.u[last] - c.u[near_last]]
    slope = np.where(dv != 0, du / np.where(dv == 0, 1.0, dv), 0.0)
    step = np.r_[np.full(len(first), -1), np.full(len(last), 1)].astype(np.int64)
    lab = np.r_[labels[first], labels[last]].astype(np.int64)
    return _kernels.walk_ends(pool_key, pool_u, pool_v, pool_lab, span, u, v, slope, step, lab, float(link_px),
                              max(1, int(round(MAX_ROWS * image_rows / 2048.0))), ROW_GAP)


def end_points(u: np.ndarray, v: np.ndarray, k: np.ndarray, walk: np.ndarray, table: np.ndarray,
               planes: np.ndarray, background: np.ndarray | None, margin_mm: float, run_rows: int,
               other_mm: float = OTHER_STRIPE_MM) -> tuple[np.ndarray, np.ndarray]:
    """Points (E, 3) mm of ``faint_ends``' peaks on their light planes, and a keep mask (E,) bool: each
    walk ends at its first point within ``margin_mm`` of a background plane (P, 4) (the stripe has run
    onto the floor or wall where the animal stands on it), and after ``run_rows`` points in a row that one
    other light plane puts within ``other_mm`` of a background plane: seen from above, a stripe's end at
    the flank merges with the floor's stripe a few over (the depth alias), its last rows lie on both, and
    past them only the floor's stripe goes on (a 1536 px top view's stripe followed 11 rows onto the floor
    measured the body's width 5.5 % wide). A single such point is chance (a floor stripe every 15 mm, a
    millimetre and a half of tolerance)."""
    rays = rays_at(u, v, table)
    p = intersect(rays, planes.take(k, axis=0))
    keep = np.isfinite(p).all(axis=1)
    if background is not None and len(background) and len(p):
        near = (np.abs(p @ background[:, :3].T - background[:, 3]) < margin_mm).any(axis=1) | ~keep
        other = np.full(len(p), -1, np.int64)  # the light plane that puts the peak on a background plane
        with np.errstate(divide="ignore", invalid="ignore"):
            depth = planes[:, 3] / (rays @ planes[:, :3].T)  # (E, N): along each ray to every light plane
            for q in range(len(background)):
                # the ray meets plane q at s_q; each light plane's point lies |depth - s_q| |n . ray| off it
                dot = rays @ background[q, :3]
                off = np.nan_to_num(np.abs(depth - (background[q, 3] / dot)[:, None]) * np.abs(dot)[:, None],
                                    nan=np.inf)
                j = off.argmin(axis=1)
                hit = off[np.arange(len(p)), j] < other_mm
                other = np.where(hit & (other < 0), j, other)
        # the walks' points are listed step by step: a point is kept while no earlier one of its walk was near
        # a background plane, and while it is no more than ``run_rows`` points into a run on one other light
        # plane's floor or wall stripe (where a stripe's end merges with that stripe, its last rows lie on
        # both; past them only the floor's stripe goes on): one compiled pass (``walk_stops_numpy``, the
        # NumPy form, is the reference)
        _kernels.walk_stops(walk, near, other, run_rows, keep)
    return p, keep


def walk_stops_numpy(walk: np.ndarray, near: np.ndarray, other: np.ndarray, run_rows: int, keep: np.ndarray
                     ) -> np.ndarray:
    """``_kernels.walk_stops`` step by step in NumPy (its reference): clears ``keep`` (E,) past each walk's
    stop."""
    stopped = np.zeros(int(walk.max()) + 1, bool)
    last_other = np.full(int(walk.max()) + 1, -1, np.int64)
    run = np.zeros(int(walk.max()) + 1, np.int64)
    for a, b in zip(*_step_bounds(walk), strict=True):
        w = walk[a:b]
        run[w] = np.where((other[a:b] >= 0) & (other[a:b] == last_other[w]), run[w] + 1,
                          (other[a:b] >= 0).astype(np.int64))
        end = near[a:b] | (run[w] > run_rows)
        keep[a:b] &= ~stopped[w] & ~end
        stopped[w[end]] = True
        last_other[w] = other[a:b]
    return keep


def _step_bounds(walk: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start and end offsets of the steps in ``faint_ends``' output: a new step begins where the walk id
    stops increasing (each step lists its surviving walks in ascending order)."""
    cut = np.r_[0, np.flatnonzero(np.diff(walk) <= 0) + 1, len(walk)]
    return cut[:-1], cut[1:]
