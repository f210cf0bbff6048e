"""Line-plane triangulation (section 2.3.3, eq. 5-6 after undistortion): the viewing ray of a stripe
centre meets the light plane of its stripe. Rays come from a per-pixel table built once per camera, so a
frame's 100 000 centres cost microseconds, not an iterative undistortion each."""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from . import _kernels
from .camera import Intrinsics, ray_grid


@lru_cache(maxsize=4)
def _ray_table(key: tuple, transposed: bool = False) -> np.ndarray:
    if transposed:
        return np.ascontiguousarray(_ray_table(key).transpose(1, 0, 2)[..., ::-1])
    K = np.array(key[0]).reshape(3, 3)
    dist = np.array(key[1])
    intr = Intrinsics(K, dist, (key[2], key[3]))
    return ray_grid(intr).astype(np.float32)


def ray_table(intr: Intrinsics, transposed: bool = False) -> np.ndarray:
    """(H, W, 2) float32 normalised (x, y) of every pixel centre, cached per camera. ``transposed``: the
    table of the transposed image and camera frame (``orientation``): (W, H, 2), entry [u, v] holding
    (y, x) of pixel (u, v) (any distortion model, exactly)."""
    key = (tuple(np.round(intr.camera_matrix.ravel(), 9)), tuple(np.round(intr.dist_coeffs.ravel(), 12)),
           int(intr.image_size[0]), int(intr.image_size[1]))
    return _ray_table(key, transposed)


def rays_at(u: np.ndarray, v: np.ndarray, table: np.ndarray) -> np.ndarray:
    """Rays (M, 3) with z = 1 through sub-pixel columns ``u`` (M,) of integer rows ``v`` (M,), by linear
    interpolation along the row of the ray table (rows are exact)."""
    u = np.asarray(u)
    if _table_layout(u, table):  # one fused pass
        return _kernels.rays_at(u, np.asarray(v), table.reshape(-1, 2), table.shape[1], np.empty((len(u), 3)))
    return _rays_interpolated(u, v, table)


def _table_layout(u: np.ndarray, table: np.ndarray) -> bool:
    """Whether the compiled lookups apply: float64 columns ``u`` and a C-contiguous float32 ray table."""
    return u.dtype == np.float64 and table.dtype == np.float32 and table.flags.c_contiguous


def rays_and_cells(u: np.ndarray, v: np.ndarray, table: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """``rays_at(u, v, table)`` (M, 3), and the two table entries each ray interpolated between, (M, 2, 2)
    float32 (None where the compiled pass does not apply), for ``cloud_points`` to read again: a frame's
    ray lookups miss the cache once per centre, and most smoothed centres fall between the same entries."""
    u = np.asarray(u)
    if not _table_layout(u, table):
        return rays_at(u, v, table), None
    cells = np.empty((len(u), 2, 2), np.float32)
    rays = _kernels.rays_and_cells(u, np.asarray(v), table.reshape(-1, 2), table.shape[1], np.empty((len(u), 3)),
                                   cells)
    return rays, cells


def cloud_points(u_new: np.ndarray, u: np.ndarray, v: np.ndarray, idx: np.ndarray, labels: np.ndarray,
                 cells: np.ndarray | None, table: np.ndarray, planes: np.ndarray) -> np.ndarray:
    """Points (K, 3) mm of the centres ``idx`` (K,) at new columns: ``intersect(rays_at(u_new[idx], v[idx],
    table), planes[labels[idx]])`` to the bit, in one pass that reads the cells ``rays_and_cells(u, v,
    table)`` kept instead of the table wherever it can.

    u_new, u : (M,) float64 columns, pixels; v : (M,) rows; labels : (M,) plane index; planes : (N, 4)
    """
    idx = np.asarray(idx, np.int64)
    if cells is None or u_new.dtype != np.float64 or planes.dtype != np.float64 or planes.shape[1:] != (4,):
        return intersect(rays_at(u_new[idx], v[idx], table), planes.take(labels[idx], axis=0))
    return _kernels.cloud_points(u_new, u, v, idx, labels, cells, table.reshape(-1, 2), table.shape[1], planes,
                                 np.empty((len(idx), 3)))


def _rays_interpolated(u: np.ndarray, v: np.ndarray, table: np.ndarray) -> np.ndarray:
    """``rays_at`` in numpy: the arithmetic the compiled kernel repeats."""
    w = table.shape[1]
    u0 = np.clip(np.floor(u).astype(np.int64), 0, w - 2)
    f = u - u0
    # one flat index and take(): several times faster than indexing the (H, W, 2) table by (v, u0)
    flat = table.reshape(-1, 2)
    i = np.asarray(v, np.int64) * w + u0
    t0, t1 = flat.take(i, axis=0), flat.take(i + 1, axis=0)
    out = np.empty((len(u), 3))
    g = 1 - f
    out[:, 0] = t0[:, 0] * g + t1[:, 0] * f
    out[:, 1] = t0[:, 1] * g + t1[:, 1] * f
    out[:, 2] = 1.0
    return out


def intersect(rays: np.ndarray, planes: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Points (M, 3) mm where rays (M, 3) meet planes (M, 4) [n, d] (n.X = d); NaN when parallel.
    out : (M, 3) array for the points (``rays`` itself when the caller no longer needs them)"""
    if kernel_layout(rays, planes) and len(rays) == len(planes):  # summed as np.einsum sums ray . n
        return _kernels.intersect(rays, planes, np.empty_like(rays) if out is None else out)
    denom = np.einsum("ij,ij->i", rays, planes[:, :3])
    with np.errstate(divide="ignore", invalid="ignore"):
        s = planes[:, 3] / denom
    s[np.abs(denom) < 1e-9] = np.nan
    return np.multiply(rays, s[:, None], out=out)


def kernel_layout(rays: np.ndarray, planes: np.ndarray) -> bool:
    """Whether np.einsum("ij,ij->i", rays, planes[:, :3]) takes its unit-stride path (three float64
    products summed (x + z) + y), so that the compiled kernels reproduce it."""
    return (rays.dtype == planes.dtype == np.float64 and rays.ndim == planes.ndim == 2
            and rays.strides[1] == planes.strides[1] == 8 and rays.shape[1] == 3 and planes.shape[1] == 4)


def depth_on(rays: np.ndarray, planes: np.ndarray) -> np.ndarray:
    """Depth z (M,) mm of ``intersect(rays, planes)``, without the other two coordinates."""
    denom = np.einsum("ij,ij->i", rays, planes[:, :3])
    with np.errstate(divide="ignore", invalid="ignore"):
        s = planes[:, 3] / denom
    s[np.abs(denom) < 1e-9] = np.nan
    return rays[:, 2] * s


def depth_for_labels(rays: np.ndarray, planes: np.ndarray) -> np.ndarray:
    """Depth z (M, K) mm of each ray (M, 3) on every plane (K, 4); NaN/negative where behind the camera.
    Each row comes out the same whichever other rows share the call."""
    if len(rays) == 1:  # one row alone would take BLAS's matrix-vector product, which rounds differently
        return depth_for_labels(np.repeat(rays, 2, axis=0), planes)[:1]
    z = rays @ planes[:, :3].T
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.divide(planes[None, :, 3], z, out=z)  # in place: one (M, K) array, not two


def depth_in_range(rays: np.ndarray, planes: np.ndarray, k: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """(M,) True where lo < z < hi for the depth z of each ray (M, 3) on its plane ``k`` (M,) as
    ``depth_for_labels`` gives it, without that (M, N) matrix: z is formed ray by ray (the same formula,
    rounded another way), and where it lies within that rounding of a bound, or is not finite, the
    matrix's row decides."""
    if kernel_layout(rays, planes):  # ray by ray, summed as np.einsum sums
        out = np.empty(len(rays), bool)
        unsure = _kernels.depth_screen(rays, planes, k, float(lo), float(hi), out)
    else:
        p = planes.take(k, axis=0)
        dot = np.einsum("ij,ij->i", rays, p[:, :3])
        # both sums of three products err by under 4 ulp of the sum of their magnitudes: a margin 1000 times that
        size = np.einsum("ij,ij->i", np.abs(rays), np.abs(p[:, :3]))
        with np.errstate(divide="ignore", invalid="ignore"):
            z = p[:, 3] / dot
            margin = np.abs(z) * 1e-12 * (1 + size / np.abs(dot))
        out = (z > lo) & (z < hi)
        unsure = np.flatnonzero(~(np.minimum(np.abs(z - lo), np.abs(z - hi)) > margin))
    if len(unsure):
        z = depth_for_labels(rays.take(unsure, axis=0), planes)[np.arange(len(unsure)), k[unsure]]
        out[unsure] = (z > lo) & (z < hi)
    return out
