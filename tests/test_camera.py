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
