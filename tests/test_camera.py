import numpy as np
import pytest

from measurement.camera import Intrinsics, project, ray_grid, rays, undistort
from measurement.simulate.rig import default_rig


@pytest.fixture()
def intr() -> Intrinsics:
    return default_rig((640, 427)).intrinsics


def test_project_then_undistort_round_trips_to_the_normalised_point(intr):
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(-300, 300, 200), rng.uniform(-200, 200, 200), rng.uniform(800, 1400, 200)])
    uv = project(pts, intr)
    xy = undistort(uv, intr)
    assert np.abs(xy - pts[:, :2] / pts[:, 2:]).max() < 1e-9


def test_rays_have_unit_depth_and_pass_through_the_point(intr):
    pts = np.array([[100.0, -50.0, 1000.0], [-200.0, 120.0, 900.0]])
    r = rays(project(pts, intr), intr)
    assert np.allclose(r[:, 2], 1.0)
    assert np.allclose(r * pts[:, 2:], pts, atol=1e-6)


def test_ray_grid_matches_pointwise_undistortion(intr):
    grid = ray_grid(intr)
    w, h = intr.image_size
    assert grid.shape == (h, w, 2)
    uv = np.array([[0.0, 0.0], [w - 1.0, h - 1.0], [123.0, 321.0]])
    expect = undistort(uv, intr)
    assert np.abs(grid[uv[:, 1].astype(int), uv[:, 0].astype(int)] - expect).max() < 1e-12


def test_intrinsics_survive_a_dict_round_trip(intr):
    back = Intrinsics.from_dict(intr.to_dict())
    assert np.allclose(back.camera_matrix, intr.camera_matrix)
    assert np.allclose(back.dist_coeffs, intr.dist_coeffs)
    assert back.image_size == intr.image_size


def test_a_rational_distortion_model_is_kept_whole(intr):
    """A calibration.json from another tool with OpenCV's 8-coefficient rational model: the rays of the
    frame's corners follow all eight (cutting to five, as before, moved them by pixels)."""
    d = intr.to_dict()
    d["dist_coeffs"] = [-0.28, 0.09, 1e-4, -2e-4, -0.01, 0.05, -0.02, 0.01]
    rational = Intrinsics.from_dict(d)
    assert rational.dist_coeffs.size == 8
    pts = np.array([[-330.0, -220.0, 1000.0], [0.0, 0.0, 1000.0], [310.0, 210.0, 1000.0]])
    uv = project(pts, rational)
    assert np.abs(undistort(uv, rational) - pts[:, :2] / pts[:, 2:]).max() < 1e-9
    five = Intrinsics.from_dict({**d, "dist_coeffs": d["dist_coeffs"][:5]})
    assert np.abs(project(pts, five) - uv).max() > 1.0


@pytest.mark.parametrize("field, value, says", [
    ("dist_coeffs", [0.1, 0.2, 0.3], "3 coefficients"),
    ("dist_coeffs", [float("nan")] * 5, "finite"),
    ("camera_matrix", [[0, 0, 320], [0, 500, 240], [0, 0, 1]], "focal lengths"),
    ("image_size", [0, 480], "not an image size"),
])
def test_malformed_intrinsics_name_their_field(intr, field, value, says):
    with pytest.raises(ValueError, match=says):
        Intrinsics.from_dict({**intr.to_dict(), field: value})
