import numpy as np
import pytest

from measurement.board import find_corners
from measurement.errors import StripeDetectionError
from measurement.images import read_image
from measurement.stripes import StripeParams, _otsu_rows, detect_board_stripes, room_light_ratio


def _pose(capture, name="pose_02"):
    board = read_image(capture / "calib" / f"{name}_board.png")
    stripes = read_image(capture / "calib" / f"{name}_stripes.png")
    return board, stripes, find_corners(board, (14, 10))


def _errors(found, capture, name="pose_02"):
    """Per-centre error (px) against the simulator's exact plane crossings, matched by stripe and row."""
    t = np.load(capture / "truth" / f"{name}_stripes.npz")
    on_board = t["kind"] == 4  # the far wall behind the plate catches the same stripes too
    truth = {(int(k), int(round(v))): u for k, (u, v) in zip(t["stripe"][on_board], t["uv"][on_board], strict=True)}
    keys = [(int(k), int(v)) for k, (_, v) in zip(found.stripe, found.uv, strict=True)]
    matched = [truth.get(key) for key in keys]
    ok = np.array([m is not None for m in matched])
    return found.uv[ok, 0] - np.array([m for m in matched if m is not None]), ok


def test_every_stripe_is_found_and_labelled_left_to_right(small_capture):
    board, stripes, corners = _pose(small_capture)
    found = detect_board_stripes(stripes, board, corners, (14, 10), 40)
    assert set(np.unique(found.stripe)) == set(range(40))
    assert found.rows_used > 0.3 * found.rows_total
    err, matched = _errors(found, small_capture)
    assert matched.mean() > 0.995  # a centre with no truth at its (stripe, row) would be a wrong label
    assert np.abs(err).max() < 2.0  # a wrong label would be a whole stripe spacing (> 10 px) off


def test_weighted_centres_beat_the_paper_midpoint(small_capture):
    board, stripes, corners = _pose(small_capture)
    rms = {}
    for method in ("midpoint", "weighted"):
        found = detect_board_stripes(stripes, board, corners, (14, 10), 40, StripeParams(method=method))
        err, _ = _errors(found, small_capture)
        rms[method] = float(np.sqrt(np.mean(err**2)))
        assert abs(err.mean()) < 0.05  # unbiased either way
    assert rms["weighted"] < rms["midpoint"]
    assert rms["weighted"] < 0.25


def test_a_dark_stripe_image_is_refused_with_the_file_name(small_capture):
    board, stripes, corners = _pose(small_capture)
    dark = np.random.default_rng(0).integers(0, 4, stripes.shape).astype(np.uint8)
    with pytest.raises(StripeDetectionError, match="pose_02_stripes.png"):
        detect_board_stripes(dark, board, corners, (14, 10), 40, name="pose_02_stripes.png")


def test_the_wrong_stripe_count_is_refused(small_capture):
    board, stripes, corners = _pose(small_capture)
    with pytest.raises(StripeDetectionError, match="show all 50 stripes"):
        detect_board_stripes(stripes, board, corners, (14, 10), 50)


def test_sixteen_bit_images_give_the_same_centres(small_capture):
    board, stripes, corners = _pose(small_capture)
    a = detect_board_stripes(stripes, board, corners, (14, 10), 40)
    b = detect_board_stripes(stripes.astype(np.uint16) * 257, board.astype(np.uint16) * 257, corners, (14, 10), 40)
    assert a.rows_used == b.rows_used
    assert np.abs(a.uv - b.uv).max() < 1e-3


def test_vectorised_otsu_splits_two_clusters():
    rows = np.array([[1, 2, 1, 2, 9, 10, 9, 10], [0, 0, 0, 0, 0, 5, 5, 5]], float)
    t = _otsu_rows(rows)
    assert 2 < t[0] < 9 and 0 < t[1] < 5


def test_stripes_missing_in_some_rows_do_not_cost_the_other_stripes_there(small_capture):
    board, stripes, corners = _pose(small_capture)
    full = detect_board_stripes(stripes, board, corners, (14, 10), 40)
    band = (full.uv[:, 1] > np.percentile(full.uv[:, 1], 40)) & (full.uv[:, 1] < np.percentile(full.uv[:, 1], 60))
    rows = np.unique(full.uv[band, 1]).astype(int)
    # erase stripe 7 in a band of rows, as if it fell on a black square too dark to see
    damaged = stripes.copy()
    u7 = full.uv[band & (full.stripe == 7), 0]
    box = (slice(rows.min(), rows.max() + 1), slice(int(u7.min()) - 6, int(u7.max()) + 7))
    ratio = room_light_ratio(stripes.astype(np.float32), board.astype(np.float32), None)
    damaged[box] = np.clip(board[box] * ratio, 0, 255).astype(np.uint8)  # room light only, no stripe
    found = detect_board_stripes(damaged, board, corners, (14, 10), 40)
    # (the detector smooths along the stripes, so the band's first and last few rows still see stripe 7)
    in_band = (found.uv[:, 1] >= rows.min() + 6) & (found.uv[:, 1] <= rows.max() - 6)
    assert not (in_band & (found.stripe == 7)).any()
    assert (in_band & (found.stripe == 20)).sum() > 0.9 * (len(rows) - 12)  # the others keep their rows
    err, matched = _errors(found, small_capture)
    assert matched.mean() > 0.995 and np.abs(err).max() < 2.0
