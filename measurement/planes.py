"""Light-plane fitting: the paper's z = A x + B y + C least squares, total least squares with outlier
rejection, and a pencil of planes sharing one axis through the projector; plane error E2 (Algorithm 4).

Planes are rows [nx, ny, nz, d] with n.X = d, |n| = 1, camera frame, mm.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from . import _kernels
from .board import abc_to_plane, fit_plane_abc
from .threads import second_core

PLANE_METHODS = ("abc", "tls", "robust", "pencil")


def _check_points(points: np.ndarray, name: str = "points") -> np.ndarray:
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 3:
        raise ValueError(f"{name} must be (N>=3, 3), got {pts.shape}")
    return pts


def fit_plane_tls(points: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Total least squares plane (smallest singular vector of the centred points).

    points : (N, 3) float64 mm; weights : (N,) optional non-negative
    returns: (4,) [nx, ny, nz, d], n_x >= 0
    """
    pts = _check_points(points)
    if weights is None:  # the weighted formulas with unit weights, without their passes over the points
        c = pts.sum(axis=0) / len(pts)
        q = pts - c
    else:
        w = np.asarray(weights, float)
        c = (pts * w[:, None]).sum(axis=0) / w.sum()
        q = (pts - c) * np.sqrt(w)[:, None]
    _, s, vt = np.linalg.svd(q, full_matrices=False)
    if s[1] < 1e-9 * max(s[0], 1e-300):
        raise ValueError("points are collinear: a plane is not determined")
    n = vt[2]
    return _orient(np.append(n, n @ c))


def _orient(plane: np.ndarray) -> np.ndarray:
    return plane if plane[0] >= 0 else -plane


def point_plane_distance(points: np.ndarray, plane: np.ndarray) -> np.ndarray:
    """Signed distances (N,) mm of points (N, 3) to plane [n, d]."""
    return points @ plane[:3] - plane[3]


def fit_plane_robust(points: np.ndarray, rng: np.random.Generator | None = None, iterations: int = 200,
                     inlier_mm: float | None = None, exact: bool = True, refine_points: int | None = None
                     ) -> tuple[np.ndarray, np.ndarray]:
    """RANSAC on point triples, then iterated TLS on inliers within 3.5 robust sigma.

    exact   : refit the final inliers by SVD (False: keep the scatter-matrix plane that chose them, equal
              to rounding, ~1e-12 relative, and cheaper by one SVD of the inliers)
    refine_points : iterate on an even subsample of about this many points (every k-th), not all of them:
              the plane of 10^5 floor points is no better than of 10^4 (its offset's error shrinks as
              1/sqrt(n), 1e-3 mm either way); the RANSAC draws are those of the whole set
    returns : plane (4,), inlier mask (N,) bool (of the subsample with ``refine_points``)
    """
    pts = _check_points(points)
    rng = rng or np.random.default_rng(0)
    tol = inlier_mm if inlier_mm is not None else 2.0
    sample = pts[rng.choice(len(pts), min(len(pts), 2000), replace=False)]  # scoring on a subsample
    tri = sample[rng.integers(0, len(sample), (iterations, 3))]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(n, axis=1)
    good = norm > 1e-9
    n = n[good] / norm[good, None]
    d = np.einsum("ij,ij->i", n, tri[good, 0])
    counts = _inlier_counts(sample, n, d, tol)
    best = np.append(n[np.argmax(counts)], d[np.argmax(counts)]) if len(counts) else fit_plane_tls(pts)
    if refine_points is not None and len(pts) > refine_points:
        pts = pts[::-(-len(pts) // refine_points)]
    inl = np.abs(point_plane_distance(pts, best)) < tol
    # the inlier sets are chosen with planes from the scatter matrix (a few passes over the points instead
    # of an SVD each); with ``exact`` the plane returned is the TLS fit of the last set, as it always was
    moments = _Moments(pts, sample.mean(axis=0))
    used, plane = inl, best
    for _ in range(4):
        used = inl
        quick = moments.plane(inl)
        # too few or nearly collinear inliers: the exact fit decides (or raises)
        plane = quick if quick is not None else fit_plane_tls(pts[inl])
        r = point_plane_distance(pts, plane)
        sigma = 1.4826 * np.median(np.abs(r[inl])) + 1e-9
        new = np.abs(r) < max(3.5 * sigma, 1e-6)
        if (new == inl).all():
            break
        inl = new
    return (fit_plane_tls(pts[used]) if exact else _orient(plane)), inl


def _inlier_counts(sample: np.ndarray, n: np.ndarray, d: np.ndarray, tol: float) -> np.ndarray:
    """``_kernels.inlier_counts`` (each hypothesis (H,) scored on its own), the later half of many on the
    second core."""
    if len(n) < 64:
        return _kernels.inlier_counts(sample, n, d, tol)
    half = len(n) // 2
    later = second_core().submit(_kernels.inlier_counts, sample, n[half:], d[half:], tol)
    return np.concatenate([_kernels.inlier_counts(sample, n[:half], d[:half], tol), later.result()])


class _Moments:
    """Plane fits of subsets of one point set from its first and second moments (about a point near
    its centroid, so that little cancels): (3, 3) scatter matrix and its eigenvectors."""

    def __init__(self, pts: np.ndarray, ref: np.ndarray):
        self.ref = ref
        self.t = np.ascontiguousarray((pts - ref).T)  # (3, N)

    def plane(self, mask: np.ndarray) -> np.ndarray | None:
        """[n, d] of the points where ``mask``; None when they are fewer than 3 or nearly collinear."""
        w = mask.astype(np.float64)
        count = w.sum()
        if count < 3:
            return None
        tw = self.t * w
        mean = tw.sum(axis=1) / count
        scatter = tw @ self.t.T - count * np.outer(mean, mean)
        ev, vec = np.linalg.eigh(scatter)
        if not ev[1] > 1e-12 * ev[2]:  # singular values 1e-6 apart: let the SVD judge
            return None
        n = vec[:, 0]
        return np.append(n, n @ (mean + self.ref))


def fit_planes(groups: list[np.ndarray], method: str = "pencil") -> tuple[np.ndarray, list[np.ndarray]]:
    """One plane per group of points, by ``method`` in PLANE_METHODS.

    groups  : list of (N_k, 3) float64 mm, one per stripe, left to right
    returns : planes (K, 4), inlier masks (list of (N_k,) bool)
    """
    planes, masks, _ = fit_planes_detailed(groups, method)
    return planes, masks


def fit_planes_detailed(groups: list[np.ndarray], method: str = "pencil"
                        ) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
    """Like fit_planes, also returning the independent per-stripe fits (K, 4) before any pencil constraint."""
    if method not in PLANE_METHODS:
        raise ValueError(f"method must be one of {PLANE_METHODS}, got {method!r}")
    every = [np.ones(len(g), bool) for g in groups]
    if method == "abc":
        planes = np.array([_orient(abc_to_plane(fit_plane_abc(g))) for g in groups])
        return planes, every, planes
    if method == "tls":
        planes = np.array([fit_plane_tls(g) for g in groups])
        return planes, every, planes
    fits = [fit_plane_robust(g) for g in groups]
    independent = np.array([f[0] for f in fits])
    masks = [f[1] for f in fits]
    planes = independent
    if method == "pencil" and len(groups) >= 3:
        planes = fit_pencil([g[m] for g, m in zip(groups, masks, strict=True)], independent)
    return planes, masks, independent


def pencil_axis(planes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The line that a set of planes comes closest to sharing: point (3,) mm and unit direction (3,)."""
    n, d = planes[:, :3], planes[:, 3]
    _, _, vt = np.linalg.svd(n)
    a = vt[2]  # direction most orthogonal to every normal
    p0, *_ = np.linalg.lstsq(np.vstack([n, a]), np.append(d, 0.0), rcond=None)
    return p0, a


def extended_planes(planes: np.ndarray, pad: int, ends: int = 4) -> np.ndarray:
    """The light planes (N, 4) with ``pad`` virtual ones before the first and after the last: (N + 2 pad, 4),
    the real ones at pad..pad + N - 1. The virtual planes go on turning about the planes' common axis
    (``pencil_axis``) by the mean angle between the last ``ends`` planes at each end: the stripes a wider
    pattern would cast. Labelling grows a piece with provisional indices before it knows where the piece
    lies in the pattern; held to the N real planes, a piece whose seed sat off the middle was cut off at
    an index that is no edge of the animal (``matching._pieces``)."""
    n = len(planes)
    if pad <= 0 or n < 2:
        return np.array(planes, np.float64)
    p0, a = pencil_axis(planes)
    u, w = _axis_basis(a)
    normals = planes[:, :3]
    theta = np.unwrap(np.arctan2(normals @ w, normals @ u))
    k = min(ends, n - 1)
    lo_step = (theta[k] - theta[0]) / k
    hi_step = (theta[-1] - theta[-1 - k]) / k
    t = np.concatenate([theta[0] - lo_step * np.arange(pad, 0, -1), theta[-1] + hi_step * np.arange(1, pad + 1)])
    virtual_n = np.cos(t)[:, None] * u + np.sin(t)[:, None] * w
    virtual = np.column_stack([virtual_n, virtual_n @ p0])
    return np.concatenate([virtual[:pad], planes, virtual[pad:]])


def _axis_basis(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ref = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(a, ref)
    u /= np.linalg.norm(u)
    return u, np.cross(a, u)


def _planes_through_axis(groups: list[np.ndarray], p0: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, list]:
    """Best plane through the axis for each group: closed form (2x2 eigenproblem), plus residuals."""
    u, v = _axis_basis(a)
    planes, resid = [], []
    for g in groups:
        q = g - p0
        uv = np.column_stack([q @ u, q @ v])
        w, vec = np.linalg.eigh(uv.T @ uv)
        c = vec[:, 0]  # normal = c0 u + c1 v, perpendicular to the axis
        n = c[0] * u + c[1] * v
        planes.append(_orient(np.append(n, n @ p0)))
        resid.append(uv @ c)
    return np.array(planes), resid


def fit_pencil(groups: list[np.ndarray], init: np.ndarray) -> np.ndarray:
    """Planes constrained to share one axis (the projector's stripes all pass through its centre and are
    parallel to its columns). The axis (4 parameters) is optimised; each plane's angle about it has a
    closed form, so the problem stays small however many points there are.

    groups : list of (N_k, 3) mm inlier points per stripe; init : (K, 4) independent plane fits
    returns: (K, 4) planes
    """
    p0, a = pencil_axis(init)
    u, v = _axis_basis(a)
    # parametrise the axis by a point offset in the plane normal to the initial axis and a small tilt
    sub = [g[:: max(1, len(g) // 4000)] for g in groups]

    def axis(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        point = p0 + x[0] * u + x[1] * v
        direction = a + x[2] * u + x[3] * v
        return point, direction / np.linalg.norm(direction)

    def residuals(x: np.ndarray) -> np.ndarray:
        return np.concatenate(_planes_through_axis(sub, *axis(x))[1])

    sol = least_squares(residuals, np.zeros(4), x_scale=[10.0, 10.0, 1e-3, 1e-3], method="lm")
    planes, _ = _planes_through_axis(groups, *axis(sol.x))
    return planes


def plane_error_e2(planes: np.ndarray) -> float:
    """The paper's light-plane error (Algorithm 4): write each plane as A x + B y - z = -C, solve the
    stacked system for the point all planes nearly share, and take the deviation of the recomputed
    right-hand side: sqrt(|b_hat - b|^2 / (n + 1)). Units of C (mm)."""
    A = -planes[:, 0] / planes[:, 2]
    B = -planes[:, 1] / planes[:, 2]
    C = planes[:, 3] / planes[:, 2]
    M = np.column_stack([A, B, -np.ones(len(A))])
    b = -C
    x, *_ = np.linalg.lstsq(M, b, rcond=None)
    return float(np.sqrt(np.sum((M @ x - b) ** 2) / (len(b) + 1)))


def planes_to_abc(planes: np.ndarray) -> np.ndarray:
    """(K, 4) [n, d] -> (K, 3) [A, B, C] of z = A x + B y + C (the paper's form; ill-conditioned when n_z ~ 0)."""
    return np.column_stack([-planes[:, 0] / planes[:, 2], -planes[:, 1] / planes[:, 2], planes[:, 3] / planes[:, 2]])
