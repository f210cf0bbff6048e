import numpy as np
import pytest

from measurement.planes import (
    fit_pencil,
    fit_plane_robust,
    fit_plane_tls,
    fit_planes,
    plane_error_e2,
    planes_to_abc,
    point_plane_distance,
)


def _pencil(n_planes=8, centre=(250.0, 0.0, 0.0)):
    """Planes through a vertical axis at ``centre``, fanning over 30 degrees."""
    ang = np.deg2rad(np.linspace(-15, 15, n_planes))
    n = np.column_stack([np.cos(ang), np.zeros(n_planes), np.sin(ang)])
    return np.column_stack([n, n @ np.asarray(centre)])


def _sample(plane, rng, n=400, noise=0.1):
    """Points on a plane within a board-sized patch around z = 1000 mm."""
    nrm, d = plane[:3], plane[3]
    u = np.cross(nrm, [0, 1, 0])
    u /= np.linalg.norm(u)
    v = np.cross(nrm, u)
    base = d * nrm + (1000 - (d * nrm)[2]) / u[2] * u if abs(u[2]) > 1e-6 else d * nrm
    pts = base + rng.uniform(-150, 150, (n, 1)) * u + rng.uniform(-200, 200, (n, 1)) * v
    return pts + rng.normal(0, noise, (n, 1)) * nrm


def test_tls_recovers_a_plane_parallel_to_the_camera_axis_where_abc_is_ill_conditioned():
    rng = np.random.default_rng(0)
    true = np.array([1.0, 0.0, 0.0, 250.0])  # x = 250: z = A x + B y + C cannot even express it
    pts = _sample(true, rng)
    fit = fit_plane_tls(pts)
    assert np.degrees(np.arccos(abs(fit[:3] @ true[:3]))) < 0.05
    assert abs(fit[3] - 250) < 0.1


def test_robust_fit_ignores_a_fifth_of_gross_outliers():
    rng = np.random.default_rng(1)
    true = _pencil(1)[0]
    pts = _sample(true, rng, 500)
    pts[:100] += rng.normal(0, 15, (100, 3))
    plane, inliers = fit_plane_robust(pts)
    assert np.degrees(np.arccos(abs(plane[:3] @ true[:3]))) < 0.1
    assert inliers[100:].mean() > 0.95 and inliers[:100].mean() < 0.3
    assert np.degrees(np.arccos(abs(fit_plane_tls(pts)[:3] @ true[:3]))) > 0.1  # plain TLS is pulled


def test_robust_fit_on_a_subsample_lands_within_a_hundredth_of_a_millimetre_of_the_full_fit():
    rng = np.random.default_rng(2)
    true = _pencil(1)[0]
    pts = _sample(true, rng, 60000, noise=0.3)
    pts[:6000] += rng.normal(0, 20, (6000, 3))  # a tenth of the points off the plane (an animal)
    full, _ = fit_plane_robust(pts, np.random.default_rng(0), exact=False)
    sub, inl = fit_plane_robust(pts, np.random.default_rng(0), exact=False, refine_points=8000)
    assert len(inl) < 10000  # the mask is the subsample's
    centre = pts.mean(axis=0)
    assert abs(point_plane_distance(centre[None], full)[0] - point_plane_distance(centre[None], sub)[0]) < 0.01
    assert np.degrees(np.arccos(min(1.0, abs(full[:3] @ sub[:3])))) < 0.005


def test_pencil_fit_is_closer_to_truth_than_independent_fits_on_noisy_data():
    rng = np.random.default_rng(2)
    true = _pencil(10)
    groups = [_sample(p, rng, 60, noise=0.5) for p in true]
    independent = np.array([fit_plane_tls(g) for g in groups])
    pencil = fit_pencil(groups, independent)

    def err(p):
        return np.degrees(np.arccos(np.clip(np.abs(np.sum(p[:, :3] * true[:, :3], 1)), 0, 1))).mean()

    assert err(pencil) < err(independent)
    assert plane_error_e2(pencil) < 1e-6 < plane_error_e2(independent)


def test_fit_planes_orders_and_orients_every_method_alike():
    rng = np.random.default_rng(3)
    true = _pencil(4)  # 4 planes: none exactly parallel to the z axis, where abc breaks down
    groups = [_sample(p, rng, 200, 0.05) for p in true]
    for method in ("abc", "tls", "robust", "pencil"):
        planes, masks = fit_planes(groups, method)
        assert planes.shape == (4, 4) and (planes[:, 0] > 0).all()
        assert all(m.all() or m.mean() > 0.9 for m in masks)
        for g, p in zip(groups, planes, strict=True):
            assert np.abs(point_plane_distance(g, p)).mean() < 0.2
    with pytest.raises(ValueError, match="method"):
        fit_planes(groups, "magic")


def test_abc_form_round_trips():
    true = _pencil(4)
    abc = planes_to_abc(true)
    pts = np.array([[0.0, 0.0, 0.0], [10.0, 5.0, 0.0]])
    z = pts[:, 0:1] * abc[:, 0] + pts[:, 1:2] * abc[:, 1] + abc[:, 2]
    for k, p in enumerate(true):
        on = np.column_stack([pts[:, :2], z[:, k]])
        assert np.allclose(point_plane_distance(on, p), 0, atol=1e-6)


def test_tls_rejects_collinear_points():
    with pytest.raises(ValueError, match="collinear"):
        fit_plane_tls(np.column_stack([np.arange(10.0), np.zeros(10), np.zeros(10)]))


def test_abc_form_fails_for_a_plane_containing_the_viewing_axis_where_tls_does_not():
    rng = np.random.default_rng(4)
    true = _pencil(5)[2]  # x = 250 mm: parallel to the camera's z axis
    pts = _sample(true, rng, 300, 0.05)
    abc_plane = fit_planes([pts], "abc")[0][0]
    tls_plane = fit_planes([pts], "tls")[0][0]
    assert np.abs(point_plane_distance(pts, tls_plane)).mean() < 0.1
    assert np.abs(point_plane_distance(pts, abc_plane)).mean() > 10 * np.abs(point_plane_distance(pts, tls_plane)).mean()
