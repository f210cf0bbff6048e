"""Smoothing the centres along their stripes (``segments.smooth_along_stripes``)."""

import numpy as np

from measurement.detection import Centres
from measurement.segments import smooth_along_stripes


def _centres(u: np.ndarray, v: np.ndarray, shaded: np.ndarray | None = None) -> Centres:
    n = len(u)
    return Centres(np.asarray(u, float), np.asarray(v, np.int32), np.full(n, 40.0, np.float32),
                   np.full(n, 6.0, np.float32), None, shaded)


def test_a_slanted_stripe_comes_out_as_it_is_to_its_ends_and_across_a_short_gap():
    v = np.r_[np.arange(100, 140), np.arange(142, 170)]  # two rows missing
    u = 500.0 + 0.7 * (v - 100)
    s, keep = smooth_along_stripes(_centres(u, v), np.zeros(len(v), np.int64), np.zeros(len(v), np.int64), 2.0)
    np.testing.assert_allclose(s, u, atol=1e-9)
    assert keep.all()


def test_noise_along_a_stripe_is_smoothed_from_the_shaded_centres():
    rng = np.random.default_rng(3)
    v = np.tile(np.arange(300), 2)
    true = np.r_[800.0 + 0.3 * np.arange(300), 840.0 + 0.3 * np.arange(300)]
    shaded = true + rng.normal(0, 0.4, len(v))
    c = _centres(true + 5.0, v, shaded)  # u: only for how the segments go on; the positions are ``shaded``
    s, keep = smooth_along_stripes(c, np.repeat([0, 1], 300), np.repeat([3, 4], 300), 2.0)
    err = s - true
    assert np.sqrt(np.mean(err**2)) < 0.45 * np.sqrt(np.mean((shaded - true) ** 2))
    assert abs(err.mean()) < 0.05


def test_segments_of_a_stripe_cut_by_a_dropout_are_one_run_but_not_across_a_depth_step():
    rng = np.random.default_rng(4)
    v = np.arange(90)
    true = np.where(v < 60, 300.0 + 0.5 * v, 309.0 + 0.5 * v)  # a depth step at row 60: 9 px sideways
    u = true + rng.normal(0, 0.4, 90)
    segment = np.repeat([0, 1, 2], [30, 30, 30])  # linking cut the stripe at row 30 (a dropout) and 60
    labels = np.full(90, 7)
    c = _centres(u, v)
    s, keep = smooth_along_stripes(c, segment, labels, 2.0, reach=6)
    # over the cut at row 30 the line reads both sides, as it does mid-segment, not one (no segment going on)
    alone, _ = smooth_along_stripes(c, segment, labels, 0.0, reach=6)
    near_cut = np.abs(v - 30) <= 6
    assert np.abs(s - true)[near_cut].mean() < np.abs(alone - true)[near_cut].mean()
    # nothing of one side of the step reaches the other
    one, _ = smooth_along_stripes(_centres(u[:60], v[:60]), segment[:60], labels[:60], 2.0, reach=6)
    np.testing.assert_array_equal(s[:60], one)


def test_two_stripes_of_one_label_in_the_same_rows_are_smoothed_apart():
    # seen from above a light plane can meet the flank and, past it, the floor in the same image rows
    v = np.r_[np.arange(40), np.arange(20, 60)]
    u = np.r_[1500.0 + 0.2 * np.arange(40), 1650.0 + 2.5 * np.arange(40)]
    s, _ = smooth_along_stripes(_centres(u, v), np.repeat([0, 1], 40), np.full(80, 21), 2.0)
    np.testing.assert_allclose(s, u, atol=1e-9)


def test_an_outlier_is_flagged_and_read_as_its_median_and_unlabelled_centres_are_left():
    v = np.r_[np.arange(60), np.arange(10), np.arange(3)]
    u = np.r_[np.full(60, 400.0), np.full(10, 100.0), [200.0, 201.0, 203.0]]
    u[10] += 3.0  # a speck of scattered light
    labels = np.r_[np.zeros(60, np.int64), np.full(10, -1), np.full(3, 5)]
    s, keep = smooth_along_stripes(_centres(u, v), np.repeat([0, 1, 2], [60, 10, 3]), labels, 2.0)
    np.testing.assert_allclose(s[:60], 400.0, atol=1e-9)
    assert not keep[10] and keep[:60].sum() == 59
    np.testing.assert_array_equal(s[60:], u[60:])  # unlabelled, and a run too short to smooth
    assert not keep[60:70].any() and keep[70:].all()


def test_a_noisy_stripe_is_smoothed_over_the_longer_reach_and_a_clean_one_is_left_as_it_was():
    """Fur's centres scatter about their stripe (0.15-0.24 px median off the short line on the simulator's
    fur views): such a run takes the line over ``noisy``'s rows, a clean curving one keeps the short line."""
    rng = np.random.default_rng(5)
    v = np.arange(400)
    bend = 600.0 + 60.0 * np.sin(v / 300.0)  # a stripe curving over a rounded body
    fur = bend + rng.normal(0, 0.35, len(v))
    clean = bend + 300.0 + rng.normal(0, 0.05, len(v))
    c = _centres(np.r_[fur, clean], np.r_[v, v])
    segment, labels = np.repeat([0, 1], 400), np.repeat([3, 9], 400)
    short, kept = smooth_along_stripes(c, segment, labels, 2.0, reach=6)
    both, keep = smooth_along_stripes(c, segment, labels, 2.0, reach=6, noisy=(0.13, 12))
    def rms(s: np.ndarray) -> float:
        return float(np.sqrt(np.mean((s - bend) ** 2)))

    assert rms(both[:400]) < 0.85 * rms(short[:400])
    assert np.array_equal(both[400:], short[400:])
    assert np.array_equal(keep, kept)  # the specks flagged are the same
