"""The compiled peak finding and refinement against the OpenCV masks and NumPy windows they replaced, to
the bit, and whole-frame detection against that form band by band."""

import cv2
import numpy as np
import pytest

from measurement import _kernels
from measurement import detection as det
from measurement.images import read_image


def _peaks_reference(s: np.ndarray, bg: np.ndarray, low: int, reach: int) -> np.ndarray:
    """The peaks as full-frame OpenCV masks found them: s equal to its dilation, contrast above low, the
    first pixel of a flat top (strictly brighter than its left neighbour)."""
    contrast = cv2.subtract(s, bg)
    peak = cv2.dilate(s, np.ones((1, 2 * reach + 1), np.uint8))
    cand = cv2.compare(s, peak, cv2.CMP_EQ)
    cand = cv2.bitwise_and(cand, cv2.compare(contrast, np.full_like(contrast, low), cv2.CMP_GT))
    first = np.zeros_like(cand)
    first[:, 1:] = cv2.compare(s[:, 1:], s[:, :-1], cv2.CMP_GT)
    return np.flatnonzero(np.bitwise_and(cv2.bitwise_and(cand, first), 1).view(bool))


def _refine_reference(s, bg, x, y, half):
    """Centroid of the part of each peak above half its height within +-half pixels, that part's width,
    the peak's height above the higher of its two side minima: (window, peak) arrays."""
    n = 2 * half + 1
    pad = cv2.copyMakeBorder(s, 0, 0, half, half, cv2.BORDER_REPLICATE)
    raw = np.ascontiguousarray(np.lib.stride_tricks.sliding_window_view(pad, n, axis=1)[y, x].T)
    flank = raw[half] - np.maximum(raw[1:half + 1].min(axis=0), raw[half:2 * half].min(axis=0))
    h2 = raw.astype(np.int16) * 2 - (bg[y, x].astype(np.int16) + raw[half])
    run = h2 > 0
    for k in range(1, half + 1):
        run[half + k] &= run[half + k - 1]
        run[half - k] &= run[half - k + 1]
    wts = h2 * run
    offs = np.arange(-half, half + 1, dtype=np.int16)
    u = x + (wts * offs[:, None]).sum(axis=0, dtype=np.int32) / np.maximum(wts.sum(axis=0, dtype=np.int32), 1)
    return u.astype(np.float64), run.sum(axis=0).astype(np.float32), flank.astype(np.float32)


def _one_per_peak(x, y, u, width, flank, contrast):
    """The centres of ``_refine_reference`` as detection kept them, x, y, u, width, flank, contrast: of two
    in a row whose centroids lie within half a pixel, the first."""
    one = np.r_[True, (y[1:] != y[:-1]) | (u[1:] - u[:-1] >= 0.5)]
    return x[one], y[one], u[one], width[one], flank[one], contrast[one].astype(np.float32)


def _stripes(h: int, w: int, seed: int) -> np.ndarray:
    """Blurred noisy stripes of varying period and brightness, with flat tops, saturation and edges."""
    rng = np.random.default_rng(seed)
    x = np.arange(w)
    period = rng.uniform(6, 40)
    img = 60 + 120 * (np.sin(2 * np.pi * x / period)[None, :] > 0.6) * rng.uniform(0.2, 1.0, (h, 1))
    img = img + rng.normal(0, rng.uniform(0, 8), (h, w))
    img[:, : w // 7] = 255  # a saturated flat stretch running to the border
    img[h // 3, :] = rng.integers(0, 256, w)  # a row of pure noise
    g = np.clip(img, 0, 255).astype(np.uint8)
    return cv2.GaussianBlur(g, (0, 0), sigmaX=1.0, sigmaY=1.5)


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("reach,half,low", [(4, 9, 8), (1, 3, 0), (2, 5, 20)])
def test_peaks_and_their_refinement_equal_the_opencv_masks_and_numpy_windows(seed, reach, half, low):
    s = _stripes(40, 301, seed)
    bg = cv2.erode(s, np.ones((1, 2 * half - 1), np.uint8))
    cand = cv2.bitwise_and(cv2.compare(s, cv2.dilate(s, np.ones((1, 2 * reach + 1), np.uint8)), cv2.CMP_EQ),
                           cv2.threshold(cv2.subtract(s, bg), low, 1, cv2.THRESH_BINARY)[1])
    at = _kernels.first_peaks(cand, s)
    assert np.array_equal(at, _peaks_reference(s, bg, low, reach))
    y, x = at // s.shape[1], at % s.shape[1]
    want = _one_per_peak(x, y + 7, *_refine_reference(s, bg, x, y, half), cv2.subtract(s, bg)[y, x])
    got = _kernels.refine_peaks(s, bg, at, half, 7)
    assert all(np.array_equal(p, q) and p.dtype == q.dtype for p, q in zip(got, want, strict=True))


def test_first_peaks_reads_a_mask_whose_length_is_no_multiple_of_eight():
    s = np.tile(np.array([0, 5, 5, 1, 7], np.uint8), (3, 1))  # 15 pixels
    mask = np.ones_like(s)
    assert _kernels.first_peaks(mask, s).tolist() == [1, 4, 6, 9, 11, 14]


def test_refinement_of_a_peak_without_height_is_its_own_column():
    s = np.full((1, 12), 50, np.uint8)
    _, _, u, width, _, _ = _kernels.refine_peaks(s, s.copy(), np.array([5]), 3, 0)
    assert u[0] == 5.0 and width[0] == 0.0


def test_a_flat_top_cut_by_a_dip_refines_to_one_centre():
    s = np.array([[10, 10, 60, 60, 59, 60, 60, 10, 10, 10, 10, 10]], np.uint8)  # first pixels 2 and 5
    x, _, u, *_ = _kernels.refine_peaks(s, np.full_like(s, 10), np.array([2, 5]), 4, 0)
    assert x.tolist() == [2]


def _band_reference(g, a, b, params):
    """``detection._band_centres`` as the OpenCV masks and NumPy windows computed it."""
    h, w = g.shape
    sigma_y = params.sigma_y * max(w / 3072.0, 0.5)
    margin = int(4 * sigma_y) + 2
    a0, b0 = max(a - margin, 0), min(b + margin, h)
    s = cv2.GaussianBlur(g[a0:b0], (0, 0), sigmaX=params.sigma_x * max(w / 3072.0, 0.5), sigmaY=sigma_y)
    s = s[a - a0:b - a0]
    bg = cv2.erode(s, np.ones((1, det._scaled(params.background_px, w, odd=True)), np.uint8))
    low = params.weak_contrast if params.weak_contrast > 0 else params.min_contrast
    at = _peaks_reference(s, bg, int(low), det._scaled(params.peak_px, w))
    y, x = at // w, at % w
    u, width, flank = _refine_reference(s, bg, x, y, det._scaled(params.background_px, w) // 2 + 1)
    x, y, u, width, flank, contrast = _one_per_peak(x, y + a, u, width, flank, cv2.subtract(s, bg)[y, x])
    return x, y, u, contrast, width, flank


@pytest.mark.parametrize("weak", [0.0, 4.0])
def test_band_centres_equal_the_opencv_and_numpy_form(small_capture, weak):
    g = det.to_gray8(read_image(small_capture / "scan" / "side.png"))
    params = det.DetectionParams(weak_contrast=weak)
    for a in range(0, g.shape[0], 100):
        *got, shaded = det._band_centres(g, a, min(a + 100, g.shape[0]), params)
        want = _band_reference(g, a, min(a + 100, g.shape[0]), params)
        assert all(np.array_equal(p, q) and p.dtype == q.dtype for p, q in zip(got, want, strict=True))
        assert shaded.dtype == np.float64 and len(shaded) == len(got[0])  # (its own test above)


def test_sample_levels_are_those_of_the_strided_sample():
    rng = np.random.default_rng(11)
    for shape in ((1, 1), (5, 9), (37, 41), (64, 64)):
        g = rng.integers(0, 256, shape).astype(np.uint8)
        g[: shape[0] // 2] = np.maximum(g[: shape[0] // 2], 250)
        sample = g[::4, ::4]
        assert _kernels.sample_levels(g, 4, 250) == (int((sample >= 250).sum()), int(sample.min()),
                                                     int(sample.max()), sample.size)


@pytest.mark.parametrize("seed", range(6))
def test_strong_peaks_come_out_alike_whether_the_faint_ones_are_listed_or_not(seed):
    s = _stripes(40, 301, seed)
    bg = cv2.erode(s, np.ones((1, 17), np.uint8))
    half, strong = 9, 8.0
    both = _kernels.refine_peaks(s, bg, _kernels.first_peaks(_candidates(s, bg, 3), s), half, 0, strong)
    alone = _kernels.refine_peaks(s, bg, _kernels.first_peaks(_candidates(s, bg, 8), s), half, 0)
    kept = both[5] > strong
    assert (~kept).any()  # faint peaks were listed
    assert all(np.array_equal(p[kept], q) for p, q in zip(both, alone, strict=True))


def _candidates(s, bg, low):
    """0/1 mask of the pixels as bright as every one within 4 columns and more than ``low`` over bg."""
    peak = cv2.dilate(s, np.ones((1, 9), np.uint8))
    return cv2.bitwise_and(cv2.compare(s, peak, cv2.CMP_EQ), cv2.threshold(cv2.subtract(s, bg), low, 1,
                                                                              cv2.THRESH_BINARY)[1])


def test_a_strong_second_half_of_a_flat_top_replaces_its_faint_first_half():
    """One flat top cut by a dip into two first pixels, 3 and 6, both refining to column 5.0: over a local
    background of 14 the first stands 6 gray levels high (faint), over 10 the second 10 (a centre). Listed
    alone, the second is the centre; listed after the faint first, it must still be."""
    s = np.array([[10, 10, 10, 20, 20, 19, 20, 20, 10, 10, 10, 10, 10, 10]], np.uint8)
    bg = np.full_like(s, 10)
    bg[0, 3] = 14
    x, _, u, _, _, contrast = _kernels.refine_peaks(s, bg, np.array([3, 6]), 4, 0, 8.0)
    assert x.tolist() == [6] and u.tolist() == [5.0] and contrast.tolist() == [10.0]
    x, *_ = _kernels.refine_peaks(s, bg, np.array([3, 6]), 4, 0)  # every peak weighed against every other
    assert x.tolist() == [3]


def test_the_shaded_centroids_are_the_numpy_form_peak_by_peak():
    s = _stripes(60, 400, 3)
    bg = cv2.erode(s, np.ones((1, 17), np.uint8))
    at = _kernels.first_peaks(_candidates(s, bg, 8), s)
    x, y, *_ = _kernels.refine_peaks(s, bg, at, 9, 0)
    reach = 13
    got = _kernels.shaded_centroids(s, x, y, 0, reach, 4.0)
    want = []
    for xi, yi in zip(x, y, strict=True):
        a, b = max(xi - reach, 0), min(xi + reach, s.shape[1] - 1)
        want.append(a + det.shaded_centre(s[yi, a:b + 1], xi - a, 4.0))
    assert len(x) > 100
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
    # rows counted from a band's first row
    band = _kernels.shaded_centroids(s[20:], x[y >= 20], y[y >= 20], 20, reach, 4.0)
    np.testing.assert_array_equal(band, got[y >= 20])
