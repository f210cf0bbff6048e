"""Chessboard corners (fast on large images) and the board plane (least squares, eq. 2-4 of the paper)."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

_SUBPIX = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 60, 1e-4)


@dataclass(frozen=True)
class BoardParams:
    """Corner detection knobs.

    detect_width : the image is reduced to about this width (px) for the coarse search; full size is
                   only used for sub-pixel refinement, which keeps 6-megapixel images fast
    """

    detect_width: int = 1024


def to_uint8(gray: np.ndarray) -> np.ndarray:
    """(H, W) uint8/uint16 -> uint8, stretching 16-bit images to their own range."""
    if gray.dtype == np.uint8:
        return gray
    hi = float(np.percentile(gray, 99.9)) or 1.0
    return np.clip(gray.astype(np.float32) * (255.0 / hi), 0, 255).astype(np.uint8)


def find_corners(gray: np.ndarray, pattern: tuple[int, int], params: BoardParams = BoardParams()
                 ) -> np.ndarray | None:
    """Inner chessboard corners in OpenCV order, or None when the board is not found.

    gray    : (H, W) uint8 or uint16 image
    pattern : (cols, rows) inner corners
    returns : (cols*rows, 2) float64 pixels (u, v)
    """
    img = to_uint8(gray)
    h, w = img.shape
    scale = min(1.0, params.detect_width / w)
    small = cv2.resize(img, (round(w * scale), round(h * scale)), interpolation=cv2.INTER_AREA) if scale < 1 else img
    found, corners = cv2.findChessboardCornersSB(small, pattern, flags=cv2.CALIB_CB_NORMALIZE_IMAGE)
    if not found:  # the exhaustive search is several times slower: only when the quick one fails
        found, corners = cv2.findChessboardCornersSB(small, pattern, flags=cv2.CALIB_CB_NORMALIZE_IMAGE
                                                     | cv2.CALIB_CB_EXHAUSTIVE)
    if not found:
        flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
        found, corners = cv2.findChessboardCorners(small, pattern, flags=flags)
        if not found:
            return None
    corners = corners.reshape(-1, 2).astype(np.float64)
    # small-image pixel centres map to full-size centres by (p + 0.5) / scale - 0.5
    corners = (corners + 0.5) / scale - 0.5
    spacing = _corner_spacing(corners, pattern)
    half = int(np.clip(round(spacing * 0.1), 4, 25))  # small windows: lens curvature biases big ones
    refined = cv2.cornerSubPix(img, corners.astype(np.float32).reshape(-1, 1, 2), (half, half), (-1, -1), _SUBPIX)
    refined = _canonical_order(refined.reshape(-1, 2).astype(np.float64), pattern)
    if part_of_larger_board(img, refined, pattern):
        return None
    return refined


def part_of_larger_board(img: np.ndarray, corners: np.ndarray, pattern: tuple[int, int]) -> bool:
    """True when the squares beyond the detected grid keep alternating black and white on two or more
    sides: the detector matched a smaller pattern inside a larger board (a wrong board_cols/board_rows)."""
    cols, rows = pattern
    g = corners.reshape(rows, cols, 2)
    h, w = img.shape
    alternating = 0
    # (edge corners, outward step) for the four sides; sample the centres of the second square ring
    sides = [(g[0, :], g[0, :] - g[1, :]), (g[-1, :], g[-1, :] - g[-2, :]),
             (g[:, 0], g[:, 0] - g[:, 1]), (g[:, -1], g[:, -1] - g[:, -2])]
    for edge, out in sides:
        mid = (edge[:-1] + edge[1:]) / 2 + 1.5 * (out[:-1] + out[1:]) / 2
        inner = (edge[:-1] + edge[1:]) / 2 - 0.5 * (out[:-1] + out[1:]) / 2
        ok = (mid[:, 0] >= 0) & (mid[:, 0] < w - 1) & (mid[:, 1] >= 0) & (mid[:, 1] < h - 1)
        if ok.sum() < 3:
            continue
        ref = img[inner[:, 1].astype(int).clip(0, h - 1), inner[:, 0].astype(int).clip(0, w - 1)].astype(float)
        val = img[mid[ok, 1].astype(int), mid[ok, 0].astype(int)].astype(float)
        contrast = np.ptp(ref) + 1e-6  # black-to-white difference inside the board
        # alternation: neighbouring samples differ by a large part of the board's own contrast
        if np.median(np.abs(np.diff(val))) > 0.5 * contrast:
            alternating += 1
    return alternating >= 2


def _corner_spacing(corners: np.ndarray, pattern: tuple[int, int]) -> float:
    grid = corners.reshape(pattern[1], pattern[0], 2)
    return float(np.median(np.linalg.norm(np.diff(grid, axis=1), axis=2)))


def _canonical_order(corners: np.ndarray, pattern: tuple[int, int]) -> np.ndarray:
    """Make the first corner the top-left one and rows run left to right, so that poses agree.

    OpenCV may return a symmetric board's corners rotated by 180 degrees; that flips the board frame,
    which breaks nothing in Zhang's method but would make board coordinates inconsistent across poses."""
    grid = corners.reshape(pattern[1], pattern[0], 2)
    if grid[0, 0].sum() > grid[-1, -1].sum():
        grid = grid[::-1, ::-1]
    return grid.reshape(-1, 2)


def object_points(pattern: tuple[int, int], square_mm: float) -> np.ndarray:
    """(cols*rows, 3) float32 board-frame corners (mm), z = 0, row by row as OpenCV returns them."""
    cols, rows = pattern
    j, i = np.mgrid[0:rows, 0:cols]
    return (np.column_stack([i.ravel(), j.ravel(), np.zeros(i.size)]) * square_mm).astype(np.float32)


def fit_plane_abc(points: np.ndarray) -> np.ndarray:
    """The paper's least-squares plane z = A x + B y + C (eq. 2-4) by its normal equations.

    points  : (N, 3) float64 mm, N >= 3 not collinear
    returns : (3,) [A, B, C]
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 3:
        raise ValueError(f"points must be (N>=3, 3), got {pts.shape}")
    x, y, z = pts.T
    M = np.array([[x @ x, x @ y, x.sum()], [x @ y, y @ y, y.sum()], [x.sum(), y.sum(), len(x)]])
    rhs = np.array([x @ z, y @ z, z.sum()])
    return np.linalg.solve(M, rhs)


def abc_to_plane(abc: np.ndarray) -> np.ndarray:
    """[A, B, C] of z = A x + B y + C -> [nx, ny, nz, d] with n.X = d, |n| = 1, n_z < 0."""
    A, B, C = abc
    n = np.array([A, B, -1.0])
    s = np.linalg.norm(n)
    return np.append(n / s, -C / s)


def board_plane(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Plane of the board (z_board = 0) in camera coordinates from its pose: [nx, ny, nz, d], n.X = d."""
    n = R[:, 2]
    return np.append(n, n @ t)
