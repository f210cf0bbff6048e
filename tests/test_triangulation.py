"""Line-plane triangulation: project <-> triangulate round trips on a distorted camera."""

import numpy as np
import pytest

from measurement.camera import Intrinsics, project
from measurement.triangulation import depth_for_labels, intersect, ray_table, rays_at


def _camera(w=320, h=240):
    K = np.array([[300.0, 0, 163.0], [0, 300.0, 118.0], [0, 0, 1]])
    return Intrinsics(K, np.array([-0.1, 0.05, 1e-4, -2e-4, 0.0]), (w, h))


def test_points_on_a_plane_are_recovered_from_their_pixels():
    intr = _camera()
    plane = np.array([0.9, 0.05, -0.2, -150.0])
    plane[:3] /= np.linalg.norm(plane[:3])
    rng = np.random.default_rng(0)
    y, z = rng.uniform(-200, 200, 300), rng.uniform(900, 1400, 300)
    x = (plane[3] - plane[1] * y - plane[2] * z) / plane[0]
    pts = np.column_stack([x, y, z])
    uv = project(pts, intr)
    inside = (uv[:, 0] > 1) & (uv[:, 0] < 318) & (uv[:, 1] > 1) & (uv[:, 1] < 238)
    pts, uv = pts[inside], uv[inside]
    # rows are integers in the pipeline: snap each point's pixel row and move the point along the plane
    v = np.rint(uv[:, 1]).astype(np.int64)
    rays = rays_at(uv[:, 0], v, ray_table(intr))
    back = intersect(rays, np.repeat(plane[None], len(rays), 0))
    assert np.allclose(back @ plane[:3], plane[3], atol=1e-6)  # on the plane
    again = project(back, intr)
    assert np.abs(again[:, 1] - v).max() < 0.02 and np.abs(again[:, 0] - uv[:, 0]).max() < 0.02


def test_depth_for_labels_grows_with_the_stripe_index_on_a_fan_of_planes():
    # planes through a projector 250 mm to the right, toed in: x = 250 + t_k z
    t = np.linspace(-0.3, 0.1, 9)
    n = np.column_stack([np.ones_like(t), np.zeros_like(t), -t])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    planes = np.column_stack([n, 250.0 * n[:, 0]])
    z = depth_for_labels(np.array([[0.0, 0.0, 1.0]]), planes)[0]
    assert (np.diff(z[z > 0]) > 0).all()


def test_a_ray_parallel_to_its_plane_gives_nan():
    out = intersect(np.array([[0.0, 0.0, 1.0]]), np.array([[1.0, 0.0, 0.0, 5.0]]))
    assert np.isnan(out).all()


def test_compiled_rays_at_equals_the_numpy_interpolation_bit_for_bit():
    from measurement.triangulation import _rays_interpolated

    table = ray_table(_camera())
    rng = np.random.default_rng(5)
    u = np.concatenate([rng.uniform(-3.0, 323.0, 5000), np.arange(-1.0, 321.0), [318.999, 319.0, 319.5]])
    v = rng.integers(0, 240, len(u)).astype(np.int32)
    assert rays_at(u, v, table).tobytes() == _rays_interpolated(u, v, table).tobytes()


def test_rays_at_refuses_a_row_outside_the_ray_table():
    table = ray_table(_camera())
    with pytest.raises(IndexError):
        rays_at(np.array([10.0]), np.array([240]), table)


def test_cloud_points_from_kept_cells_equal_rays_at_and_intersect_bit_for_bit():
    from measurement.triangulation import cloud_points, rays_and_cells

    table = ray_table(_camera())
    rng = np.random.default_rng(8)
    u = np.concatenate([rng.uniform(-3.0, 323.0, 5000), np.arange(-1.0, 321.0), [0.0, 318.999, 319.0, 319.5]])
    v = rng.integers(0, 240, len(u)).astype(np.int32)
    rays, cells = rays_and_cells(u, v, table)
    assert cells is not None and rays.tobytes() == rays_at(u, v, table).tobytes()
    # moved within the kept cells, into the next ones, far, past the borders
    u_new = u + rng.choice([0.0, 0.3, -0.7, 1.2, -1.6, 2.5, -3.2, 40.0], len(u)) * rng.uniform(0.5, 1.0, len(u))
    planes = np.column_stack([rng.normal(size=(7, 3)), rng.uniform(-500, 500, 7)])
    planes[3, :3] = [1.0, 0.0, 0.0]  # rays nearly parallel: NaN
    labels = rng.integers(0, 7, len(u))
    idx = np.flatnonzero(rng.random(len(u)) < 0.8)
    got = cloud_points(u_new, u, v, idx, labels, cells, table, planes)
    want = intersect(rays_at(u_new[idx], v[idx], table), planes.take(labels[idx], axis=0))
    assert got.tobytes() == want.tobytes()
    assert cloud_points(u_new, u, v, idx, labels, None, table, planes).tobytes() == want.tobytes()
