"""`scan`: one stripe image + a calibration -> labelled point cloud and automatic body size.

The one function the CLI, the jobs and the benchmark call. Stages: centre detection
(``detection``), denoising and stripe matching (``matching``), line-plane triangulation
(``triangulation``), isolating the animal and measuring it (``body``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from . import _kernels
from .background import near_planes
from .body import BodyParams, beside, isolate_with_margin, measure
from .calibration import Calibration
from .detection import (
    DetectionParams,
    check_image,
    clipped,
    detect_centres,
    detect_centres_and_faint,
    reliable,
    stripe_width_ratio,
)
from .ends import FLOOR_STOP_MM, MERGE_ROWS, end_points, faint_ends
from .errors import ImageError, ScanError
from .images import sample_bits
from .matching import Labels, MatchingParams, denoise, label_centres
from .orientation import stripe_axis, swap_xy, transpose_image
from .segments import smooth_along_stripes
from .threads import one_blas_thread
from .triangulation import cloud_points, ray_table, rays_and_cells

VIEWS = ("side", "top", "front", "back")
SMOOTH_REACH = 6  # rows (at 2048) each side of a centre whose line along its stripe gives its column
SMOOTH_JUMP_PX = 2.0  # px (at 3072) per row: a segment that goes on from another of its label within it
# A stripe's run whose centres lie a median of more than NOISY_RUN_PX off the line over SMOOTH_REACH rows is
# smoothed over NOISY_REACH rows (at 2048) instead: fur's centres scatter (0.15-0.24 px on the fur views'
# animal runs, 0.05-0.12 on clean ones), and there a longer line averages more of that scatter than it
# bends off a curving stripe. The five seeds' 40 views (bench/scan.py --seeds 4,8,9,10,12): RMS within 2 mm
# <= 0.5 mm 37 -> 40, >= 99.5 % within 2 mm 11 -> 12, fur views 0.18 points more within 2 mm and 0.019 mm
# less RMS, clean ones +0.004 mm; every view at 12 rows: clean RMS +0.039 mm (0.103 -> 0.149 on a top view)
NOISY_RUN_PX, NOISY_REACH = 0.13, 12
ANIMAL_MEDIAN_MIN = 200  # animal centres from which their median (contrast, stripe width) speaks for the animal


@dataclass(frozen=True)
class ScanParams:
    detection: DetectionParams = field(default_factory=DetectionParams)
    matching: MatchingParams = field(default_factory=MatchingParams)
    body: BodyParams = field(default_factory=BodyParams)
    faint_ends: bool = True  # per-stripe extents read each stripe's faint ends (``ends``)


@dataclass(frozen=True, eq=False)
class ScanResult:
    """A reconstructed scan.

    points, stripe, uv : the isolated animal: (N, 3) mm camera frame, (N,) stripe index, (N, 2) pixels
    scene_points, scene_stripe, scene_uv : every reconstructed point (floor and wall included)
    measurements : JSON-ready dict (point_count, body_length_mm, body_height_mm, stripes_detected, view, ...)
    timings_ms   : per stage
    """

    points: np.ndarray
    stripe: np.ndarray
    uv: np.ndarray
    scene_points: np.ndarray
    scene_stripe: np.ndarray
    scene_uv: np.ndarray
    measurements: dict
    timings_ms: dict


def scan(image: np.ndarray, calibration: Calibration, view: str = "side", ambient: np.ndarray | None = None,
         params: ScanParams | None = None) -> ScanResult:
    """Reconstruct the animal in one decoded stripe image (H, W) uint8/uint16.

    Raises ScanError/ImageError/StripeDetectionError with a message a technician can act on. The matrix
    products run on one BLAS thread (``threads.one_blas_thread``). A rig whose stripes run across the image
    (``calibration.stripe_axis`` "horizontal": the projector above or below the camera) is scanned in the
    transposed image (``orientation``); the result is in the camera's own frame and pixels either way.
    """
    with one_blas_thread():
        if calibration.stripe_axis == "horizontal" and not calibration.transposed:
            image = np.asarray(image)
            check_image(image, calibration.intrinsics.image_size)  # sizes named as the camera has them
            if ambient is not None and np.asarray(ambient).shape[:2] != image.shape[:2]:
                a = np.asarray(ambient)
                raise ImageError(f"ambient image is {a.shape[1]}x{a.shape[0]}, the stripe image "
                                 f"{image.shape[1]}x{image.shape[0]}")
            r = _scan(transpose_image(image), calibration.in_row_frame(), view,
                      None if ambient is None else transpose_image(ambient), params)
            return _swapped(r)
        return _scan(image, calibration, view, ambient, params)


def _swapped(r: ScanResult) -> ScanResult:
    """A result of the transposed frame in the camera's own: x and y of points, u and v of pixels, and the
    3-D points and axes kept with the measurements, swapped back."""
    meas = dict(r.measurements)
    for name in ("body_height", "body_width", "body_length"):
        if isinstance(meas.get(name), dict) and meas[name].get("points"):
            meas[name] = {**meas[name], "points": swap_xy(np.array(meas[name]["points"])).tolist()}
    box = meas.get("oriented_box_mm")
    if isinstance(box, dict):
        meas["oriented_box_mm"] = {**box, "axes": swap_xy(np.array(box["axes"])).tolist(),
                                   "centre": swap_xy(np.array(box["centre"])).tolist()}
    return ScanResult(swap_xy(r.points), r.stripe, r.uv[:, ::-1].copy(), swap_xy(r.scene_points), r.scene_stripe,
                      r.scene_uv[:, ::-1].copy(), meas, r.timings_ms)


def _scan(image: np.ndarray, calibration: Calibration, view: str, ambient: np.ndarray | None,
          params: ScanParams | None) -> ScanResult:
    params = params or ScanParams()
    if view not in VIEWS:
        raise ScanError(f"view must be one of {', '.join(VIEWS)}, got {view!r}")
    if calibration.planes is None or calibration.stripes == 0:
        raise ScanError("the calibration has no light planes (camera-only): calibrate with stripe images first")
    image = np.asarray(image)
    size = calibration.intrinsics.image_size
    check_image(image, (size[1], size[0]) if calibration.transposed else size)
    if params.detection.gamma is None and calibration.gamma != 1.0:  # the camera's own encoding
        params = replace(params, detection=replace(params.detection, gamma=calibration.gamma))
    t = {"start": time.perf_counter()}
    if params.faint_ends:
        centres, faint = detect_centres_and_faint(image, params.detection, ambient)
    else:  # the faint peaks are for the ends only
        centres, faint = detect_centres(image, params.detection, ambient), None
    t["detect"] = time.perf_counter()
    if len(centres) and params.matching.denoise:
        centres = centres.take(denoise(centres, image.shape[:2]))
    t["denoise"] = time.perf_counter()
    table = ray_table(calibration.intrinsics, calibration.transposed)
    looked_up: list = []  # the centres' rays and table cells, looked up while matching links the segments

    def rays() -> np.ndarray:
        looked_up.extend(rays_and_cells(centres.u, centres.v, table))
        return looked_up[0]

    labels = label_centres(centres, rays, calibration.planes, image.shape[:2], params.matching, view)
    cells = looked_up[1] if looked_up else rays_and_cells(centres.u, centres.v, table)[1]
    t["match"] = time.perf_counter()
    seg_ids = labels.segment if labels.segment is not None else np.arange(len(centres))
    by_segment = labels.segment_order if labels.segment is not None else None  # (segment_rows of seg_ids)
    smooth_u, ok = smooth_along_stripes(centres, seg_ids, labels.stripe,
                                        SMOOTH_JUMP_PX * max(image.shape[1] / 3072.0, 0.5),
                                        reach=max(2, round(SMOOTH_REACH * image.shape[0] / 2048)), order=by_segment,
                                        noisy=(NOISY_RUN_PX, max(2, round(NOISY_REACH * image.shape[0] / 2048))))
    labelled = labels.stripe >= 0
    # one-sided peaks and stripes widened at a grazing outline helped link and label their stripe, but
    # their position is off by 1.5-5 px: they stay out of the cloud
    ok &= reliable(centres, params.detection)
    # a tail tip's stripe merged with a floor stripe (``Labels.merged``): for the length only
    merged = np.isin(seg_ids, labels.merged) & labelled if labels.merged is not None else np.zeros(len(ok), bool)
    ok &= ~merged
    if ok.sum() < 50:
        n_found = int(np.bincount(np.bincount(centres.v)).argmax()) if len(centres) else 0
        hint = ("is this calibration for this rig and stripe count, and do all its stripes fall inside the "
                "image (the indices are read from rows that show every stripe)?" if n_found < calibration.stripes
                else "is this calibration for this rig and stripe count?")
        if stripe_axis(image) == "horizontal":  # in the frame scanned: the calibration's stripes run down it
            axis = "across" if calibration.transposed else "down"
            other = "down" if calibration.transposed else "across"
            hint = (f"the stripes in this image run {other} it, the calibration's {axis} it: was the image taken "
                    "with this rig (the camera turned, or the projector moved above or beside it)?")
        raise ScanError(f"no stripe could be matched to the calibration's {calibration.stripes} light planes "
                        f"(rows show about {n_found} stripes): {hint}")
    idx = np.flatnonzero(ok)
    pts = cloud_points(smooth_u, centres.u, centres.v, idx, labels.stripe, cells, table, calibration.planes)
    rows = centres.v.take(idx)
    uv = np.column_stack([smooth_u.take(idx), rows])
    stripe = labels.stripe.take(idx)
    t["triangulate"] = time.perf_counter()
    animal, margin = isolate_with_margin(pts, labels.background, params.body)
    if labels.tips is not None and labels.background is not None and animal.any():
        # a drooping tail's stripes lie farther apart than the cloud's connectivity reaches: its tip, placed
        # beside the animal's end stripe (``matching._tips``), stays with the animal where it is off the floor
        tip = np.flatnonzero(np.isin(seg_ids.take(idx), labels.tips))
        off = np.abs(pts[tip] @ labels.background[:, :3].T - labels.background[:, 3]).min(axis=1) > margin
        animal[tip[off]] = True
    on = np.flatnonzero(animal)  # (rows taken by index: a boolean mask over the scene's rows costs several times more)
    animal_pts, animal_stripe = pts.take(on, axis=0), stripe.take(on)
    ends = None
    if faint is not None and len(animal_pts):
        eu, ev, ek, ew = faint_ends(centres, labels.stripe, seg_ids, idx.take(on), idx, faint,
                                    params.matching.link_px * max(image.shape[1] / 3072.0, 0.5), image.shape[0],
                                    over_background=view == "top", order=by_segment)
        if len(eu):
            ep, keep = end_points(eu, ev, ek, ew, table, calibration.planes, labels.background,
                                  max(margin, FLOOR_STOP_MM), max(1, round(MERGE_ROWS * image.shape[0] / 2048)))
            ends = (ep[keep], ek[keep], ew[keep], ev[keep])
    wide, past = _left_out(centres, labelled & ~ok & ~merged, labels, animal_pts, animal_stripe, rows.take(on),
                           smooth_u, cells, table, calibration.planes, margin, params.body, past=view == "top")
    if merged.any() and len(animal_pts):
        wide = _with_merged(wide, np.flatnonzero(merged), centres, labels, smooth_u, cells, table, calibration.planes,
                            margin)
    meas = measure(animal_pts, animal_stripe, rows.take(on), view, params.body, ends, wide, past)
    # a stripe profile narrower than the optics make it on the animal is cut by an outline: its centroid is off
    # by a pixel or two, which a body's extremes hundreds of mm apart barely feel (the measurement reads them as
    # before) but a point picked on the cloud does: the cloud and the scene leave them out
    on_width = centres.width.take(idx.take(on))
    cut = clipped(centres, params.detection,
                  float(np.median(on_width)) if len(on_width) >= ANIMAL_MEDIAN_MIN else None).take(idx)
    if cut.any():
        keep = np.flatnonzero(~cut)
        pts, uv = pts.take(keep, axis=0), uv.take(keep, axis=0)
        stripe, animal, idx = stripe.take(keep), animal.take(keep), idx.take(keep)
        on = np.flatnonzero(animal)
        animal_pts, animal_stripe = pts.take(on, axis=0), stripe.take(on)
        meas["point_count"] = int(len(animal_pts))
    t["measure"] = time.perf_counter()
    stages = ["start", "detect", "denoise", "match", "triangulate", "measure"]
    timings = {s: round(1000 * (t[s] - t[p]), 2) for p, s in zip(stages, stages[1:], strict=False)}
    timings["total"] = round(1000 * (t["measure"] - t["start"]), 2)
    meas["centres"] = int(len(centres))
    meas["scene_point_count"] = int(len(pts))
    meas["unplaced_share"] = round(labels.unplaced / labels.pieces, 4) if labels.pieces else 0.0
    # how bright the stripes on the animal stand above their surroundings (8-bit gray levels; not read off
    # the few stray points left when the animal could not be placed)
    on_animal = idx.take(on)
    animal_uv = uv.take(on, axis=0)
    meas["animal_contrast"] = (round(float(np.median(centres.contrast.take(on_animal))), 1)
                               if len(on_animal) >= ANIMAL_MEDIAN_MIN else None)
    meas["saturated_share"] = saturated_share(image, animal_uv)
    meas["frame_edges"] = (frame_edges(animal_uv[:, ::-1], (image.shape[1], image.shape[0])) if calibration.transposed
                           else frame_edges(animal_uv, image.shape[:2]))
    # the stripes' median width at half height, against the width the detector's windows were set for
    meas["stripe_width_px"] = round(centres.median_width, 1) if len(centres) else None
    meas["pattern_edges"] = pattern_edges(animal_stripe, calibration.stripes, params.body.min_group)
    meas["warnings"] = _warnings(meas, labels, stripe_width_ratio(centres, image.shape[1]) if len(centres) else None)
    return ScanResult(animal_pts, animal_stripe, animal_uv, pts, stripe, uv, meas, timings)


def _left_out(centres, unreliable: np.ndarray, labels: Labels, animal_pts: np.ndarray, animal_stripe: np.ndarray,
              animal_rows: np.ndarray, smooth_u: np.ndarray, cells, table, planes: np.ndarray, margin: float,
              body: BodyParams, past: bool = False
              ) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray] | None, tuple[np.ndarray, np.ndarray] | None]:
    """Of the labelled centres the cloud left out, ``unreliable`` (M,) (``detection.reliable``, or off the median
    along their stripe), those that belong to the animal (``body.beside`` its cloud ``animal_pts``, stripes
    ``animal_stripe`` (N,), rows ``animal_rows`` (N,)): the points (W, 3) mm, stripes (W,) and rows (W,) of
    the stripes the cloud makes no group of (``measure``'s ``wide``), and with ``past`` the points (X, 3) mm and
    stripes (X,) of those beyond their stripe's rows in the cloud (``measure``'s ``past_ends``); None where
    there are none."""
    if len(animal_pts) == 0:
        return None, None
    xi = np.flatnonzero(unreliable)
    if len(xi) == 0:
        return None, None
    thin, beyond = _thin_and_past(labels.stripe[xi], centres.v[xi], animal_stripe, animal_rows, len(planes),
                                  body.min_group, past)
    xi, thin, beyond = xi[thin | beyond], thin[thin | beyond], beyond[thin | beyond]
    if len(xi) == 0:
        return None, None
    xp = cloud_points(smooth_u, centres.u, centres.v, xi, labels.stripe, cells, table, planes)
    on = beside(animal_pts, xp, labels.background, margin, body.cluster_mm)  # (point by point)
    ks, vs = labels.stripe[xi], centres.v[xi].astype(np.int64)
    a, b = thin & on, beyond & on
    return ((xp[a], ks[a], vs[a]) if thin.any() else None), ((xp[b], ks[b]) if b.any() else None)


def _thin_and_past(stripe: np.ndarray, rows: np.ndarray, animal_stripe: np.ndarray, animal_rows: np.ndarray, n: int,
                   min_group: int, past: bool) -> tuple[np.ndarray, np.ndarray]:
    """For left-out centres of stripes ``stripe`` (X,) in ``rows`` (X,): whether their stripe is one the cloud
    (stripes ``animal_stripe`` (N,), rows ``animal_rows`` (N,)) holds fewer than ``min_group`` points of, and
    (with ``past``) whether they lie beyond their stripe's first or last row in the cloud.

    Seen from above, the widest stripe crosses the flanks at grazing incidence and its last rows are wide or
    one-sided peaks, 1-3 px off (kept out of the cloud); the width without them ran 1-3 % short on the five
    seeds' top views, the truth's extremes lying there. Those inside the cloud's rows are not read: read too,
    they moved the extents' trim inward (1536 px renders' widths up to 0.8 points shorter)."""
    counts = np.bincount(animal_stripe, minlength=n)
    thin = counts[stripe] < min_group
    if not past or len(animal_stripe) == 0:
        return thin, np.zeros(len(stripe), bool)
    lo = np.full(n, np.iinfo(np.int64).max)
    hi = np.full(n, -1, np.int64)
    order = _kernels.stable_group_order(animal_stripe.astype(np.int64, copy=False), n)  # (np.minimum.at: 0.4 ms)
    ks, vs = animal_stripe[order], animal_rows[order].astype(np.int64, copy=False)
    starts = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1]])
    lo[ks[starts]] = np.minimum.reduceat(vs, starts)
    hi[ks[starts]] = np.maximum.reduceat(vs, starts)
    return thin, (rows < lo[stripe]) | (rows > hi[stripe])


def _with_merged(wide: tuple[np.ndarray, np.ndarray, np.ndarray] | None, xi: np.ndarray, centres, labels: Labels,
                 smooth_u: np.ndarray, cells, table, planes: np.ndarray, margin: float
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """``wide`` (``_wide_peaks``) with the points, stripes and rows of the centres ``xi`` (X,) of a tail tip's
    stripe merged with a floor stripe (``Labels.merged``) that lie more than ``margin`` mm off the floor and
    wall (as a tip's points join the cloud)."""
    xp = cloud_points(smooth_u, centres.u, centres.v, xi, labels.stripe, cells, table, planes)
    off = np.isfinite(xp).all(axis=1)
    if labels.background is not None:
        off &= ~near_planes(np.nan_to_num(xp), labels.background, margin)
    extra = (xp[off], labels.stripe[xi][off], centres.v[xi][off].astype(np.int64))
    if wide is None:
        return extra if len(extra[1]) else None
    return tuple(np.concatenate([a, b]) for a, b in zip(wide, extra, strict=True))  # type: ignore[return-value]


FRAME_MARGIN = 0.01  # share of the image's width (height) within which an animal point is at its edge


def frame_edges(uv: np.ndarray, shape: tuple[int, int], margin: float = FRAME_MARGIN) -> list[str]:
    """The picture's edges ("left", "right", "top", "bottom") that animal points uv (N, 2) px come within
    ``margin`` of the image's size (H, W) of: there the animal probably continues out of view. On the
    benches' renders the animals keep 17-55 % of the frame from every edge; the Stanford bunny's ears
    reach the top of its 1536 px side view."""
    if len(uv) == 0:
        return []
    h, w = shape
    mu, mv = max(4.0, margin * w), max(4.0, margin * h)
    u, v = uv[:, 0], uv[:, 1]
    near = {"left": u.min() < mu, "right": u.max() > w - 1 - mu, "top": v.min() < mv, "bottom": v.max() > h - 1 - mv}
    return [edge for edge, hit in near.items() if hit]


SATURATED = 0.05  # share of the animal's points on saturated pixels from which a scan is warned about


def pattern_edges(stripe: np.ndarray, n: int, min_group: int = 10) -> list[str]:
    """Which of the pattern's outermost stripes ("first": index 0, "last": n - 1) light the animal: stripe indices
    (K,) of its points, at least ``min_group`` of them on the stripe. There the animal may go on past the
    light, unmeasured: the paper's length runs between its outermost stripe groups, so it then spans the
    pattern's reach, not the animal (on the simulator's rig every view of the five-seed bench reaches one end or both)."""
    counts = np.bincount(stripe, minlength=n) if len(stripe) else np.zeros(n, np.int64)
    return [name for name, k in (("first", 0), ("last", n - 1)) if counts[k] >= min_group]


def saturated_share(image: np.ndarray, uv: np.ndarray) -> float | None:
    """The share of the points at pixels uv (N, 2) whose pixel in the frame (H, W) holds the largest value its
    samples can (255, or 2^bits - 1 of a 16-bit frame's ``sample_bits``): clipped stripe crests. None without
    points. On the simulator's five seeds' 40 views at 3072 px: at most 0.03 % as rendered, 0.9-44 % when
    overexposed 2.5x (under ``SATURATED`` only four clean side views, each placed right)."""
    if len(uv) == 0:
        return None
    top = 2 ** sample_bits(image) - 1
    px = np.rint(uv).astype(np.int64)
    h, w = image.shape[:2]
    u, v = np.clip(px[:, 0], 0, w - 1), np.clip(px[:, 1], 0, h - 1)
    return round(float(np.mean(image[v, u] >= top)), 4)


FEW_ANIMAL_POINTS, FEW_ANIMAL_SHARE = 300, 0.02  # an "animal" under both is stray points, not an animal
WIDE_STRIPES = 1.25  # a frame's median stripe width over the detector's reference above which a scan is warned about
FAINT_ANIMAL = 25.0  # gray levels: the animal's stripes' median contrast under which a scan is warned about


def _warnings(meas: dict, labels: Labels, stripe_ratio: float | None = None) -> list[str]:
    """What a technician should know before trusting the numbers. ``stripe_ratio`` : the frame's median stripe
    width over the width the detector was set for (``detection.stripe_width_ratio``)."""
    out = []
    if meas.get("view") in ("front", "back"):
        out.append(f"{meas['view']} views are not yet reliable: seen end-on, the head, chest and legs stand at "
                   "different depths and their stripe indices are often wrong (on the simulator's front and back "
                   "views from a fifth to nearly all of the animal's stripes), so the measurements below may be far "
                   "off: measure from the side or from above")
    if stripe_ratio is not None and stripe_ratio >= WIDE_STRIPES:
        out.append(f"the stripes are {stripe_ratio:.1f} times as wide as the scan is made for ({meas['stripe_width_px']:.0f} "
                   "px at half their height): wide stripes merge where a surface turns away and are cut by shadow "
                   "edges, so more of the cloud lies off the surface (on the simulator, stripes of twice the "
                   "light's width leave 92 % of a furred side view's points within 2 mm of it, against 99.6 %): "
                   "focus the projector on the animal or narrow its stripes")
    contrast = meas.get("animal_contrast")
    if contrast is not None and contrast < FAINT_ANIMAL:
        out.append(f"the stripes on the animal are faint (median {contrast:.0f} gray levels above their "
                   "surroundings; 30-70 is usual): a dark coat loses the stripes at its outline, so the body "
                   "measures short and, seen from above, its stripe indices may be off by a stripe or more, "
                   "which moves the whole cloud in depth: raise the exposure or the projector's brightness "
                   "and scan again")
    saturated = meas.get("saturated_share")
    if saturated is not None and saturated >= SATURATED:
        out.append(f"{100 * saturated:.0f} % of the animal's points lie on saturated pixels: clipped stripes are "
                   "flat-topped and wide, their centres less sure, and they join parts of the animal that should "
                   "stay apart (on the simulator, frames overexposed 2.5 times left 2 of 40 views with all or part "
                   "of the animal one stripe off, which moves it in depth; none as exposed): lower the exposure or the "
                   "projector's brightness and scan again")
    if labels.pieces and labels.unplaced > 0.3 * labels.pieces:
        out.append(f"{100 * labels.unplaced / labels.pieces:.0f} % of the stripe light on the animal could not be "
                   "matched to a light plane (nothing in the image fixed which stripe it was), so those parts "
                   "are missing from the cloud; this happens when the animal fills the stripe pattern to its "
                   "edge or casts no visible shadow: move it so that stripes fall on the floor or wall on both "
                   "sides of it")
    scene = meas.get("scene_point_count") or 0
    hardly_any = "point_count" in meas and meas["point_count"] < max(FEW_ANIMAL_POINTS, FEW_ANIMAL_SHARE * scene)
    if hardly_any:
        out.append(f"hardly anything was found off the floor and wall ({meas['point_count']} of {scene} "
                   "points): is the animal in the picture and inside the stripe pattern? The measurements "
                   "below describe those few points, not an animal")
    edges = meas.get("frame_edges") or []
    if edges:
        where = " and ".join(edges)
        out.append(f"the animal reaches the {where} edge of the picture: part of it is probably out of view, so "
                   "its length and height may be short: step the camera back or centre the animal and scan again")
    if labels.faint_shadow:
        out.append("the stripe indices of the animal were read from a faint shadow (most of the animal's shadow "
                   "is hidden from the camera), so they may be off by one stripe, which moves the whole cloud "
                   "in depth and changes its size: check one measurement against a tape, or move the projector "
                   "or the animal so that more of its shadow falls on floor the camera sees")
    if not hardly_any and (meas.get("body_length_mm") is None or meas.get("body_height_mm") is None):
        out.append("no body length or height: too few animal points were reconstructed")
    return out
