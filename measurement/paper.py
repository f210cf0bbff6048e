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



def boundaries_literal(binary: np.ndarray, window: int, ratio_threshold: float) -> list[tuple[int, int, int]]:
    """Algorithm 2 on a 0/1 image exactly as written: forward pass for right boundaries, mirrored pass
    for left ones (left = image.cols - temp boundary), paired in order. Returns [(row, left, right)]."""
    h, w = binary.shape
    out = []
    for i in range(h):
        row = [int(x) for x in binary[i]]
        right = _boundaries_inclusive(row, window, ratio_threshold)
        temp = _boundaries_inclusive(row[::-1], window, ratio_threshold)
        left = sorted(w - t for t in temp)
        out += [(i, lb, rb) for lb, rb in zip(left, right, strict=False)]
    return out


def _boundaries_inclusive(row: list[int], window: int, ratio_threshold: float) -> list[int]:
    """One pass of Algorithm 2 over every window position j = window .. cols - window."""
    out = []
    flag = False
    for j in range(window, len(row) - window + 1):
        a = sum(row[j - window:j])
        c = sum(row[j:j + window])
        m = (a + c) / (2.0 * window)
        total = m * (1 - m)
        ratio = ((a - c) / window) ** 2 / 4.0 / total if total > 0 else 0.0
        if not flag and a < c and ratio > ratio_threshold:
            flag = True
        elif flag and a > c and ratio > ratio_threshold:
            out.append(j)
            flag = False
    return out


def match_paper(u: np.ndarray, v: np.ndarray, n: int) -> np.ndarray:
    """Algorithm 3's matching as written: the first row holding exactly ``n`` centres is the main centre
    line; walking up and then down from it, each centre takes the index of the nearest reference column,
    and the references follow the matched centres (unmatched ones move by the row's mean offset).

    u : (M,) float px, v : (M,) int rows (any order); returns labels (M,) int64, -1 if unmatched.
    """
    labels = np.full(len(u), -1, np.int64)
    rows = np.unique(v)
    groups = {int(r): np.flatnonzero(v == r) for r in rows}
    main = next((int(r) for r in rows if len(groups[int(r)]) == n), None)
    if main is None:
        return labels
    idx = groups[main][np.argsort(u[groups[main]])]
    labels[idx] = np.arange(n)
    spacing = float(np.median(np.diff(u[idx]))) if n > 1 else 1.0
    for direction in (-1, 1):
        ref = u[idx].astype(np.float64).copy()
        for r in range(main + direction, (rows[0] - 1) if direction < 0 else (rows[-1] + 1), direction):
            members = groups.get(r)
            if members is None or len(members) == 0:
                continue
            d = u[members][:, None] - ref[None, :]
            k = np.abs(d).argmin(axis=1)
            ok = np.abs(d[np.arange(len(members)), k]) < spacing / 2
            labels[members[ok]] = k[ok]
            if ok.any():  # offset tracking: matched references follow, the others move by the mean offset
                shift = np.zeros(n)
                np.add.at(shift, k[ok], d[np.arange(len(members)), k][ok])
                hit = np.zeros(n, bool)
                hit[k[ok]] = True
                ref = ref + np.where(hit, shift, shift[hit].mean())
    return labels
