"""Stripe centres on the calibration board (section 2.2.2, Algorithm 1).

The paper's baseline: histogram equalisation + Otsu to estimate the stripe spacing, Otsu inside windows
one spacing wide, stripe boundaries -> midpoint per row, rows whose count differs from N dropped.
Our default adds two things the numbers favour (see docs/benchmarks.md): the room-light board image of
the same pose cancels ambient light and albedo (stripes are far dimmer on black squares), and the centre
is the intensity-weighted centroid of the run instead of the midpoint of its boundaries.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .errors import StripeDetectionError
from .images import sample_bits, to_float

METHODS = ("paper", "midpoint", "weighted", "gaussian")


@dataclass(frozen=True)
class StripeParams:
    """Knobs of the board stripe detector.

    method        : "paper" (equalise + windowed Otsu + midpoint), or on the albedo-normalised image
                    "midpoint", "weighted" (intensity-weighted centroid) or "gaussian" (3-point log-parabola)
    rel_threshold : a pixel belongs to a stripe above this fraction of the local maximum
    min_rows      : a pose counts when at least this many rows hold all N stripes ...
    min_row_frac  : ... and at least this fraction of the board's rows do; those rows fix the labels,
                    which then follow each stripe into rows where some stripes were missed
    """

    method: str = "weighted"
    rel_threshold: float = 0.5
    min_rows: int = 15
    min_row_frac: float = 0.03


@dataclass(frozen=True, eq=False)
class BoardStripes:
    """Stripe centres found on one board image.

    uv        : (M, 2) float64 pixel centres (u, v)
    stripe    : (M,) int32 stripe index, 0 = leftmost
    rows_used : rows holding all N stripes; rows_total: rows of the board region
    spacing_px: median distance between neighbouring stripes, pixels
    """

    uv: np.ndarray
    stripe: np.ndarray
    rows_used: int
    rows_total: int
    spacing_px: float


def board_region(corners: np.ndarray, pattern: tuple[int, int], shape: tuple[int, int],
                 board_img: np.ndarray | None = None) -> np.ndarray:
    """(H, W) bool mask of the plate around the chessboard: the checkered area plus the white margin
    that the board image shows bright, within two squares of the outer corners."""
    cols, rows = pattern
    grid = corners.reshape(rows, cols, 2)

    def hull(expand: float) -> np.ndarray:
        # extrapolate the corner grid outward by ``expand`` squares along its own axes
        c = grid
        dx = (c[:, -1] - c[:, 0]) / (cols - 1)
        dy = (c[-1, :] - c[0, :]) / (rows - 1)
        tl = c[0, 0] - expand * (dx[0] + dy[0])
        tr = c[0, -1] + expand * (dx[0] - dy[-1])
        br = c[-1, -1] + expand * (dx[-1] + dy[-1])
        bl = c[-1, 0] - expand * (dx[-1] - dy[0])
        m = np.zeros(shape, np.uint8)
        cv2.fillConvexPoly(m, np.round(np.array([tl, tr, br, bl]) * 16).astype(np.int32), 1, cv2.LINE_8, 4)
        return m.astype(bool)

    inner = hull(0.85)
    if board_img is None:
        return inner
    outer = hull(2.4)
    b = cv2.GaussianBlur(to_float(board_img), (0, 0), 2.0)
    vals = b[inner][::7]  # a strided sample is plenty for two order statistics
    white = np.median(vals[vals > np.percentile(vals, 60)])
    bright = b > 0.55 * white
    return inner | (outer & bright)


def estimate_spacing(img: np.ndarray, region: np.ndarray, n_stripes: int) -> float:
    """Stripe period in pixels from the mean power spectrum of the region's rows."""
    rows = np.nonzero(region.any(axis=1))[0]
    cols = np.nonzero(region.any(axis=0))[0]
    if len(rows) < 4 or len(cols) < 16:
        return 0.0
    sl = (slice(rows[0], rows[-1] + 1, 6), slice(cols[0], cols[-1] + 1))  # every 6th row suffices
    sub = img[sl] * region[sl]
    sub = sub - sub.mean(axis=1, keepdims=True)
    n = cv2.getOptimalDFTSize(sub.shape[1] * 2)
    power = (np.abs(np.fft.rfft(sub * np.hanning(sub.shape[1]), n=n, axis=1)) ** 2).mean(axis=0)
    freqs = np.fft.rfftfreq(n)
    width = len(cols)
    ok = (freqs > 1.0 / (2.0 * width / max(n_stripes, 1) + 1)) & (freqs < 1.0 / 4.0)
    if not ok.any():
        return 0.0
    return float(1.0 / freqs[ok][np.argmax(power[ok])])


def stripe_light(stripes_img: np.ndarray, spacing: float, board_img: np.ndarray | None = None,
                 region: np.ndarray | None = None) -> np.ndarray:
    """Stripe light with room light removed.

    With the room-light board image of the same pose, room light is cancelled by subtracting it scaled to
    the stripe image's exposure; a horizontal top-hat narrower than the stripe period removes the rest.
    (The top-hat alone leaves a residue wherever a square edge sits between two stripes.)
    returns : (H, W) float32 gray levels above the local background
    """
    # smoothing along the (nearly vertical) stripes averages noise without moving their centres
    s = cv2.GaussianBlur(to_float(stripes_img), (0, 0), sigmaX=0.6, sigmaY=2.0)
    if board_img is not None:
        b = cv2.GaussianBlur(to_float(board_img), (0, 0), sigmaX=0.6, sigmaY=2.0)
        s = s - room_light_ratio(s, b, region) * b
    k = max(3, int(round(spacing * 0.8)) | 1)
    background = cv2.morphologyEx(s, cv2.MORPH_OPEN, np.ones((1, k), np.uint8))
    return s - background


def room_light_ratio(stripes: np.ndarray, board: np.ndarray, region: np.ndarray | None) -> float:
    """How much of the board image's room light is in the stripe image: a low percentile of their ratio
    on bright pixels (stripes cover well under half of the plate, so it falls between stripes)."""
    mask = board > max(float(np.percentile(board[::4, ::4], 75)) * 0.5, 4.0)
    if region is not None:
        mask &= region
    if mask.sum() < 100:
        return 0.0
    return float(max(np.percentile((stripes[mask] / board[mask])[::5], 20), 0.0))


def normalise_albedo(light: np.ndarray, board_img: np.ndarray) -> np.ndarray:
    """Divide stripe light by the room-light image of the same pose, cancelling albedo (black squares).

    returns : (H, W) float32, comparable across square colours
    """
    b = cv2.GaussianBlur(to_float(board_img), (0, 0), sigmaX=0.6, sigmaY=2.0)
    floor = max(float(np.percentile(b[::4, ::4], 99)) * 0.02, 2.0)
    return light / np.maximum(b, floor)


def _runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Horizontal runs of True: row, first column, one-past-last column, each (R,) int."""
    h, w = mask.shape
    padded = np.zeros((h, w + 2), np.int8)
    padded[:, 1:-1] = mask
    d = np.diff(padded, axis=1)
    r0, c0 = np.nonzero(d == 1)
    r1, c1 = np.nonzero(d == -1)
    return r0, c0, c1  # both are in row-major order, so starts and ends pair up


def _centres(weight: np.ndarray, rows: np.ndarray, c0: np.ndarray, c1: np.ndarray, method: str) -> np.ndarray:
    """Sub-pixel centre of each run: midpoint of its boundaries, weighted centroid or Gaussian peak."""
    if method in ("paper", "midpoint"):
        return (c0 + c1 - 1) / 2.0
    w = np.maximum(weight, 0).astype(np.float64)
    if method == "weighted":
        m0, m1 = run_moments(w, rows, c0, c1)
        return np.where(m0 > 0, m1 / np.maximum(m0, 1e-12), (c0 + c1 - 1) / 2.0)
    # gaussian: log-parabola through the run's maximum and its neighbours
    seg_max = _run_argmax(w, rows, c0, c1)
    left = np.log(np.maximum(w[rows, np.maximum(seg_max - 1, 0)], 1e-6))
    mid = np.log(np.maximum(w[rows, seg_max], 1e-6))
    right = np.log(np.maximum(w[rows, np.minimum(seg_max + 1, w.shape[1] - 1)], 1e-6))
    denom = left - 2 * mid + right
    off = np.where(denom < 0, 0.5 * (left - right) / np.where(denom < 0, denom, -1), 0.0)
    return seg_max + np.clip(off, -1, 1)


def run_moments(w: np.ndarray, rows: np.ndarray, c0: np.ndarray, c1: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """Zeroth and first moments (sum of w, sum of w * column) of each run [c0, c1) in row ``rows``.

    w : (H, W) float weights; runs must be in row-major order and not overlap. Uses np.add.reduceat on the
    flattened image, so the cost is proportional to the image, with no Python loop over runs.
    """
    width = w.shape[1]
    flat = np.append(w.ravel(), 0.0)
    cols = np.append(np.tile(np.arange(width, dtype=np.float64), w.shape[0]), 0.0)
    bounds = np.empty(2 * len(rows), np.int64)
    bounds[0::2] = rows * width + c0
    bounds[1::2] = rows * width + c1
    if len(bounds) == 0:
        return np.zeros(0), np.zeros(0)
    m0 = np.add.reduceat(flat, bounds)[0::2]
    m1 = np.add.reduceat(flat * cols, bounds)[0::2]
    return m0, m1


def _run_argmax(w: np.ndarray, rows: np.ndarray, c0: np.ndarray, c1: np.ndarray) -> np.ndarray:
    lengths = c1 - c0
    idx = np.repeat(np.arange(len(rows)), lengths)
    cols = np.arange(lengths.sum()) - np.repeat(np.cumsum(lengths) - lengths, lengths) + np.repeat(c0, lengths)
    vals = w[rows[idx], cols]
    order = np.lexsort((-vals, idx))
    first = np.ones(len(order), bool)
    first[1:] = idx[order][1:] != idx[order][:-1]
    return cols[order][first]


def _binary(img: np.ndarray, light: np.ndarray, region: np.ndarray, spacing: float, params: StripeParams,
            stripes_img: np.ndarray) -> np.ndarray:
    if params.method == "paper":
        return _paper_binary(stripes_img, region, spacing)
    k = max(3, int(round(spacing)) | 1)
    local_max = cv2.dilate(img, np.ones((1, k), np.uint8))
    # the signal must stand clear of the sensor noise in absolute gray levels, wherever the albedo
    noise = noise_level(light, region)
    strong = cv2.dilate(light, np.ones((1, k), np.uint8)) > max(5.0 * noise, 1.0)
    binary = (region & strong & (img > params.rel_threshold * local_max)).astype(np.uint8)
    return cv2.morphologyEx(binary, cv2.MORPH_CLOSE, np.ones((1, 3), np.uint8)).astype(bool)


def noise_level(img: np.ndarray, region: np.ndarray) -> float:
    """Robust noise sigma from vertical differences 8 rows apart (beyond the smoothing), which cancel
    near-vertical stripes and edges."""
    d = (img[8::3] - img[:-8:3])[region[8::3] & region[:-8:3]]
    if d.size == 0:
        return 0.0
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / np.sqrt(2.0))


def _paper_binary(stripes_img: np.ndarray, region: np.ndarray, spacing: float) -> np.ndarray:
    """Histogram equalisation, then Otsu inside windows two stripe spacings wide along each row (Algorithm 1).

    Each window holds about two stripes and their gaps, so its own Otsu threshold adapts to the local
    brightness; a window that straddles a square edge still splits on albedo, the weakness our default fixes.
    """
    g = cv2.equalizeHist(np.clip(to_float(stripes_img), 0, 255).astype(np.uint8)).astype(np.float32)
    h, w = g.shape
    step = max(int(round(2 * spacing)), 8)
    pad = (-w) % step
    win = np.pad(g, ((0, 0), (0, pad)), mode="edge").reshape(h, -1, step)
    t = _otsu_rows(win.reshape(-1, step)).reshape(h, -1, 1)
    out = (win > t).reshape(h, -1)[:, :w]
    return out & region


def _otsu_rows(values: np.ndarray) -> np.ndarray:
    """Otsu threshold of every row of ``values`` (R, n), vectorised: (R,) thresholds."""
    v = np.sort(values, axis=1).astype(np.float64)
    n = v.shape[1]
    c = np.cumsum(v, axis=1)
    k = np.arange(1, n, dtype=np.float64)
    m0 = c[:, :-1] / k
    m1 = (c[:, -1:] - c[:, :-1]) / (n - k)
    between = k * (n - k) * (m0 - m1) ** 2
    best = np.argmax(between, axis=1)
    rows = np.arange(len(v))
    return (v[rows, best] + v[rows, best + 1]) / 2


def detect_board_stripes(stripes_img: np.ndarray, board_img: np.ndarray | None, corners: np.ndarray,
                         pattern: tuple[int, int], n_stripes: int, params: StripeParams = StripeParams(),
                         name: str = "stripes image") -> BoardStripes:
    """Centres of the N stripes on the board, labelled 0..N-1 left to right, in rows that hold all N.

    Raises StripeDetectionError naming ``name`` when no stripes are seen or too few rows hold all N.
    """
    if params.method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {params.method!r}")
    # both images on one scale, that of the stripe image's samples (12-bit samples in a 16-bit file scaled
    # by 1/257 kept 16 gray levels: a tenth of the rows showed every stripe)
    bits = sample_bits(stripes_img)
    stripes_img = to_float(stripes_img, bits)
    board_img = None if board_img is None else to_float(board_img, bits)
    region = board_region(corners, pattern, stripes_img.shape, board_img)
    ys, xs = np.nonzero(region.any(axis=1))[0], np.nonzero(region.any(axis=0))[0]
    if len(ys) == 0:
        raise StripeDetectionError(f"{name}: the board lies outside the image")
    # all the work happens inside the plate's bounding box (a third to a half of the frame)
    y0, x0 = int(ys[0]), int(xs[0])
    crop = (slice(y0, int(ys[-1]) + 1), slice(x0, int(xs[-1]) + 1))
    found = _detect_in(stripes_img[crop], None if board_img is None else board_img[crop], region[crop],
                       n_stripes, params, name)
    return BoardStripes(found.uv + [x0, y0], found.stripe, found.rows_used, found.rows_total, found.spacing_px)


def _detect_in(stripes_img: np.ndarray, board_img: np.ndarray | None, region: np.ndarray, n_stripes: int,
               params: StripeParams, name: str) -> BoardStripes:
    stripes_img = to_float(stripes_img) if params.method != "paper" else stripes_img
    board_img = None if board_img is None else to_float(board_img)
    spacing = estimate_spacing(stripe_light(stripes_img, 12.0), region, n_stripes)
    if spacing <= 0:
        raise StripeDetectionError(f"{name}: no stripe pattern found on the board")
    if params.method == "paper" or board_img is None:
        light = img = stripe_light(stripes_img, spacing)
    else:
        light = stripe_light(stripes_img, spacing, board_img, region)
        img = normalise_albedo(light, board_img)
    binary = _binary(img, light, region, spacing, params, stripes_img)
    # runs must not touch the region's border (a stripe cut by it has a biased centre)
    binary &= cv2.erode(region.astype(np.uint8), np.ones((1, 3), np.uint8)).astype(bool)
    rows, c0, c1 = _runs(binary)
    long_enough = (c1 - c0) >= 2
    rows, c0, c1 = rows[long_enough], c0[long_enough], c1[long_enough]
    u = _centres(img, rows, c0, c1, params.method)
    counts = np.bincount(rows, minlength=img.shape[0])
    full = counts[rows] == n_stripes
    seed_rows, seed_u, seed_k = _regular_rows(rows[full], u[full], n_stripes, spacing)
    region_rows = int(region.any(axis=1).sum())
    used = len(np.unique(seed_rows))
    if used == 0 and counts.max(initial=0) == 0:
        raise StripeDetectionError(f"{name}: no stripes found on the board")
    if used < max(params.min_rows, params.min_row_frac * region_rows):
        most = int(np.bincount(counts).argmax()) if counts.any() else 0
        raise StripeDetectionError(
            f"{name}: only {used} of {region_rows} board rows show all {n_stripes} stripes "
            f"(most rows show {most}): part of the pattern misses the plate, or the stripe count is wrong")
    if params.method == "paper":
        rows, u, k = seed_rows, seed_u, seed_k
    else:
        rows, u, k = _extend_labels(rows, u, seed_rows, seed_u, seed_k, n_stripes, spacing)
    return BoardStripes(np.column_stack([u, rows.astype(np.float64)]), k, used, region_rows, spacing)


def _extend_labels(rows, u, seed_rows, seed_u, seed_k, n: int, spacing: float):
    """Label centres in rows that miss some stripes (dim stripes on black squares, noise) by following
    each stripe from the complete rows: a stripe on the flat board is a smooth curve u_k(v), fitted and
    re-fitted as labelled centres accumulate; a centre joins stripe k when it lies within a fifth of the
    spacing of the prediction and no other centre of its row claims k."""
    lab_rows, lab_u, lab_k = seed_rows, seed_u, seed_k
    v = rows.astype(np.float64)
    vmid = float(np.median(v)) if len(v) else 0.0
    tol = 0.2 * spacing
    for _ in range(3):
        span = np.ptp(lab_rows) if len(lab_rows) else 0
        deg = 2 if span > 200 else 1 if span > 10 else 0
        coef = np.zeros((n, 3))
        for kk in range(n):
            sel = lab_k == kk
            if sel.sum() > deg:
                coef[kk, 3 - deg - 1:] = np.polyfit(lab_rows[sel] - vmid, lab_u[sel], deg)
            else:
                coef[kk, 2] = np.nan
        dv = v - vmid
        pred = coef[:, 0][None] * dv[:, None] ** 2 + coef[:, 1][None] * dv[:, None] + coef[:, 2][None]
        dist = np.abs(pred - u[:, None])
        best = np.nanargmin(np.where(np.isnan(dist), np.inf, dist), axis=1)
        ok = dist[np.arange(len(u)), best] < tol
        # one centre per stripe per row: drop both when two claim the same stripe
        key = rows.astype(np.int64) * (n + 1) + best
        uniq, cnt = np.unique(key[ok], return_counts=True)
        ok &= ~np.isin(key, uniq[cnt > 1])
        lab_rows, lab_u, lab_k = rows[ok], u[ok], best[ok].astype(np.int32)
    return lab_rows, lab_u, lab_k


def _regular_rows(rows: np.ndarray, u: np.ndarray, n: int, spacing: float):
    """Keep rows whose N centres are evenly spread (no missing stripe replaced by a spurious one)."""
    if len(rows) == 0:
        return rows, u, np.zeros(0, np.int32)
    order = np.lexsort((u, rows))
    rows, u = rows[order], u[order]
    grid = u.reshape(-1, n)
    gaps = np.diff(grid, axis=1)
    med = np.median(gaps, axis=1, keepdims=True)
    ok = ((gaps > 0.55 * med) & (gaps < 1.6 * med)).all(axis=1) & (med[:, 0] > 0.4 * spacing)
    keep = np.repeat(ok, n)
    k = np.tile(np.arange(n, dtype=np.int32), len(ok))
    return rows[keep], u[keep], k[keep]
