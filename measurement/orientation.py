"""Which way the stripes run in the image, and the transposed frame a rig with horizontal stripes is
measured in.

The paper's rig has its projector beside the camera: the stripes run down the image and every step
(board stripes, the gray-centre detector, denoising, matching) reads the image row by row. A projector
mounted above or below the camera, or a camera turned on its side to fit a standing animal, gives
stripes that run across the image. Such a rig is calibrated and scanned in the transposed image (its
rows are the original's columns), whose camera frame has x and y swapped: rays, planes and points are
swapped back on the way out, and every distance is the same in both frames.
"""

from __future__ import annotations

import cv2
import numpy as np

from .images import to_gray

AXES = ("vertical", "horizontal")


def stripe_axis(stripes: np.ndarray, background: np.ndarray | None = None) -> str:
    """``"vertical"`` when the stripes of ``stripes`` (H, W) or (H, W, C) run closer to the image's columns,
    ``"horizontal"`` when closer to its rows: from the energy of the brightness changes across and along
    the rows of the stripe light, at a quarter of the resolution. ``background`` : the same view without
    the stripes (the board image of a calibration pose), subtracted first so that the chessboard's own
    edges do not count."""
    img = to_gray(stripes).astype(np.float32)
    if background is not None and background.shape[:2] == img.shape:
        img -= to_gray(background).astype(np.float32)
    small = cv2.resize(img, (max(1, img.shape[1] // 4), max(1, img.shape[0] // 4)), interpolation=cv2.INTER_AREA)
    across = cv2.Sobel(small, cv2.CV_32F, 1, 0, ksize=3)  # changes along a row: stripes that run down
    along = cv2.Sobel(small, cv2.CV_32F, 0, 1, ksize=3)
    return "vertical" if float(np.sum(across * across)) >= float(np.sum(along * along)) else "horizontal"


def transpose_image(img: np.ndarray) -> np.ndarray:
    """The image (H, W[, C]) with rows and columns swapped, C-contiguous: (W, H[, C])."""
    return np.ascontiguousarray(np.swapaxes(np.asarray(img), 0, 1))


def swap_xy(a: np.ndarray) -> np.ndarray:
    """Points (N, 3) or planes (N, 4) with their x and y (normal) components swapped: the same geometry in
    the transposed camera frame (and back)."""
    a = np.asarray(a)
    order = [1, 0] + list(range(2, a.shape[-1]))
    return np.ascontiguousarray(a[..., order])
