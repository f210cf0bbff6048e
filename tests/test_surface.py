"""Meshing between stripes and snapping picks onto the surface, checked on a sampled cylinder."""

import numpy as np
import pytest

from measurement.surface import (
    MeshParams,
    polyline_length,
    resample,
    snap,
    stripe_mesh,
    surface_path,
)

RADIUS = 150.0  # mm, a barrel-like body along the x axis
DEPTH = 1500.0  # mm, distance of the axis from the camera
SPACING = 15.0  # mm between stripes on the surface


def on_cylinder(x: np.ndarray, theta: np.ndarray, r: float = RADIUS) -> np.ndarray:
    """Points (N, 3) mm on the cylinder at axial position x and angle theta (0 faces the camera)."""
    return np.stack([x, r * np.sin(theta), DEPTH - r * np.cos(theta)], axis=1)


def cylinder_scan(rows_mm: float = 1.0):
    """Stripes across the cylinder every SPACING mm, each sampled about every ``rows_mm`` of height."""
    theta = np.arcsin(np.arange(-0.93 * RADIUS, 0.93 * RADIUS, rows_mm) / RADIUS)
    xs = np.arange(-300.0, 300.0 + 1e-9, SPACING)
    x = np.repeat(xs, len(theta))
    th = np.tile(theta, len(xs))
    points = on_cylinder(x, th)
    stripe = np.repeat(np.arange(len(xs)), len(theta))
    uv = np.stack([x, points[:, 1]], axis=1)  # stand-in image coordinates: row grows with height
    return points, stripe, uv


def helix(n: int, x0=-200.0, x1=220.0, t0=-0.6, t1=0.7) -> np.ndarray:
    s = np.linspace(0, 1, n)
    return on_cylinder(x0 + (x1 - x0) * s, t0 + (t1 - t0) * s)


def helix_length(x0=-200.0, x1=220.0, t0=-0.6, t1=0.7) -> float:
    return float(np.hypot(x1 - x0, RADIUS * (t1 - t0)))


def radial_offset(points: np.ndarray, mm: float) -> np.ndarray:
    """Move points straight away from the cylinder axis by ``mm``."""
    out = points.copy()
    yz = out[:, 1:] - [0.0, DEPTH]
    out[:, 1:] += yz / np.linalg.norm(yz, axis=1, keepdims=True) * mm
    return out


def test_stripe_mesh_joins_only_neighbouring_stripes():
    points, stripe, uv = cylinder_scan()
    surface = stripe_mesh(points, stripe, uv)
    faces = surface.mesh.faces
    assert len(faces) > 0
    spans = stripe[faces].max(axis=1) - stripe[faces].min(axis=1)
    assert set(np.unique(spans)) == {1}
    assert surface.longest_edge_mm < 2 * SPACING


def test_stripe_mesh_skips_long_edges_across_a_missing_stripe():
    points, stripe, uv = cylinder_scan()
    keep = stripe != 10
    surface = stripe_mesh(points[keep], stripe[keep], uv[keep], MeshParams(max_edge_mm=25.0))
    kept = stripe[keep][surface.mesh.faces]
    assert not np.isin(kept, [9, 11]).all(axis=1).any()


def test_snap_moves_an_off_surface_pick_onto_the_true_surface():
    points, stripe, uv = cylinder_scan()
    surface = stripe_mesh(points, stripe, uv)
    truth = on_cylinder(np.array([7.5, -52.5, 101.0]), np.array([0.2, -0.5, 0.9]))  # between stripes
    snapped = snap(radial_offset(truth, 4.0), surface)
    radius = np.linalg.norm(snapped[:, 1:] - [0.0, DEPTH], axis=1)
    assert np.abs(radius - RADIUS).max() < 0.2
    assert np.linalg.norm(snapped - truth, axis=1).max() < 0.5


def test_path_on_the_mesh_matches_the_helix_length_and_beats_nearest_stripe_points():
    points, stripe, uv = cylinder_scan()
    surface = stripe_mesh(points, stripe, uv)
    picks = radial_offset(helix(7), 3.0)
    truth = helix_length()
    on_mesh = polyline_length(surface_path(picks, surface, step_mm=2.0))
    assert abs(on_mesh - truth) / truth < 0.01
    dense = resample(picks, 2.0)
    _, nearest = surface.tree.query(dense)
    nearest_points = polyline_length(points[nearest])
    assert abs(nearest_points - truth) / truth > 3 * abs(on_mesh - truth) / truth


def test_snap_falls_back_to_points_of_a_lone_stripe():
    points, stripe, uv = cylinder_scan()
    keep = stripe == 3
    surface = stripe_mesh(points[keep], stripe[keep], uv[keep])
    assert len(surface.mesh.faces) == 0
    middle = points[keep][len(points[keep]) // 2 - 2:][:5]  # facing the camera: nearest is straight in front
    snapped = snap(middle + [0.0, 0.0, -0.4], surface)
    np.testing.assert_allclose(snapped, middle)


def test_resample_keeps_the_picks_and_bounds_the_step():
    picks = np.array([[0.0, 0, 0], [10.0, 0, 0], [10.0, 3.0, 0]])
    dense = resample(picks, 2.0)
    assert np.linalg.norm(np.diff(dense, axis=0), axis=1).max() <= 2.0 + 1e-12
    assert all(np.isclose(dense, p).all(axis=1).any() for p in picks)
    assert polyline_length(dense) == pytest.approx(13.0)


def test_inputs_with_wrong_shapes_are_refused_with_the_argument_name():
    points, stripe, uv = cylinder_scan()
    with pytest.raises(ValueError, match="uv must have shape"):
        stripe_mesh(points, stripe, uv[:, :1])
    with pytest.raises(ValueError, match=r"points must have shape \(N, 3\)"):
        snap(np.zeros((2, 2)), stripe_mesh(points, stripe, uv))
    with pytest.raises(ValueError, match="finite"):
        polyline_length(np.array([[0.0, np.nan, 0.0]]))


def test_the_automatic_edge_limit_follows_the_stripe_spacing():
    points, stripe, uv = cylinder_scan()
    wide = points * [2.0, 1.0, 1.0]  # stripes 30 mm apart: a fixed 40 mm limit would still do, 25 mm not
    surface = stripe_mesh(wide, stripe, uv)
    assert len(surface.mesh.faces) == len(stripe_mesh(points, stripe, uv).mesh.faces)
    assert len(stripe_mesh(wide, stripe, uv, MeshParams(max_edge_mm=25.0)).mesh.faces) == 0
    keep = stripe != 10  # a missing stripe leaves a hole instead of a bridge
    holed = stripe_mesh(points[keep], stripe[keep], uv[keep])
    assert not np.isin(stripe[keep][holed.mesh.faces], [9, 11]).all(axis=1).any()
