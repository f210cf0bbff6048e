"""Chessboard plates at random poses: geometry, anti-aliased albedo, and pose sampling that keeps the
whole stripe pattern on the plate (as the paper's calibration requires)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..camera import Intrinsics, project
from .rig import Rig
from .scene import PlaneSurface

WHITE = 0.82
BLACK = 0.07


@dataclass(frozen=True, eq=False)
class Board:
    """A plate carrying a chessboard of ``cols`` x ``rows`` inner corners of ``square_mm``, with a white margin.

    Board frame: origin at the first inner corner, x along the columns, y along the rows, z into the plate.
    """

    cols: int = 14
    rows: int = 10
    square_mm: float = 40.0
    margin_mm: float = 60.0
    white: float = WHITE
    black: float = BLACK

    def object_points(self) -> np.ndarray:
        """(cols*rows, 3) float64 mm, in OpenCV's corner order (row by row)."""
        j, i = np.mgrid[0:self.rows, 0:self.cols]
        return np.column_stack([i.ravel(), j.ravel(), np.zeros(i.size)]) * self.square_mm

    def squares_extent(self) -> tuple[float, float, float, float]:
        """(x0, x1, y0, y1) mm of the checkered area in the board frame (outer squares included)."""
        s = self.square_mm
        return -s, self.cols * s, -s, self.rows * s

    def plate_extent(self) -> tuple[float, float, float, float]:
        x0, x1, y0, y1 = self.squares_extent()
        m = self.margin_mm
        return x0 - m, x1 + m, y0 - m, y1 + m


def _smooth_sign(u: np.ndarray, period: float, footprint: np.ndarray) -> np.ndarray:
    """Box-filtered square wave of half-period ``period`` (+1 on even cells), filter width ``footprint``."""
    m = np.mod(u, 2 * period)
    parity = np.where(m < period, 1.0, -1.0)
    edge = np.minimum(np.mod(u, period), period - np.mod(u, period))
    return parity * np.clip(edge / np.maximum(footprint, 1e-9) + 0.5, 0.0, 1.0) * 2 - parity


def board_surface(board: Board, R: np.ndarray, t: np.ndarray, fx: float) -> PlaneSurface:
    """The plate as a bounded plane in camera coordinates; X_cam = R @ X_board + t."""
    normal = R[:, 2]
    px0, px1, py0, py1 = board.plate_extent()
    sx0, sx1, sy0, sy1 = board.squares_extent()
    s = board.square_mm

    def to_board(points: np.ndarray) -> np.ndarray:
        return (points - t) @ R

    def inside(points: np.ndarray) -> np.ndarray:
        b = to_board(points)
        return (b[:, 0] >= px0) & (b[:, 0] <= px1) & (b[:, 1] >= py0) & (b[:, 1] <= py1)

    def albedo(points: np.ndarray) -> np.ndarray:
        b = to_board(points)
        fp = points[:, 2] / fx * 1.2  # pixel footprint on the plate, mm
        # the first inner corner sits between squares: cell (0, 0) starts at the corner
        checker = _smooth_sign(b[:, 0], s, fp) * _smooth_sign(b[:, 1], s, fp)
        a = (board.white + board.black) / 2 - (board.white - board.black) / 2 * checker
        in_sq = (b[:, 0] >= sx0) & (b[:, 0] <= sx1) & (b[:, 1] >= sy0) & (b[:, 1] <= sy1)
        return np.where(in_sq, a, board.white)

    return PlaneSurface(normal, float(normal @ t), "board", albedo, inside)


def _rot(ax: float, ay: float, az: float) -> np.ndarray:
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def sample_poses(board: Board, rig: Rig, n: int, rng: np.random.Generator, dist_range=(800.0, 1300.0),
                 max_tilt_deg: float = 35.0) -> list[tuple[np.ndarray, np.ndarray]]:
    """``n`` board poses (R, t) with the board fully in view and every stripe on the checkered area.

    Poses spread over the distance range and over tilt directions (Zhang's method needs varied tilts).
    """
    poses: list[tuple[np.ndarray, np.ndarray]] = []
    tries = 0
    while len(poses) < n:
        tries += 1
        if tries > 20000:
            raise RuntimeError("cannot place the board: rig geometry leaves no valid pose")
        k = len(poses)
        # stratified over distance; a slot that keeps failing falls back to the middle of the range
        frac = (k + rng.uniform()) / n if tries < 300 * (k + 1) else rng.uniform(0.25, 0.75)
        dist = dist_range[0] + (dist_range[1] - dist_range[0]) * frac
        tilt = np.deg2rad(rng.uniform(10, max_tilt_deg))
        phi = 2 * np.pi * (k / n) + rng.uniform(-0.4, 0.4)
        R = _rot(tilt * np.sin(phi), tilt * np.cos(phi), np.deg2rad(rng.uniform(-8, 8)))
        centre_b = np.array([(board.cols - 1) * board.square_mm / 2, (board.rows - 1) * board.square_mm / 2, 0])
        aim_x = rig.projector.centre_cam[0] * (1 - dist / 1150.0)  # where the pattern's middle falls
        centre_c = np.array([aim_x + rng.uniform(-0.03, 0.03) * dist, rng.uniform(-0.04, 0.04) * dist, dist])
        t = centre_c - R @ centre_b
        if _pose_ok(board, rig, R, t):
            poses.append((R, t))
    return poses


def _pose_ok(board: Board, rig: Rig, R: np.ndarray, t: np.ndarray) -> bool:
    intr: Intrinsics = rig.intrinsics
    w, h = intr.image_size
    x0, x1, y0, y1 = board.squares_extent()
    corners = np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0]])
    cam = corners @ R.T + t
    if (cam[:, 2] < 300).any() or R[2, 2] <= 0.2:  # must face the camera
        return False
    uv = project(cam, intr)
    border = 0.012 * w
    if (uv[:, 0] < border).any() or (uv[:, 0] > w - border).any() or (uv[:, 1] < border).any() or (
            uv[:, 1] > h - border).any():
        return False
    # every stripe must cross the plate (inside its margin) at the top, middle and bottom rows of corners
    planes = rig.projector.planes_cam()
    n_b = planes[:, :3] @ R  # plane normal in board coordinates
    d_b = planes[:, 3] - planes[:, :3] @ t
    s = board.square_mm
    for y in (0.0, (board.rows - 1) * s / 2, (board.rows - 1) * s):
        x = (d_b - n_b[:, 1] * y) / n_b[:, 0]
        if (x < x0 - 0.6 * board.margin_mm).any() or (x > x1 + 0.6 * board.margin_mm).any():
            return False
        pts = np.column_stack([x, np.full_like(x, y), np.zeros_like(x)]) @ R.T + t
        pp = rig.projector.to_proj(pts)
        if (np.abs(pp[:, 1] / pp[:, 2]) > rig.projector.half_height * 0.95).any():
            return False
    # the projector must light the plate's front side
    if (rig.projector.centre_cam - t) @ R[:, 2] >= 0:
        return False
    return True
