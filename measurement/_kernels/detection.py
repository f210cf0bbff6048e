"""Peak listing and sub-pixel refinement of stripe centres (``measurement.detection``): one pass over the
candidates instead of more full-frame masks and (window, peak) arrays. Integer arithmetic throughout, so
the centres are those of the NumPy form to the bit (tests/test_detection_kernels.py)."""

from __future__ import annotations

import numpy as np

from .jit import compiled


@compiled
def _rising(s, j, w):
    """Whether flat pixel j of s (h, w) is strictly brighter than its left neighbour (never column 0)."""
    y = j // w
    x = j - y * w
    return x > 0 and s[y, x] > s[y, x - 1]


@compiled
def first_peaks(mask, s):
    """Flat indices (K,) int64, in raster order, of the pixels marked in ``mask`` (h, w) uint8 0/1 that
    are strictly brighter than their left neighbour in s (h, w) uint8: the first pixel of a flat top."""
    w = s.shape[1]
    flat = mask.reshape(-1)
    words = flat[: len(flat) // 8 * 8].view(np.uint64)  # eight pixels at a time: the mask is sparse
    out = np.empty(len(flat) // 2 + 1, np.int64)  # a rising pixel's right neighbour is never a peak too
    k = 0
    for q in range(len(words)):
        if words[q] == 0:
            continue
        for j in range(8 * q, 8 * q + 8):
            if flat[j] and _rising(s, j, w):
                out[k] = j
                k += 1
    for j in range(len(words) * 8, len(flat)):
        if flat[j] and _rising(s, j, w):
            out[k] = j
            k += 1
    return out[:k].copy()


@compiled
def refine_peaks(s, bg, at, half, row0, strong=np.inf):
    """The peaks at flat indices ``at`` (K,) (raster order) of s (h, w) uint8 over the background bg (h, w)
    uint8 (bg <= s), one per peak: x, y (P,) int64 pixels (y counted from ``row0``); u (P,) float64, the
    centroid column of the run of pixels through the peak above half its height (twice the height above
    the level half way from bg to the peak, integers: the exact ratio), within +-``half`` pixels, the row's
    end pixel repeated past the border; that run's width (P,) float32; the flank (P,) float32, the peak's
    height above the higher of its side minima (within half - 1 pixels each side); the contrast s - bg
    (P,) float32. A peak whose centroid lies less than half a pixel right of the previous one's in its row
    is the other half of a flat top cut by a one-level dip (the same centroid): it is left out.

    ``strong`` : a contrast above which a peak is a centre, the others faint (``detection.faint``). The
    strong peaks are then weighed against each other only, so they come out as they do when the faint ones
    are not listed at all (``at`` without them); a faint peak is left out as the other half of a strong
    one's flat top, before it or after it. With the default every peak is weighed against every other."""
    w = s.shape[1]
    n = len(at)
    x_out, y_out = np.empty(n, np.int64), np.empty(n, np.int64)
    u = np.empty(n)
    width = np.empty(n, np.float32)
    flank = np.empty(n, np.float32)
    contrast = np.empty(n, np.float32)
    pad = np.empty(2 * half + 1, np.uint8)
    p = 0
    last_y, last_u = -1, 0.0  # the previous peak (strong ones: the previous strong peak)
    any_y, any_u = -1, 0.0  # the previous peak of either kind
    for i in range(n):
        y = at[i] // w
        x = at[i] - y * w
        raw = s[y, x - half:x + half + 1]
        if x < half or x + half >= w:
            for k in range(2 * half + 1):
                pad[k] = s[y, min(max(x - half + k, 0), w - 1)]
            raw = pad
        peak, back = np.int64(raw[half]), np.int64(bg[y, x])
        num, den, run = _run_moments(raw, half, back + peak)
        ui = x + num / max(den, 1)
        is_strong = peak - back > strong
        if is_strong or strong == np.inf:
            repeat = y == last_y and ui - last_u < 0.5
            last_y, last_u = y, ui
        else:
            repeat = y == any_y and ui - any_u < 0.5
        any_y, any_u = y, ui
        if repeat:
            continue
        # a strong peak takes the place of a faint first half of its flat top
        at_p = p
        if is_strong and p > 0 and y_out[p - 1] == y + row0 and contrast[p - 1] <= strong and ui - u[p - 1] < 0.5:
            at_p = p - 1
        left, right = peak, peak
        for k in range(1, half):
            left = min(left, np.int64(raw[k]))
            right = min(right, np.int64(raw[half + k]))
        x_out[at_p], y_out[at_p], u[at_p], width[at_p] = x, y + row0, ui, run
        flank[at_p], contrast[at_p] = peak - max(left, right), peak - back
        p = at_p + 1
    return x_out[:p], y_out[:p], u[:p], width[:p], flank[:p], contrast[:p]


@compiled
def _run_moments(raw, half, level):
    """Sum of offset x weight, sum of weights and length of the run through the centre of the window raw
    (2 half + 1,) where the weight 2 raw - level stays positive."""
    h2 = 2 * np.int64(raw[half]) - level
    if h2 <= 0:
        return 0, 0, 0
    num, den, run = 0, h2, 1
    for sign in (1, -1):
        for k in range(1, half + 1):
            h2 = 2 * np.int64(raw[half + sign * k]) - level
            if h2 <= 0:
                break
            num += sign * k * h2
            den += h2
            run += 1
    return num, den, run


@compiled
def difference_counts(g, row_step, col_step):
    """Counts (256,) int64 of |g[r + 1, c] - g[r, c]| over rows r = 0, row_step, ... < h - 1 and columns
    c = 0, col_step, ... of the gray image g (h, w) uint8: ``detection.noise_sigma``'s sample."""
    counts = np.zeros(256, np.int64)
    h, w = g.shape
    for r in range(0, h - 1, row_step):
        for c in range(0, w, col_step):
            counts[abs(np.int64(g[r + 1, c]) - np.int64(g[r, c]))] += 1
    return counts


@compiled
def sample_levels(g, step, bright):
    """Over g[::step, ::step] of the gray image g (h, w) uint8: how many pixels are at least ``bright``,
    the least and the greatest level, and how many pixels there are (``detection.check_image``'s sample)."""
    h, w = g.shape
    count, lo, hi, n = 0, 255, 0, 0
    for r in range(0, h, step):
        for c in range(0, w, step):
            x = np.int64(g[r, c])
            count += x >= bright
            lo = min(lo, x)
            hi = max(hi, x)
            n += 1
    return count, lo, hi, n


@compiled
def shaded_centroids(s, x, y, row0, reach, floor):
    """Centroid columns (P,) float64 of the peaks at pixels (``x``, ``y``) (P,) int64 (``y`` counted from
    ``row0``) of s (h, w) uint8, with the light under each stripe that is not the stripe's own divided out:
    ``detection.shaded_centre``, peak by peak (its docstring gives the model). ``reach``: how far each side
    of the peak the flanks are looked for, pixels (not bounded by the next peak in the row: fur's specks
    make peaks a few pixels off a stripe, and bounded there the flanks' line came out wrong; on the cached
    views 0.1-1 % fewer points within 2 mm); ``floor``: gray levels added to the flanks' line before
    dividing by it. Only the pixels the centroid weighs are divided."""
    w = s.shape[1]
    n = len(x)
    out = np.empty(n)
    for i in range(n):  # (s[r, k], not a row view: a view per peak cost a fifth of the time)
        r = y[i] - row0
        xi = x[i]
        a, b = max(xi - reach, 0), min(xi + reach, w - 1)
        il, low = a, s[r, a]  # the flanks: the darkest pixel each side (the first of equals from the outside in)
        for k in range(a + 1, xi):
            if s[r, k] < low:
                low, il = s[r, k], k
        ir, low = b, s[r, b]
        for k in range(b - 1, xi, -1):
            if s[r, k] < low:
                low, ir = s[r, k], k
        if il >= xi or ir <= xi:  # the peak at the row's end: no flank on one side
            out[i] = xi
            continue
        left = float(s[r, il])
        slope = (float(s[r, ir]) - left) / (ir - il)
        base = left + slope * (xi - il)
        top = (float(s[r, xi]) - base) / (base + floor)
        if not top > 0:
            out[i] = xi
            continue
        level = 0.5 * top
        num, den = 0.0, top - level
        for sign in (-1, 1):  # the run through the peak, each way to where the ratio falls to its half
            k = xi + sign
            while il < k < ir:
                base = left + slope * (k - il)
                q = (float(s[r, k]) - base) / (base + floor) - level
                if not q > 0:
                    break
                num += (k - xi) * q
                den += q
                k += sign
        out[i] = xi + num / den
    return out
