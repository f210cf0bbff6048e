"""Pinhole camera with OpenCV lens distortion: projection, undistortion and viewing rays."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12)
_EYE = np.eye(3)


@dataclass(frozen=True, eq=False)
class Intrinsics:
    """Camera intrinsics in OpenCV's model.

    camera_matrix : (3, 3) float64, pixels
    dist_coeffs   : (5,) float64, (k1, k2, p1, p2, k3), or OpenCV's longer models as given: (8,) adds the
                    rational k4-k6, (12,) the thin prism s1-s4, (14,) the tilt tauX, tauY
    image_size    : (width, height), pixels
    """

    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    image_size: tuple[int, int]

    @property
    def fx(self) -> float:
        return float(self.camera_matrix[0, 0])

    @property
    def fy(self) -> float:
        return float(self.camera_matrix[1, 1])

    @property
    def cx(self) -> float:
        return float(self.camera_matrix[0, 2])

    @property
    def cy(self) -> float:
        return float(self.camera_matrix[1, 2])

    def to_dict(self) -> dict:
        return {
            "image_size": [int(self.image_size[0]), int(self.image_size[1])],
            "camera_matrix": self.camera_matrix.tolist(),
            "dist_coeffs": self.dist_coeffs.ravel().tolist(),
        }

    @classmethod
    def from_dict(cls, d: dict) -> Intrinsics:
        """From a calibration's fields; ValueError names a malformed one. Distortion models of 0 or 4
        coefficients are padded to 5, those of 8, 12 or 14 (another tool's rational, thin-prism or tilted
        model) kept whole: cutting them to 5 moved the rays of a wide-angle camera's image corners."""
        K = np.asarray(d["camera_matrix"], dtype=np.float64).reshape(3, 3)
        given = np.asarray(d["dist_coeffs"], dtype=np.float64).ravel()
        if given.size not in (0, 4, 5, 8, 12, 14):
            raise ValueError(f"dist_coeffs: {given.size} coefficients; OpenCV's models have 4, 5, 8, 12 or 14")
        if not (np.isfinite(K).all() and np.isfinite(given).all()):
            raise ValueError("camera_matrix and dist_coeffs must be finite numbers")
        if K[0, 0] <= 0 or K[1, 1] <= 0:
            raise ValueError("camera_matrix: the focal lengths fx, fy must be positive")
        dist = np.pad(given, (0, 5 - given.size)) if given.size < 5 else given
        w, h = d["image_size"]
        if int(w) <= 0 or int(h) <= 0:
            raise ValueError(f"image_size: {w}x{h} is not an image size")
        return cls(K, dist, (int(w), int(h)))


def project(points_cam: np.ndarray, intr: Intrinsics) -> np.ndarray:
    """Project camera-frame points to distorted pixels.

    points_cam : (N, 3) float64, mm, z > 0
    returns    : (N, 2) float64, pixels (u, v)
    """
    pts = np.asarray(points_cam, dtype=np.float64).reshape(-1, 1, 3)
    if pts.shape[0] == 0:
        return np.zeros((0, 2))
    uv, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), intr.camera_matrix, intr.dist_coeffs)
    return uv.reshape(-1, 2)


def undistort(uv: np.ndarray, intr: Intrinsics) -> np.ndarray:
    """Distorted pixels to ideal normalised image coordinates (x, y) with z = 1.

    uv      : (N, 2) float, pixels
    returns : (N, 2) float64, normalised (dimensionless)
    """
    pts = np.asarray(uv, dtype=np.float64).reshape(-1, 1, 2)
    if pts.shape[0] == 0:
        return np.zeros((0, 2))
    xy = cv2.undistortPoints(
        pts, intr.camera_matrix, intr.dist_coeffs, R=_EYE, P=_EYE, criteria=_UNDISTORT_CRITERIA
    )
    return xy.reshape(-1, 2)


def rays(uv: np.ndarray, intr: Intrinsics) -> np.ndarray:
    """Viewing rays through distorted pixels, scaled so that z = 1 (eq. 5 of the paper, after undistortion).

    uv      : (N, 2) float, pixels
    returns : (N, 3) float64, direction with z = 1
    """
    xy = undistort(uv, intr)
    return np.column_stack([xy, np.ones(len(xy))])


def ray_grid(intr: Intrinsics) -> np.ndarray:
    """Normalised (x, y) of every pixel centre by exact iterative undistortion (about 2 s at 6 MP).

    returns : (H, W, 2) float64 normalised coordinates
    """
    w, h = intr.image_size
    uu, vv = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    return undistort(np.column_stack([uu.ravel(), vv.ravel()]), intr).reshape(h, w, 2)
