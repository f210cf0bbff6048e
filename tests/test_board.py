import numpy as np
import pytest

from measurement.board import abc_to_plane, board_plane, find_corners, fit_plane_abc, object_points
from measurement.camera import Intrinsics, project
from measurement.images import read_image


def test_fit_plane_abc_recovers_a_known_plane():
    rng = np.random.default_rng(1)
    xy = rng.uniform(-200, 200, (500, 2))
    z = 0.2 * xy[:, 0] - 0.1 * xy[:, 1] + 1000 + rng.normal(0, 0.01, 500)
    abc = fit_plane_abc(np.column_stack([xy, z]))
    assert np.allclose(abc, [0.2, -0.1, 1000], atol=1e-3)
    plane = abc_to_plane(abc)
    assert np.isclose(np.linalg.norm(plane[:3]), 1.0)
    assert abs(np.array([0, 0, 1000.0]) @ plane[:3] - plane[3]) < 0.01


def test_fit_plane_abc_rejects_too_few_points():
    with pytest.raises(ValueError, match="points"):
        fit_plane_abc(np.zeros((2, 3)))


def test_board_plane_contains_the_board_origin():
    R = np.eye(3)
    t = np.array([10.0, 20.0, 900.0])
    plane = board_plane(R, t)
    assert np.isclose(plane[:3] @ t, plane[3])


def test_corners_on_a_rendered_board_lie_within_a_fraction_of_a_pixel(small_capture, small_truth):
    intr = Intrinsics.from_dict(small_truth)
    pose = small_truth["board_poses"][0]
    img = read_image(small_capture / "calib" / f"{pose['name']}_board.png")
    corners = find_corners(img, (14, 10))
    assert corners is not None and corners.shape == (140, 2)
    truth = project(object_points((14, 10), 40.0).astype(float) @ np.array(pose["R"]).T + pose["t"], intr)
    if np.linalg.norm(corners[0] - truth[0]) > 20:  # a symmetric board may come back rotated by 180 degrees
        truth = truth[::-1]
    assert np.sqrt(np.mean(np.sum((corners - truth) ** 2, axis=1))) < 0.25


def test_corners_are_not_found_on_a_blank_image_or_with_the_wrong_pattern(small_capture):
    assert find_corners(np.full((400, 600), 128, np.uint8), (14, 10)) is None
    img = read_image(small_capture / "calib" / "pose_01_board.png")
    assert find_corners(img, (11, 8)) is None
