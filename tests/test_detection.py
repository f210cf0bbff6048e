"""Stripe-centre detection: the vectorised Algorithm 2 against its literal transcription, centres against
the simulator's exact crossings, and refusals of unusable images."""

import numpy as np
import pytest

from measurement.detection import (
    Centres,
    DetectionParams,
    algorithm2_boundaries,
    algorithm2_centres,
    check_image,
    clipped,
    detect_centres,
    detect_centres_and_faint,
    noise_sigma,
    reliable,
    subtract_ambient,
)
from measurement.errors import ImageError, StripeDetectionError
from measurement.images import read_image
from measurement.paper import boundaries_literal
from measurement.simulate.truth import match_crossings


@pytest.mark.parametrize("window", [1, 2, 3, 5])
@pytest.mark.parametrize("density", [0.1, 0.3, 0.5])
def test_vectorised_algorithm2_equals_the_literal_per_pixel_loop(window, density):
    rng = np.random.default_rng(int(density * 10) + window)
    binary = (rng.random((30, 160)) < density).astype(np.uint8)
    binary[:, 40:50] = 1
    binary[:, [39, 50]] = 0
    rows, left, right = algorithm2_boundaries(binary, window, 0.5)
    assert list(zip(rows.tolist(), left.tolist(), right.tolist(), strict=True)) == \
        boundaries_literal(binary, window, 0.5)


def test_algorithm2_centre_of_a_clean_run_is_its_middle():
    img = np.zeros((5, 100), np.uint8)
    img[:, 30:39] = 200  # run of pixels 30..38, middle 34
    c = algorithm2_centres(img, window=3, local_px=31, offset=4)
    assert len(c) == 5 and np.allclose(c.u, 34.0) and (c.v == np.arange(5)).all()


def _side(small_capture):
    img = read_image(small_capture / "scan" / "side.png")
    truth = dict(np.load(small_capture / "truth" / "side_stripes.npz"))
    return img, truth


def test_centres_lie_on_the_exact_plane_crossings(small_capture):
    img, truth = _side(small_capture)
    c = detect_centres(img)
    label, kind = match_crossings(np.column_stack([c.u, c.v]), truth)
    assert np.mean(label >= 0) > 0.8  # most centres are real crossings
    found = truth["kind"] != 0
    assert len(c) > 0.8 * found.sum()
    # sub-pixel error on the wall (no fur): the centroid beats Algorithm 2's boundary midpoint
    order = np.lexsort((truth["uv"][:, 0], np.rint(truth["uv"][:, 1])))
    key = np.rint(truth["uv"][order, 1]) * 1e5 + truth["uv"][order, 0]

    def wall_rms(u, v):
        q = v * 1e5 + u
        i = np.clip(np.searchsorted(key, q), 1, len(key) - 1)
        d = np.where(np.abs(key[i] - q) < np.abs(key[i - 1] - q), key[i] - q, key[i - 1] - q)
        _, k = match_crossings(np.column_stack([u, v]), truth)
        return float(np.sqrt(np.mean(d[k == 3] ** 2)))

    alg2 = algorithm2_centres(img)
    assert wall_rms(c.u, c.v) < 0.3
    assert wall_rms(c.u, c.v) < wall_rms(alg2.u, alg2.v)


def _row_image(profile: np.ndarray, rows: int = 20) -> np.ndarray:
    """Rows of a full-width (3072 px) frame, the scale the detector's pixel parameters are given at."""
    return np.tile(np.clip(profile, 0, 255).astype(np.uint8), (rows, 1))


def test_a_symmetric_stripe_is_reliable_and_the_rising_side_of_a_brightness_step_is_not():
    x = np.arange(3072, dtype=float)
    stripe = 20 + 80 * np.exp(-0.5 * ((x - 60) / 2.0) ** 2)
    # a dim stripe on dark fur right beside a brighter patch: its peak barely stands above the patch side
    step = 10 + 40 / (1 + np.exp(-(x - 146) / 3.0)) + 12 * np.exp(-0.5 * ((x - 140) / 2.0) ** 2)
    c = detect_centres(_row_image(np.maximum(stripe, step)))
    ok = reliable(c)
    near_stripe = np.abs(c.u - 60) < 1
    on_step = np.abs(c.u - 60) > 10
    assert near_stripe.any() and ok[near_stripe].all()
    assert on_step.any() and not ok[on_step].any()


@pytest.mark.parametrize("room", [60.0, 25.0])
def test_the_shaded_centre_divides_out_a_reflectance_ramp_that_pulls_the_plain_centroid_off(room):
    # dark fur (reflectance 0.15) turning to a brighter patch (0.6) across a stripe: rho (room + stripe)
    x = np.arange(3072, dtype=float)
    rho = 0.15 + 0.45 / (1 + np.exp(-(x - 1508) / 8.0))
    stripe = sum(110 * np.exp(-0.5 * ((x - m) / 3.0) ** 2) for m in (1464.3, 1500.3, 1536.3))
    c = detect_centres(_row_image(rho * (room + stripe)))
    at = np.abs(c.u - 1500.3) < 3
    assert at.sum() == 20
    plain, shaded = np.abs(c.u[at] - 1500.3).max(), np.abs(c.shaded[at] - 1500.3).max()
    assert plain > 0.5 and shaded < 0.2 and shaded < plain / 3
    assert (c.position is c.shaded) and np.allclose(c.take(at).shaded, c.shaded[at])


def test_without_room_light_the_shaded_centre_is_the_plain_one():
    x = np.arange(3072, dtype=float)
    stripe = sum(100 * np.exp(-0.5 * ((x - m) / 3.0) ** 2) for m in (200.2, 236.6, 273.0))
    c = detect_centres(_row_image(stripe + 1.0))
    assert len(c) == 60
    np.testing.assert_allclose(c.shaded, c.u, atol=0.02)
    np.testing.assert_allclose(c.shaded, np.repeat([200.2, 236.6, 273.0], 20).reshape(3, 20).T.ravel(), atol=0.05)


def test_a_stripe_widened_at_a_grazing_surface_is_unreliable():
    x = np.arange(3072, dtype=float)
    narrow = sum(100 * np.exp(-0.5 * ((x - m) / 2.0) ** 2) for m in (40, 80, 120, 160, 200))
    wide = 100 * np.exp(-0.5 * ((x - 300) / 4.0) ** 2)
    c = detect_centres(_row_image(10 + narrow + wide))
    ok = reliable(c)
    widened = np.abs(c.u - 300) < 2
    assert widened.any() and ok[~widened].all() and not ok[widened].any()


def test_a_stripe_cut_by_an_outline_is_clipped_and_its_centroid_is_off():
    x = np.arange(3072, dtype=float)
    whole = sum(100 * np.exp(-0.5 * ((x - m) / 2.5) ** 2) for m in (40, 80, 120, 160, 200, 240))
    cut = np.where(x <= 300.5, 100 * np.exp(-0.5 * ((x - 300) / 2.5) ** 2), 0.0)  # an outline hides its right half
    c = detect_centres(_row_image(10 + whole + cut))
    at_cut = np.abs(c.u - 300) < 3
    flagged = clipped(c)
    assert at_cut.any() and flagged[at_cut].all() and not flagged[~at_cut].any()
    assert np.abs(c.u[at_cut] - 300).min() > 0.5  # what keeps it out of the cloud: its centroid is off
    assert not clipped(c, DetectionParams(min_width=0)).any()
    assert clipped(c, reference=2 * c.median_width).all()  # against stripes twice as wide (the scan: the animal's)


def test_with_hysteresis_a_faint_stripe_end_is_followed_from_its_bright_part_but_a_faint_stripe_alone_is_not():
    x = np.arange(3072, dtype=float)
    bright = 20 + 60 * np.exp(-0.5 * ((x - 500) / 2.0) ** 2)
    faint = 20 + 7 * (np.exp(-0.5 * ((x - 500) / 2.0) ** 2) + np.exp(-0.5 * ((x - 1500) / 2.0) ** 2))
    img = np.vstack([_row_image(bright, 40), _row_image(faint, 40)])
    c = detect_centres(img, DetectionParams(weak_contrast=4.0))
    tail = (np.abs(c.u - 500) < 1) & (c.v >= 45)
    assert set(c.v[tail].tolist()) == set(range(45, 80))  # the grazing end of a stripe is kept
    assert not (np.abs(c.u - 1500) < 5).any()  # a faint stripe linked to no bright one is not
    off = detect_centres(img)  # hysteresis is off by default
    assert not ((np.abs(off.u - 500) < 1) & (off.v >= 45)).any()


def test_the_faint_peaks_are_listed_apart_and_leave_the_centres_as_they_were(small_capture):
    x = np.arange(3072, dtype=float)
    bright = 20 + 60 * np.exp(-0.5 * ((x - 500) / 2.0) ** 2)
    faint = 20 + 7 * (np.exp(-0.5 * ((x - 500) / 2.0) ** 2) + np.exp(-0.5 * ((x - 1500) / 2.0) ** 2))
    img = np.vstack([_row_image(bright, 40), _row_image(faint, 40)])
    centres, weak = detect_centres_and_faint(img)
    assert not (centres.v >= 45).any()  # the faint rows hold no centre
    for col in (500, 1500):
        assert set(range(45, 80)) <= set(weak.v[np.abs(weak.u - col) < 1].tolist())
    # on a rendered view the centres are detect_centres' to the bit
    img, _ = _side(small_capture)
    alone = detect_centres(img)
    centres, weak = detect_centres_and_faint(img)
    assert len(weak) > 0
    for name in ("u", "v", "contrast", "width", "flank"):
        assert np.array_equal(getattr(alone, name), getattr(centres, name))


def test_unreliable_centres_are_mostly_off_the_true_crossings(small_capture):
    img, truth = _side(small_capture)
    c = detect_centres(img)
    ok = reliable(c)
    label, _ = match_crossings(np.column_stack([c.u, c.v]), truth, max_px=1.0)
    assert ok.mean() > 0.9  # most centres are kept
    assert np.mean(label[~ok] < 0) > 2 * np.mean(label[ok] < 0)  # the rejected ones are far more often off


def test_ambient_image_of_another_size_is_refused(small_capture):
    img, _ = _side(small_capture)
    with pytest.raises(ImageError, match="ambient"):
        detect_centres(img, ambient=img[:100])


def test_the_ambient_image_is_subtracted_without_cutting_the_dim_background_at_zero():
    # a dim room (5 gray levels, noise 2 in both shots) and faint stripes (+9 at the peak), as on a dark floor
    rng = np.random.default_rng(3)
    x = np.arange(1536)
    centres = np.arange(60, 1476, 72)
    stripes = sum(np.exp(-0.5 * ((x - c) / 2.5) ** 2) for c in centres)
    img = np.clip(np.rint(5 + 9 * stripes + rng.normal(0, 2, (200, 1536))), 0, 255).astype(np.uint8)
    ambient = np.clip(np.rint(5 + rng.normal(0, 2, (200, 1536))), 0, 255).astype(np.uint8)
    diff = subtract_ambient(img, ambient)
    assert abs(noise_sigma(diff) - 2 * np.sqrt(2)) < 0.5  # both shots' noise is left, none cut off at 0

    def found(c):
        return int(sum((np.abs(c.u - k) < 1.5).sum() for k in centres))

    assert found(detect_centres(img, ambient=ambient)) >= found(detect_centres(img)) > 500


def test_blank_saturated_and_wrong_size_images_are_refused():
    with pytest.raises(StripeDetectionError, match="blank"):
        check_image(np.full((200, 300), 30, np.uint8), (300, 200))
    with pytest.raises(StripeDetectionError, match="saturated"):
        check_image(np.full((200, 300), 255, np.uint8), (300, 200))
    with pytest.raises(ImageError, match="calibration is for"):
        check_image(np.zeros((200, 300), np.uint8), (3072, 2048))


def _noisy_stripes(noise: float, seed: int = 0, sigma: float = 1.5) -> np.ndarray:
    """A 200 x 1536 frame of 40 Gaussian stripes (sigma px, 35 gray levels over 40) plus sensor noise."""
    x = np.arange(1536, dtype=float)
    centres = 100 + 33.0 * np.arange(40)
    row = 40 + 35 * np.exp(-0.5 * ((x[:, None] - centres[None, :]) / sigma) ** 2).sum(axis=1)
    rng = np.random.default_rng(seed)
    return np.clip(np.rint(row[None, :] + rng.normal(0, noise, (200, 1536))), 0, 255).astype(np.uint8)


@pytest.mark.parametrize("noise", [2.0, 5.0, 9.0])
def test_noise_sigma_reads_the_sensor_noise(noise):
    from measurement.detection import noise_sigma, to_gray8

    est = noise_sigma(to_gray8(_noisy_stripes(noise)))
    assert abs(est - noise) < 0.25 * noise + 0.6  # the integer median steps by about 1 gray level


def test_a_noisy_sensor_does_not_turn_its_noise_into_stripes():
    """At 9 gray levels of noise a fixed 8-level contrast threshold finds hundreds of peaks per row; the
    threshold that follows the noise finds the 40 stripes."""
    img = _noisy_stripes(9.0)
    fixed = detect_centres(img, DetectionParams(noise_k=0.0))
    adaptive = detect_centres(img)
    per_row = np.bincount(np.bincount(adaptive.v)).argmax()
    assert len(fixed) / 200 > 80
    assert per_row == 40
    assert abs(len(adaptive) / 200 - 40) < 2


def test_a_wide_stripe_gives_one_centre_not_two():
    """Stripes twice as wide as the reference optics' (sigma 3.5 px at 1536 px) with a little noise: a
    one-level dip splits the flat top of some into two equal maxima, which refine to the same centroid;
    each row still has one centre per stripe, none within half a pixel of another."""
    ours = detect_centres(_noisy_stripes(3.0, sigma=3.5))
    order = np.lexsort((ours.u, ours.v))
    same_row = ours.v[order][1:] == ours.v[order][:-1]
    assert (np.diff(ours.u[order])[same_row] >= 0.5).all()
    assert abs(len(ours) / 200 - 40) < 0.25


@pytest.mark.parametrize("width", [1536, 3072])
def test_smoothing_gain_is_the_noise_the_detectors_blur_leaves(width):
    import cv2

    from measurement.detection import smoothing_gain

    p = DetectionParams()
    scale = max(width / 3072.0, 0.5)
    noise = np.random.default_rng(1).normal(0, 10.0, (1000, 1000)).astype(np.float32)
    left = cv2.GaussianBlur(noise, (0, 0), sigmaX=p.sigma_x * scale, sigmaY=p.sigma_y * scale).std() / 10.0
    assert abs(smoothing_gain(p, width) - left) < 0.01


def test_a_faint_stripe_under_a_noisy_sensor_is_found_at_full_resolution():
    """3072 px wide, 40 stripes of 11 gray levels under 4.5 levels of sensor noise. The detector smooths
    over twice the pixels it does at 1536 px, so the noise it sees is a quarter of the sensor's: the old
    threshold of 2.5x the raw noise lost a third of these crossings; one on the smoothed noise finds them
    all but a few, and still turns no noise into stripes."""
    from measurement.detection import noise_sigma

    x = np.arange(3072, dtype=float)
    centres = 200 + 66.0 * np.arange(40)
    row = 40 + 11 * np.exp(-0.5 * ((x[:, None] - centres[None, :]) / 3.0) ** 2).sum(axis=1)
    rng = np.random.default_rng(3)
    img = np.clip(np.rint(row[None, :] + rng.normal(0, 4.5, (120, 3072))), 0, 255).astype(np.uint8)
    c = detect_centres(img)
    assert len(c) > 0.95 * 40 * 120
    assert np.bincount(c.v, minlength=120).max() <= 40
    old = detect_centres(img, DetectionParams(min_contrast=2.5 * noise_sigma(img), noise_k=0.0, follow_exposure=False))
    assert len(old) < 0.7 * 40 * 120


def test_noise_sigma_takes_the_median_np_median_takes():
    rng = np.random.default_rng(7)
    for _ in range(200):
        g = rng.integers(0, 256, tuple(rng.integers(2, 40, 2))).astype(np.uint8)
        if rng.random() < 0.3:  # few distinct levels: the two middle differences often differ
            g = (g // 128 * rng.integers(1, 128)).astype(np.uint8)
        rows = np.arange(0, g.shape[0] - 1, 8)
        d = np.abs(g[rows + 1, ::4].astype(np.int16) - g[rows, ::4])
        assert noise_sigma(g) == float(np.median(d)) / (0.6745 * np.sqrt(2.0))


def test_the_median_width_is_np_median_of_the_widths_read_once():
    rng = np.random.default_rng(2)
    for n in (1, 2, 7, 1000):
        width = rng.integers(2, 18, n).astype(np.float32)
        c = Centres(rng.uniform(0, 100, n), np.arange(n, dtype=np.int32), np.ones(n, np.float32), width)
        assert c.median_width == float(np.median(width))
        assert "median_width" in vars(c)  # cached: the reliability test and denoising read it again
        assert c.take(np.arange(n) % 2 == 0).median_width == float(np.median(width[::2]))


def test_the_median_width_from_counts_is_np_median_s():
    from measurement.detection import _median_width

    rng = np.random.default_rng(6)
    for width in (rng.integers(0, 20, 90_001), rng.integers(0, 20, 90_000), np.array([3]), np.array([3, 4]),
                  rng.integers(0, 5000, 101), rng.uniform(0, 19, 1000), np.array([-1.0, 2.0, 5.0]),
                  np.array([np.nan, 2.0, 3.0])):
        width = width.astype(np.float32)
        assert _median_width(width) == float(np.median(width)) or np.isnan(np.median(width))
