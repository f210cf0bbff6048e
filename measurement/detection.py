"""Stripe centres in an animal image (section 2.3.1): local-background binarisation, one centre per
stripe crossing per row, sub-pixel refinement. Vectorised: OpenCV filters over the frame, NumPy only
over the sparse candidates.

The paper's Algorithm 2 finds left and right stripe boundaries with two sliding windows and takes their
midpoint; ``measurement.paper`` keeps it as the measured baseline. Here the same idea (a stripe is a run
brighter than its surroundings by a margin) is computed with a local minimum filter as the background
(one global threshold cannot serve dark fur and a bright wall at once) and the centre is the
intensity-weighted centroid of the run's upper half, which the numbers favour (docs/benchmarks.md).
Weak peaks count when they continue a strong stripe (hysteresis), so a stripe's faint grazing ends are
kept; ``reliable`` flags centres whose position should not reach the point cloud.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from functools import cached_property

import cv2
import numpy as np

from . import _kernels
from .errors import ImageError, StripeDetectionError
from .images import sample_bits
from .threads import band_workers


@dataclass(frozen=True)
class DetectionParams:
    """Knobs of the centre detector (pixels are at 3072 px image width and scale with the image).

    background_px : width of the minimum filter giving the local background (about half a stripe period)
    peak_px       : half-width of the non-maximum suppression along the row
    min_contrast  : a centre stands at least this many gray levels above its local background, and at least
                    noise_k times the noise left in the smoothed image the peaks are found in (the sensor's
                    ``noise_sigma`` times ``smoothing_gain``): a noisy sensor must not turn its noise into
                    stripes. The smoothing scales with the image, so at 3072 px it leaves half the noise it
                    leaves at 1536 px; a threshold on the raw noise was twice as strict there and lost the
                    faint ends of every stripe (noisy 3072 px top views placed one low, heights -10 %)
    weak_contrast, link_px : hysteresis: a weaker peak (above weak_contrast, two-sided: see min_flank) is a
                    centre too when a chain of such peaks, each within link_px columns of one in the next
                    or next-but-one row, reaches a centre above min_contrast. Recovers the faint ends of a
                    stripe where it grazes the back, a foot or the flank seen from above (4.0 does; 0, the
                    default for now, turns it off: it changes the centres the labelling sees, and the
                    animal's absolute stripe offset still flips with such changes on some views)
    sigma_x, sigma_y : smoothing across and along the (near-vertical) stripes before peak finding
    min_flank, flank_ratio : a reliable centre falls on each side, within half the background window, by at
                    least max(min_flank, flank_ratio * contrast) gray levels (a stripe is a peak; the
                    rising side of an albedo or shadow edge is not)
    max_width     : a reliable centre is at most this many times the image's median stripe width (a stripe
                    widened by a grazing surface has its centroid off the plane's image)
    min_width     : a centre narrower than this share of the animal's median stripe width (``clipped``) has
                    part of its profile hidden, and its centroid moved with it: it stays out of the cloud (0: none)
    faint_contrast, faint_k : ``detect_centres_and_faint`` also lists the faint peaks, above
                    max(faint_contrast, faint_k x the smoothed noise) but not above min_contrast, two-sided
                    (see min_flank), apart from the centres: where a stripe grazes the outline (the flank seen
                    from above, the back of a dark coat) its last rows fade below min_contrast, and the
                    measurement's per-stripe extents read them (``ends``); the labelling never sees them
    shade_px, shade_floor : ``shaded_centre``'s reach each side of the peak (pixels) and the gray levels
                    added to the flanks' line before dividing by it (the position of the points); shade_px
                    0: the points at the plain centroid ``u``
    follow_exposure : lower min_contrast, min_flank, faint_contrast, weak_contrast and shade_floor in
                    proportion for a frame whose stripes stand dimmer than those they were set for
                    (``exposure_scale``); False: the levels as given
    gamma         : the camera's display gamma (None: the calibration's, ``Calibration.gamma``; 1.0: linear):
                    a frame written as (light)^(1 / gamma) is linearised, 255 (v / 255)^gamma on the gray
                    image, before anything else. Every threshold, the flank test and the centroid assume that
                    light adds: on the five seeds' renders encoded with gamma 2.2 (as an sRGB renderer or
                    camera writes) two of 40 views were placed a stripe off and four fur views fell under
                    99.5 % of labels right; linearised, every figure is the linear frame's
    """

    background_px: int = 17
    peak_px: int = 4
    min_contrast: float = 8.0
    noise_k: float = 5.0
    weak_contrast: float = 0.0
    link_px: float = 2.0
    sigma_x: float = 1.0
    sigma_y: float = 1.5
    min_flank: float = 4.0
    flank_ratio: float = 0.5
    max_width: float = 1.5
    min_width: float = 0.65
    faint_contrast: float = 3.0
    faint_k: float = 2.5
    gamma: float | None = None
    shade_px: int = 13
    shade_floor: float = 4.0
    follow_exposure: bool = True


@dataclass(frozen=True, eq=False)
class Centres:
    """Stripe centres found in one image.

    u       : (M,) float64 sub-pixel column, pixels
    v       : (M,) int32 row, pixels
    contrast: (M,) float32 peak height above the local background, gray levels
    width   : (M,) float32 width of the stripe at half its height, pixels
    flank   : (M,) float32 peak height above the higher of the two side minima (its weaker flank), gray
              levels; None when not measured (every centre then counts as reliable)
    shaded  : (M,) float64 sub-pixel column with the surface's shading under the stripe divided out
              (``shaded_centre``), pixels: where the points go; ``u`` is what the stripes are linked and
              labelled by. None when not measured (``u`` serves for both)
    exposure: the factor (at most 1) the detector's gray-level thresholds were scaled by for a dim frame
              (``exposure_scale``); ``reliable`` scales ``min_flank`` by it too
    """

    u: np.ndarray
    v: np.ndarray
    contrast: np.ndarray
    width: np.ndarray
    flank: np.ndarray | None = None
    shaded: np.ndarray | None = None
    exposure: float = 1.0

    def __len__(self) -> int:
        return len(self.u)

    @cached_property
    def median_width(self) -> float:
        """np.median of ``width`` (pixels), taken once: the reliability test reads it in matching and again
        in the pipeline. (The arrays are not to be changed in place after it is read.)"""
        return _median_width(self.width)

    @property
    def position(self) -> np.ndarray:
        """(M,) float64 column to triangulate, pixels: ``shaded`` where measured, else ``u``."""
        return self.u if self.shaded is None else self.shaded

    def take(self, mask: np.ndarray) -> Centres:
        flank = None if self.flank is None else self.flank[mask]
        shaded = None if self.shaded is None else self.shaded[mask]
        return Centres(self.u[mask], self.v[mask], self.contrast[mask], self.width[mask], flank, shaded, self.exposure)


def _median_width(width: np.ndarray) -> float:
    """np.median of widths (M,) float32: from their counts where they are small whole numbers (detection's
    run lengths are), the mean of the two middle ones exactly as np.median forms it; else np.median."""
    if width.dtype == np.float32 and len(width) and 0 <= width.min() and width.max() < 4096:
        whole = width.astype(np.int32)
        if (whole == width).all():
            below = np.cumsum(np.bincount(whole))
            n = len(width)
            middle = np.searchsorted(below, [(n - 1) // 2, n // 2], side="right")
            return float(middle.sum()) / 2
    return float(np.median(width))


def to_gray8(image: np.ndarray, name: str = "image", bits: int | None = None) -> np.ndarray:
    """(H, W), (H, W, 1), (H, W, 3) or (H, W, 4) uint8/uint16 -> (H, W) uint8; ImageError, naming the image
    as ``name``, for any other shape or type. A 16-bit frame is scaled from the ``bits`` its samples use
    (``sample_bits`` of the frame itself by default) to 0-255: a full 16-bit frame by 1/257, 12-bit samples
    by 1/16.06 (scaled by 1/257 they kept 16 gray levels and no stripe was found)."""
    if image.dtype not in (np.uint8, np.uint16):
        raise ImageError(f"{name} must be uint8 or uint16, got {image.dtype}")
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    elif image.ndim == 3 and image.shape[2] in (3, 4):
        image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY if image.shape[2] == 3 else cv2.COLOR_BGRA2GRAY)
    if image.ndim != 2:
        raise ImageError(f"{name} must be (H, W) gray or (H, W, 3) colour, got shape {image.shape}")
    if image.dtype == np.uint16:
        bits = sample_bits(image) if bits is None else bits
        return cv2.convertScaleAbs(image, alpha=255.0 / float(2**bits - 1))
    return image


def linearised(g: np.ndarray, gamma: float | None) -> np.ndarray:
    """The gray image g (H, W) uint8 of a camera writing (light)^(1 / gamma), as linear light: 255 (g / 255)^gamma
    rounded, by one table lookup (g itself for gamma None or 1)."""
    if gamma is None or gamma == 1.0:
        return g
    table = np.rint(255.0 * (np.arange(256) / 255.0) ** float(gamma)).astype(np.uint8)
    return cv2.LUT(g, table)


def _scaled(px: float, width: int, odd: bool = False) -> int:
    n = max(1, int(round(px * width / 3072.0)))
    return n | 1 if odd else n


def detect_centres(image: np.ndarray, params: DetectionParams = DetectionParams(),
                   ambient: np.ndarray | None = None) -> Centres:
    """Centres of all stripe crossings in an image.

    image   : (H, W) uint8/uint16 (colour is converted)
    ambient : optional image of the same view with the projector off; subtracting it cancels room light
              and, with the stripe image, most of the albedo's texture
    """
    return _detect(image, params, ambient, faint=False)[0]


def detect_centres_and_faint(image: np.ndarray, params: DetectionParams = DetectionParams(),
                             ambient: np.ndarray | None = None) -> tuple[Centres, Centres]:
    """``detect_centres``' centres (the same to the bit) and, apart from them, the faint peaks
    (``DetectionParams.faint_contrast``) found in the same pass."""
    return _detect(image, params, ambient, faint=True)


def _detect(image: np.ndarray, params: DetectionParams, ambient: np.ndarray | None, faint: bool
            ) -> tuple[Centres, Centres]:
    bits = sample_bits(np.asarray(image))  # the ambient image is scaled as the stripe image is
    g = linearised(to_gray8(image, bits=bits), params.gamma)
    if ambient is not None:
        a = linearised(to_gray8(ambient, "ambient image", bits=bits), params.gamma)
        if a.shape != g.shape:
            raise ImageError(f"ambient image is {a.shape[1]}x{a.shape[0]}, the stripe image {g.shape[1]}x{g.shape[0]}")
        # stripes only add light: an ambient image brighter than the stripe image beyond a flicker's 2 % is
        # the other one of the pair
        lit, dark = float(g[::4, ::4].mean()), float(a[::4, ::4].mean())
        if dark > 1.02 * lit + 1.0:
            raise ImageError("the ambient image is brighter than the stripe image: are the two swapped? (the "
                             "ambient image is the same view with the projector off)")
        g = subtract_ambient(g, a)
        _, lo, hi, _ = _kernels.sample_levels(g, 4, 250)
        if hi - lo < 10:
            raise StripeDetectionError("nothing is left of the stripe image once the ambient image is subtracted: "
                                       "the ambient image is as bright as the stripe image (are the two swapped, "
                                       "or was the projector on for both?)")
    noise = noise_sigma(g) * smoothing_gain(params, g.shape[1])
    exposure = exposure_scale(g, params, noise) if params.follow_exposure else 1.0
    if exposure < 1.0:
        params = scaled_thresholds(params, exposure)
    params = replace(params, min_contrast=max(params.min_contrast, params.noise_k * noise))
    hysteresis = 0 < params.weak_contrast < params.min_contrast
    faint_low = max(params.faint_contrast, params.faint_k * noise) if faint and not hysteresis else 0.0
    if faint_low >= params.min_contrast:
        faint_low = 0.0
    # the frame is filtered in bands of rows (each with enough rows above and below for the vertical blur),
    # so the filters' images stay in cache, and the bands share the cores (OpenCV and NumPy release the
    # GIL): the same centres to the bit
    h, w = g.shape
    # (the flat top of a wide stripe is a run of equal gray levels that a one-level dip can cut in two:
    # both halves pass the non-maximum suppression and refine to the same centroid; the bands keep one)
    if faint_low > 0:  # split into centres and faint peaks band by band, on the bands' threads
        found = _split_bands(g, params, faint_low, exposure)
        wider = _shade_for_width(params, found[0], w)
        return found if wider is None else _split_bands(g, wider, faint_low, exposure)
    x, y, u, contrast, width, flank, shaded = _all_bands(g, params, faint_low)
    wider = _shade_for_width(params, Centres(u, y, contrast, width), w)
    if wider is not None:
        params = wider
        x, y, u, contrast, width, flank, shaded = _all_bands(g, params, faint_low)
    c = Centres(u, y.astype(np.int32), contrast, width, flank, shaded, exposure)
    none = c.take(np.zeros(len(c), bool))
    if not hysteresis:
        return c, none
    strong = c.contrast > params.min_contrast
    weak = ~strong & (flank >= params.flank_ratio * c.contrast)
    return c.take(strong | _linked(x, y, w, strong, weak, params.link_px * w / 3072.0)), none


SHADE_WIDTH_PX = 8.0  # the stripe width (at half height, 3072 px) ``DetectionParams.shade_px`` was set for
SHADE_WIDER = 1.2  # a frame whose median stripe is this much wider has its shaded centres taken again


def stripe_width_ratio(c: Centres, w: int) -> float:
    """The median width (``Centres.median_width``) of the stripes of a frame ``w`` px wide over
    ``SHADE_WIDTH_PX`` scaled to that frame: 1 at the width the detector's windows were set for."""
    return c.median_width / (SHADE_WIDTH_PX * max(w / 3072.0, 0.5))


def _shade_for_width(params: DetectionParams, c: Centres, w: int) -> DetectionParams | None:
    """``params`` with ``shade_px`` times the square of the frame's median stripe width (``Centres.median_width``,
    pixels) over ``SHADE_WIDTH_PX`` (scaled to a frame ``w`` px wide) where that ratio exceeds ``SHADE_WIDER``,
    else None. The shaded centroid looks for the room light's level on each side of the stripe within
    ``shade_px``; under wider stripes (another projector or focus: the optics bench's twice the light's sigma
    reads 11 px against the reference's 8 at 3072 px; the half-height width grows more slowly than the
    tails, hence the square) that reach ended on the stripe's own flanks, and the line through them cut the
    profile off-centre: 85.5 % of the 40-stripe fur side view's points within 2 mm, 91.5 % at the widened
    reach (99.6 % at the reference width, which is left as it was: every frame up to the threshold keeps the
    fixed reach to the bit)."""
    if params.shade_px <= 0 or len(c) == 0:
        return None
    ratio = stripe_width_ratio(c, w)
    if ratio <= SHADE_WIDER:
        return None
    return replace(params, shade_px=int(round(params.shade_px * ratio ** 2)))


AMBIENT_PEDESTAL = 32  # gray levels added back after subtracting the ambient image


def subtract_ambient(g: np.ndarray, a: np.ndarray) -> np.ndarray:
    """The stripe image g (H, W) uint8 minus the ambient image a (H, W) uint8, plus ``AMBIENT_PEDESTAL``
    (saturating): the stripes over a flat background near the pedestal. Where room light is dim (a dark floor,
    dark fur) the two images' noise puts half the background below the ambient, and a plain saturating
    difference cut it to 0: the local background then read 0 instead of the noise's low side, a faint stripe's
    contrast shrank by that much, and the noise estimate halved. On a 3072 px top view over a floor of albedo
    0.12 no row then showed all the stripes and the scan failed, while the stripe image alone scanned."""
    return cv2.addWeighted(g, 1.0, a, -1.0, float(AMBIENT_PEDESTAL))


_BAND_ROWS = 256
_WORKERS = min(4, os.cpu_count() or 1)


def _all_bands(g: np.ndarray, params: DetectionParams, faint: float = 0.0) -> tuple[np.ndarray, ...]:
    """x, y, u, contrast, width, flank, shaded of every candidate in the gray image g (H, W), in raster order
    (``_band_centres``)."""
    h = g.shape[0]
    found = list(band_workers(_WORKERS).map(lambda a: _band_centres(g, a, min(a + _BAND_ROWS, h), params, faint),
                                            range(0, h, _BAND_ROWS)))
    return tuple(np.concatenate(z) for z in zip(*found, strict=True))


def _split_bands(g: np.ndarray, params: DetectionParams, faint: float, exposure: float = 1.0
                 ) -> tuple[Centres, Centres]:
    """The centres (contrast above min_contrast) and the two-sided faint peaks (above ``faint``, not above
    min_contrast, ``flank_ratio`` of their contrast on the weaker side) of the gray image g (H, W), each in
    raster order: each band of rows (``_band_centres``) is split on its own thread."""

    def band(a: int) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
        _, y, u, contrast, width, flank, shaded = _band_centres(g, a, min(a + _BAND_ROWS, g.shape[0]), params, faint)
        strong = contrast > params.min_contrast
        weak = ~strong & (flank >= params.flank_ratio * contrast)
        y = y.astype(np.int32)
        fields = (u, y, contrast, width, flank, shaded)
        return tuple(z[strong] for z in fields), tuple(z[weak] for z in fields)

    def joined(parts: list[tuple[np.ndarray, ...]]) -> Centres:
        u, v, contrast, width, flank, shaded = (np.concatenate(z) for z in zip(*parts, strict=True))
        return Centres(u, v, contrast, width, flank, shaded, exposure)

    found = list(band_workers(_WORKERS).map(band, range(0, g.shape[0], _BAND_ROWS)))
    return joined([f[0] for f in found]), joined([f[1] for f in found])


STRIPE_LEVEL = 33.0  # gray levels: the stripes' level (``stripe_level``) the thresholds are set for
EXPOSURE_NOISE_K = 10.0  # the lowered min_contrast stays at least this many smoothed noise sigmas


def stripe_level(g: np.ndarray, params: DetectionParams, noise: float, step: int = 16) -> float:
    """How bright the stripes of the gray image g (H, W) uint8 stand above their local background, gray
    levels: the 97th percentile of the contrasts of the peaks (as the detector finds them, smoothed across the
    stripes only) in every ``step``-th row that stand more than ``noise_k`` times the smoothed ``noise`` above
    it: the well-lit stripes, mostly of the floor and wall. The five seeds' 40 scan views read 34-43 (their 90th
    percentiles 17-33: how much of a view is dark fur moves those), at half their gray levels 17-20; the
    level rises as the resolution falls (the tests' 1024 px side view reads 59, 25 at half its gray levels)."""
    w = g.shape[1]
    rows = g[::step]
    s = cv2.GaussianBlur(rows, (0, 0), sigmaX=params.sigma_x * max(w / 3072.0, 0.5), sigmaY=0.01)
    _, contrast, peak = _background_and_peaks(s, params, w)
    floor = int(max(params.noise_k * noise, 1.0))  # contrast above it: integers above the floor's whole part
    at = cv2.bitwise_and(cv2.compare(s, peak, cv2.CMP_EQ), cv2.threshold(contrast, floor, 255, cv2.THRESH_BINARY)[1])
    counts = cv2.calcHist([contrast], [0], at, [256], [0, 256]).ravel()
    total = counts.sum()
    return float(np.searchsorted(np.cumsum(counts), 0.97 * total)) if total else 0.0


def exposure_scale(g: np.ndarray, params: DetectionParams, noise: float) -> float:
    """The factor (0-1] by which the detector's gray-level thresholds (``scaled_thresholds``) are lowered for
    the gray image g (H, W) uint8: its ``stripe_level`` over ``STRIPE_LEVEL``, 1 at and above it. The
    thresholds are gray levels tuned on frames at the simulator's exposure; a frame exposed half as long
    (another camera's gain, another renderer's light) halves every contrast and its noise, and at the full
    thresholds a fur view lost the stripes of its dark coat: of the five-seed bench's views 4 and 8 at half
    the gray levels 10 of 16 were placed (8 of 8 at seed 4 with the thresholds halved)."""
    level = stripe_level(g, params, noise)
    if level <= 0 or level >= STRIPE_LEVEL:
        return 1.0
    # never nearer the noise than EXPOSURE_NOISE_K smoothed sigmas: on a noisy sensor the fixed 8 levels were
    # what kept the noise's bumps beside a dim stripe out (40 stripes of 11 levels under 4.5 levels of noise
    # at 3072 px: 90 centres in a row at level / STRIPE_LEVEL, 41 at 8 sigmas, 40 at 10)
    return min(1.0, max(level / STRIPE_LEVEL, EXPOSURE_NOISE_K * noise / params.min_contrast))


def scaled_thresholds(params: DetectionParams, exposure: float) -> DetectionParams:
    """``params`` with the gray-level thresholds scaled by ``exposure``: min_contrast, min_flank,
    faint_contrast, weak_contrast and shade_floor (the noise guards, ``noise_k`` and ``faint_k``, are
    relative to the noise already)."""
    return replace(params, min_contrast=params.min_contrast * exposure, min_flank=params.min_flank * exposure,
                   faint_contrast=params.faint_contrast * exposure, weak_contrast=params.weak_contrast * exposure,
                   shade_floor=params.shade_floor * exposure)


def smoothing_gain(params: DetectionParams, width: int) -> float:
    """The factor by which the detector's Gaussian smoothing (``sigma_x``, ``sigma_y``, scaled to an
    image ``width`` px wide) divides white noise: the root of the sum of its squared weights, with the
    kernel sizes OpenCV picks for 8-bit images. About 0.49 at 1536 px and below, 0.23 at 3072 px."""
    scale = max(width / 3072.0, 0.5)
    gain = 1.0
    for sigma in (params.sigma_x * scale, params.sigma_y * scale):
        kernel = cv2.getGaussianKernel(int(round(sigma * 6 + 1)) | 1, sigma)
        gain *= float(np.sqrt(np.square(kernel).sum()))
    return gain


def noise_sigma(g: np.ndarray) -> float:
    """Sensor noise of a gray image (H, W) uint8, gray levels (sigma): the median absolute difference of
    vertically adjacent pixels on a sparse grid (every 8th row pair, every 4th column). The stripes run down
    the image, so these differences are mostly noise; the median ignores the outlines."""
    h = g.shape[0]
    if h < 2:
        return 0.0
    # np.median of the integers 0..255 from their counts: the mean of the two middle ones, exactly
    below = np.cumsum(_kernels.difference_counts(g, 8, 4))
    n = int(below[-1])
    middle = np.searchsorted(below, [(n - 1) // 2, n // 2], side="right")
    return float(middle.sum()) / 2 / (0.6745 * np.sqrt(2.0))


def _band_centres(g: np.ndarray, a: int, b: int, params: DetectionParams, faint: float = 0.0
                  ) -> tuple[np.ndarray, ...]:
    """Candidate centres of rows a..b-1 of the gray image g (H, W) uint8, one per peak: x, y (int64 pixels),
    u, contrast, width, flank and shaded (see Centres), in raster order. With ``faint`` (> 0, under min_contrast)
    the peaks above it are listed too, and those above min_contrast come out as without them."""
    h, w = g.shape
    sigma_y = params.sigma_y * max(w / 3072.0, 0.5)
    margin = int(4 * sigma_y) + 2  # beyond the blur's reach (OpenCV's 8-bit kernel: radius ~3 sigma)
    a0, b0 = max(a - margin, 0), min(b + margin, h)
    s = cv2.GaussianBlur(g[a0:b0], (0, 0), sigmaX=params.sigma_x * max(w / 3072.0, 0.5), sigmaY=sigma_y)
    s = s[a - a0:b - a0]
    bg, contrast, peak = _background_and_peaks(s, params, w)
    low = params.weak_contrast if params.weak_contrast > 0 else params.min_contrast
    if faint > 0:
        low = min(low, faint)
    # 0/1: as bright as every pixel within peak_px columns, and more than low above the background
    strong = cv2.threshold(contrast, int(low), 1, cv2.THRESH_BINARY)[1]
    cand = cv2.bitwise_and(cv2.compare(s, peak, cv2.CMP_EQ), strong)
    # on a flat-topped peak keep only its first pixel (strictly brighter than the left neighbour); then
    # the centroids, widths and flanks of the peaks in one compiled pass, one centre per peak (the NumPy
    # form they replaced is in tests/test_detection_kernels.py)
    at = _kernels.first_peaks(cand, s)
    half = _scaled(params.background_px, w) // 2 + 1
    strong_at = float(params.min_contrast) if faint > 0 else np.inf
    x, y, u, width, flank, contrast_at = _kernels.refine_peaks(s, bg, at, half, a, strong_at)
    shaded = u.copy()
    if params.shade_px > 0:  # the faint peaks (``faint``) are for the stripes' ends, not for the points
        sel = np.flatnonzero(contrast_at > strong_at) if faint > 0 else slice(None)
        shaded[sel] = _kernels.shaded_centroids(s, x[sel], y[sel], a, _scaled(params.shade_px, w),
                                                float(params.shade_floor))
    return x, y, u, contrast_at, width, flank, shaded


def _background_and_peaks(s: np.ndarray, params: DetectionParams, w: int) -> tuple[np.ndarray, ...]:
    """Of the smoothed rows s (R, W) uint8 of an image ``w`` px wide: the local background (the minimum over
    ``background_px`` columns), the contrast s - background and the maximum over ``peak_px`` columns each side
    (a peak is where s equals it), all (R, W) uint8."""
    bg = cv2.erode(s, np.ones((1, _scaled(params.background_px, w, odd=True)), np.uint8))
    contrast = cv2.subtract(s, bg)
    peak = cv2.dilate(s, np.ones((1, 2 * _scaled(params.peak_px, w) + 1), np.uint8))
    return bg, contrast, peak


def shaded_centre(profile: np.ndarray, peak: int, floor: float = 4.0) -> float:
    """Sub-pixel centre of the stripe peaking at index ``peak`` of one row's profile (K,) gray levels (the
    smoothed image, ``shade_px`` each side), pixels from the profile's start.

    What the camera sees is the surface's reflectance times the light on it, rho(x) (R(x) + S(x)): room light
    R and the stripe S. Where the stripe is dim against its surroundings (dark fur beside a brighter patch,
    a shaded flank) the room light's share, rho R, slopes across the stripe and pulls the centroid toward
    the brighter side, and a reflectance that changes across the stripe skews the stripe's own profile the
    same way: on the simulator's fur side views 1.5-3 px over a hundred rows, the points 2-5 mm off. Here
    the darkest pixel on each side (within the profile) stands for rho R there, the line through the two
    for rho R under the stripe, and the profile is (p - line) / (line + floor): the stripe's light over the
    room light's, rho cancelled. The centre is the centroid of that ratio above half its height, in the
    run through the peak (as ``refine_peaks`` takes it on the plain profile). ``floor`` keeps a dark
    background (no room light: rho R is the noise) from weighting the profile much: there it is close to
    the plain difference (synthetic stripes of 20-60 gray levels on black with 1.5 levels of read noise:
    RMS 0.177 px against the plain centroid's 0.157; under 60 levels of room light on a varying reflectance
    0.23 against 0.72). A floor of 8 costs less in the dark (0.165) but more on dark fur under dim room
    light, and 4 measured a little better on the bench's fur views. A peak with no darker pixel on one side
    keeps its own column."""
    p = np.asarray(profile, np.float64)
    c = int(peak)
    if c < 1 or c > len(p) - 2:
        return float(c)
    il = int(np.argmin(p[:c]))
    ir = len(p) - 1 - int(np.argmin(p[c + 1:][::-1]))  # the first of equals from the outside in
    line = p[il] + (p[ir] - p[il]) / (ir - il) * (np.arange(len(p)) - il)
    ratio = (p - line) / (line + floor)
    top = ratio[c]
    if not top > 0:
        return float(c)
    level = 0.5 * top
    lo = c
    while lo - 1 > il and ratio[lo - 1] > level:
        lo -= 1
    hi = c
    while hi + 1 < ir and ratio[hi + 1] > level:
        hi += 1
    k = np.arange(lo, hi + 1)
    weight = ratio[lo:hi + 1] - level
    return float(c + np.sum((k - c) * weight) / np.sum(weight))


def _linked(x: np.ndarray, y: np.ndarray, w: int, strong: np.ndarray, weak: np.ndarray, link: float
            ) -> np.ndarray:
    """(M,) bool: weak candidates joined to a strong one through weak ones, row to row (one or two rows
    apart, within ``link`` columns). x, y : (M,) int64 pixels in raster order (as the bands list them)."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    m = len(x)
    wi = np.nonzero(weak)[0]
    if len(wi) == 0:
        return weak
    key = y * w + x  # ascending
    r = int(np.floor(link))
    src, dst = [], []
    for gap in (-2, -1, 1, 2):
        lo = np.searchsorted(key, key[wi] + gap * w - r)
        hi = np.searchsorted(key, key[wi] + gap * w + r, side="right")
        for off in range(2 * r + 1):  # candidates are at least two pixels apart: a handful per window
            j = np.minimum(lo + off, m - 1)
            ok = (lo + off < hi) & (y[j] == y[wi] + gap) & (strong[j] | weak[j])
            src.append(wi[ok])
            dst.append(j[ok])
    a, b = np.concatenate(src), np.concatenate(dst)
    _, comp = connected_components(csr_matrix((np.ones(len(a)), (a, b)), shape=(m, m)), directed=False)
    reached = np.zeros(comp.max() + 1, bool)
    reached[comp[strong]] = True
    return weak & reached[comp]


def reliable(c: Centres, params: DetectionParams = DetectionParams()) -> np.ndarray:
    """(M,) bool: centres whose position can be trusted for triangulation.

    Not for dropping centres before labelling (every centre helps link and label its stripe) but for
    keeping unreliable ones out of the point cloud. On the simulator's 3072 px fur side views most animal
    points more than 2 mm off the surface came from centres 1.5-5 px off the true crossing: one-sided
    peaks on a brightness ramp (a dark, barely lit stretch of fur beside a brighter patch or the outline)
    and stripes widened at a grazing silhouette; leaving these out takes the points beyond 2 mm from
    4.4 % to 2.6 % and from 6.9 % to 4.2 % (seed 4, 40 and 50 stripes).
    """
    ok = np.ones(len(c), bool)
    if c.flank is not None:
        ok &= c.flank >= np.maximum(params.min_flank * c.exposure, params.flank_ratio * c.contrast)
    if len(c) and params.max_width > 0:
        ok &= c.width <= params.max_width * c.median_width
    return ok


def clipped(c: Centres, params: DetectionParams = DetectionParams(), reference: float | None = None) -> np.ndarray:
    """(M,) bool: centres whose run above half height (``Centres.width``) is narrower than ``min_width`` of
    the ``reference`` width: a profile cut by an outline in front of it, or running off the edge of the surface it
    lights, has lost one side, and its centroid lies off the plane's image toward the other. The stripe's
    width is set by the projector's focus and the camera's blur; a surface turned away from the camera narrows
    it too, but such a stripe grazes an outline as well. Like ``reliable``, for keeping centres out of the cloud,
    not out of the labelling. ``reference`` : the width (pixels) to compare with, the image's median
    (``Centres.median_width``) if None; the scan passes the animal's own, as a wall or floor out of focus
    widens its stripes and would otherwise cut every stripe of an animal in focus. Measured in
    docs/benchmarks.md (2026-12-04)."""
    if len(c) == 0 or params.min_width <= 0:
        return np.zeros(len(c), bool)
    return c.width < params.min_width * (c.median_width if reference is None else reference)


def check_image(image: np.ndarray, expected: tuple[int, int] | None, name: str = "image") -> None:
    """Refuse blank, saturated or wrong-size images with a message a technician can act on."""
    if image.ndim not in (2, 3) or image.size == 0:
        raise ImageError(f"{name}: not an image array (shape {image.shape})")
    h, w = image.shape[:2]
    if expected is not None and (w, h) != tuple(expected):
        raise ImageError(f"{name}: image is {w}x{h} but the calibration is for {expected[0]}x{expected[1]}")
    # every 4th pixel of every 4th row: how many are saturated, the darkest and the brightest
    bright, lo, hi, n = _kernels.sample_levels(to_gray8(image, name), 4, 250)
    if bright / n > 0.5:
        raise StripeDetectionError(f"{name}: more than half of the image is saturated: reduce exposure or "
                                   "projector brightness")
    if hi - lo < 10:
        raise StripeDetectionError(f"{name}: the image is blank (no contrast): no stripes to measure")


# --- Algorithm 2, vectorised -------------------------------------------------------------------------
# Algorithm 2 slides a left and a right window along each row of a binarised image: a stripe starts where
# the right window is brighter and the between-group variance ratio of the two exceeds a threshold, and
# ends where the left one is. The mirrored pass gives the left boundary. In event terms the right
# boundary is the first "falling" event after a "rising" one and the mirrored pass picks the last
# "rising" event before it, so each rising -> falling transition of a row's event sequence is one
# stripe. That lets the whole frame be done with one box filter and one lookup table.


def binarize_local(signal: np.ndarray, local_px: int, offset: float) -> tuple[np.ndarray, np.ndarray]:
    """Local binarisation: a pixel is stripe light when it exceeds the mean of a row window by ``offset``.

    signal : (H, W) uint8. Returns (binary (H, W) uint8 0/1, local mean (H, W) uint8).
    """
    mean = cv2.blur(signal, (max(3, local_px | 1), 1))
    thr = cv2.add(mean, np.full_like(mean, int(round(offset))))
    return cv2.compare(signal, thr, cv2.CMP_GT) // 255, mean


def _event_lut(w: int, ratio: float) -> np.ndarray:
    """Event code (0 none, 1 rising, 2 falling) for each pair of window sums (left a, right c) of a 0/1 row."""
    a, c = np.meshgrid(np.arange(w + 1), np.arange(w + 1), indexing="ij")
    m = (a + c) / (2.0 * w)
    between = ((a - c) / w) ** 2 / 4.0  # between-group variance of two equal groups
    total = m * (1 - m)  # variance of the pooled binary windows
    with np.errstate(divide="ignore", invalid="ignore"):
        eta = np.where(total > 0, between / total, 0.0)
    code = np.where(eta > ratio, np.where(a < c, 1, np.where(a > c, 2, 0)), 0)
    lut = np.zeros(256, np.uint8)
    lut[(a * (w + 1) + c).ravel()] = code.ravel()
    return lut


def algorithm2_boundaries(binary: np.ndarray, window: int, ratio: float
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Algorithm 2's stripe boundaries on a 0/1 image (H, W) uint8, both passes at once.

    Returns rows (K,), left (K,) and right (K,) int64: ``left`` is the first pixel of the stripe as the
    mirrored pass reports it (image.cols - temp boundary), ``right`` the first pixel after it.
    """
    w = int(window)
    if not 1 <= w <= 14:
        raise ValueError(f"window must be 1..14 px, got {w}")
    width = binary.shape[1]
    sums = cv2.boxFilter(binary, -1, (w, 1), normalize=False, anchor=(0, 0), borderType=cv2.BORDER_CONSTANT)
    n = width - 2 * w + 1  # window positions x = w .. width - w, both windows inside the row
    code = sums[:, : n] * np.uint8(w + 1) + sums[:, w: w + n]  # left window sum at x, right window sum at x
    events = cv2.LUT(np.ascontiguousarray(code), _event_lut(w, ratio))
    flat = np.flatnonzero(events)
    kind = events.ravel()[flat]
    row = flat // n
    col = flat % n + w
    i = np.flatnonzero((kind[:-1] == 1) & (kind[1:] == 2) & (row[:-1] == row[1:]))
    return row[i], col[i], col[i + 1]


def algorithm2_centres(image: np.ndarray, window: int = 3, ratio: float = 0.5, local_px: int = 31,
                       offset: float = 4.0, ambient: np.ndarray | None = None) -> Centres:
    """The paper's gray centres (mean of the two boundaries), vectorised, on a locally binarised image.

    image : (H, W) uint8/uint16. ``u`` is the boundary midpoint in pixel-centre coordinates (no sub-pixel
    refinement: that is the baseline the pipeline's centroid is measured against).
    """
    bits = sample_bits(np.asarray(image))
    g = to_gray8(image, bits=bits)
    if ambient is not None:
        g = cv2.subtract(g, to_gray8(ambient, bits=bits))
    binary, _ = binarize_local(g, local_px, offset)
    rows, left, right = algorithm2_boundaries(binary, window, ratio)
    width = (right - left).astype(np.float32)
    return Centres((left + right - 1) / 2.0, rows.astype(np.int32), g[rows, np.clip(left, 0, g.shape[1] - 1)]
                   .astype(np.float32), width)
