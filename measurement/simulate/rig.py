"""Geometry of the simulated rig: a distorted pinhole camera and a pinhole stripe projector beside it."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..camera import Intrinsics

PIXEL_MM = 0.0024  # 2.4 um pixels (Hikvision MV-CA060-11GM, Table 2 of the paper)
FOCAL_MM = 8.0
FULL_WIDTH = 3072


@dataclass(frozen=True, eq=False)
class Projector:
    """A pinhole projector casting N vertical stripes; each stripe is the plane x_p = stripe_x[k] * z_p.

    R_proj_cam, t_proj_cam : (3, 3), (3,) mm; X_proj = R_proj_cam @ X_cam + t_proj_cam
    stripe_x     : (N,) projector-normalised x of each stripe centre, increasing left to right in the camera
    sigma        : stripe half-width (Gaussian sigma) at focus, projector-normalised units
    focus_mm     : distance of best focus; defocus_per_mm widens sigma away from it
    half_height  : vertical extent of the pattern, projector-normalised (|y_p| below it is lit)
    power        : irradiance scale (gray levels on a white surface at 1 m, facing the projector)
    """

    R_proj_cam: np.ndarray
    t_proj_cam: np.ndarray
    stripe_x: np.ndarray
    sigma: float = 0.0009
    focus_mm: float = 1100.0
    defocus_per_mm: float = 1.1e-6
    half_height: float = 0.32
    power: float = 190.0

    @property
    def centre_cam(self) -> np.ndarray:
        """Projector centre in camera coordinates, (3,) mm."""
        return -self.R_proj_cam.T @ self.t_proj_cam

    def to_proj(self, points_cam: np.ndarray) -> np.ndarray:
        """(..., 3) camera-frame mm -> (..., 3) projector-frame mm."""
        return points_cam @ self.R_proj_cam.T + self.t_proj_cam

    def planes_cam(self) -> np.ndarray:
        """True light planes in camera coordinates, (N, 4) rows [nx, ny, nz, d] with n.X = d, |n| = 1.

        Normals are oriented so that n_x > 0 (d then grows left to right in the image)."""
        n_p = np.column_stack([np.ones_like(self.stripe_x), np.zeros_like(self.stripe_x), -self.stripe_x])
        n_p /= np.linalg.norm(n_p, axis=1, keepdims=True)
        n_c = n_p @ self.R_proj_cam  # R^T n_p for each row
        d = -(n_p @ self.t_proj_cam)
        sign = np.sign(n_c[:, 0:1])
        return np.column_stack([n_c * sign, d[:, None] * sign])


@dataclass(frozen=True, eq=False)
class Rig:
    """Camera intrinsics plus projector: everything fixed once the rig is built."""

    intrinsics: Intrinsics
    projector: Projector


def default_rig(size: tuple[int, int] = (3072, 2048), stripes: int = 40, baseline_mm: float = 250.0,
                aim_mm: float = 1150.0, roll_deg: float = 0.0) -> Rig:
    """The reference rig: 8 mm lens on 2.4 um pixels (scaled to ``size``), projector ``baseline_mm`` to the
    right, toed in to meet the camera axis at ``aim_mm``; ``stripes`` stripes over a fixed fan (about 13 mm
    apart at 1.25 m for 40 stripes). ``roll_deg``: the projector turned about its own axis (its stripes
    then slant in the image; positive turns them clockwise as the camera sees them)."""
    w, h = size
    scale = w / FULL_WIDTH
    f = FOCAL_MM / PIXEL_MM * scale
    K = np.array([[f, 0.0, w * 0.5 + 0.0125 * w], [0.0, f * 1.0004, h * 0.5 - 0.0117 * h], [0.0, 0.0, 1.0]])
    dist = np.array([-0.108, 0.094, 4.5e-4, -3.2e-4, -0.031])
    intr = Intrinsics(K, dist, (int(w), int(h)))
    yaw = np.arctan2(baseline_mm, aim_mm)  # rotate the projector axis toward the camera axis
    pitch = np.deg2rad(1.5)
    R_yaw = np.array([[np.cos(yaw), 0, np.sin(yaw)], [0, 1, 0], [-np.sin(yaw), 0, np.cos(yaw)]])
    R_pitch = np.array([[1, 0, 0], [0, np.cos(pitch), -np.sin(pitch)], [0, np.sin(pitch), np.cos(pitch)]])
    roll = np.deg2rad(roll_deg)
    R_roll = np.array([[np.cos(roll), -np.sin(roll), 0], [np.sin(roll), np.cos(roll), 0], [0, 0, 1]])
    R = R_roll @ R_pitch @ R_yaw
    centre = np.array([baseline_mm, -12.0, 8.0])
    t = -R @ centre
    spacing = 0.0105 * 39 / max(stripes - 1, 1)
    stripe_x = (np.arange(stripes) - (stripes - 1) / 2) * spacing
    return Rig(intr, Projector(R, t, stripe_x))
