"""The paper's Algorithm 2 (gray-centre detection) written literally, pixel by pixel, as the measured
baseline for speed. Not used by the pipeline (``detection`` computes the same kind of centres with
vectorised filters)."""

from __future__ import annotations

import numpy as np


def gray_centres_literal(image: np.ndarray, window: int = 5, binary_threshold: int = 40,
                         variance_ratio: float = 0.5) -> list[tuple[int, float]]:
    """Algorithm 2: binarise, slide a left and a right window along each row, a rising edge where the
    left mean is below the right one and their between-group variance ratio exceeds the threshold, a
    falling edge the other way round; the mirrored pass finds left boundaries; centre = their mean.

    image : (H, W) uint8; returns [(row, centre column)] in pixels.
    """
    h, w = image.shape
    binary = [[255 if image[i, j] > binary_threshold else 0 for j in range(w)] for i in range(h)]
    centres = []
    for i in range(h):
        row = binary[i]
        right = _boundaries(row, window, variance_ratio)
        mirrored = _boundaries(row[::-1], window, variance_ratio)
        left = sorted(w - 1 - b for b in mirrored)
        for lb in left:
            rb = next((r for r in right if r >= lb), None)
            if rb is not None:
                centres.append((i, (lb + rb) / 2.0))
    return centres


def _boundaries(row: list[int], window: int, ratio_threshold: float) -> list[int]:
    """Right boundaries of bright runs along one row (one pass of Algorithm 2)."""
    out = []
    flag = False
    for j in range(window, len(row) - window):
        left = row[j - window:j]
        right = row[j:j + window]
        ml = sum(left) / window
        mr = sum(right) / window
        total = left + right
        mean = sum(total) / len(total)
        var = sum((x - mean) ** 2 for x in total) / len(total)
        between = ((ml - mean) ** 2 + (mr - mean) ** 2) / 2
        ratio = between / var if var > 0 else 0.0
        if not flag and ml < mr and ratio > ratio_threshold:
            flag = True
        elif flag and ml > mr and ratio > ratio_threshold:
            out.append(j)
            flag = False
    return out

