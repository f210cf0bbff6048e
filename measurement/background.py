"""The background (floor, wall) of a scan: its planes, which centres lie on them, and which pieces of
stripe one index puts on them."""

from __future__ import annotations

import numpy as np

from .segments import link_segments, split_at_changes
from .triangulation import depth_for_labels, intersect


def background_planes(rays: np.ndarray, planes: np.ndarray, labels: np.ndarray, tol_mm: float = 8.0,
                       max_planes: int = 2) -> np.ndarray | None:
    """The dominant planes (floor, wall) of the labelled cloud, (P, 4); None when no plane carries a fifth
    of it (no planar background to separate from)."""
    from .planes import fit_plane_robust

    idx = np.nonzero(labels >= 0)[0]
    if len(idx) < 200:
        return None
    pts = intersect(rays[idx], planes[labels[idx]])
    found = []
    rest = np.ones(len(idx), bool)
    rng = np.random.default_rng(0)
    for _ in range(max_planes):
        cand = np.nonzero(rest)[0]
        if len(cand) < 200:
            break
        plane, _ = fit_plane_robust(pts[cand], rng, iterations=300, inlier_mm=tol_mm / 2)
        near = np.abs(pts @ plane[:3] - plane[3]) < tol_mm
        if near[rest].sum() < 0.2 * len(idx):
            break
        found.append(plane)
        rest &= ~near
    return np.array(found) if found else None


def near_planes(points: np.ndarray, bg_planes: np.ndarray, tol_mm: float = 8.0) -> np.ndarray:
    """(M,) True where a point lies within ``tol_mm`` of any background plane."""
    d = np.abs(points @ bg_planes[:, :3].T - bg_planes[:, 3])
    return np.nan_to_num(d, nan=np.inf).min(axis=1) < tol_mm


def on_plane_fractions(rays: np.ndarray, planes: np.ndarray, bg_planes: np.ndarray, tol_mm: float
                        ) -> np.ndarray:
    """(N,) share of the rays (m, 3) whose point on light plane k lies within ``tol_mm`` of a background
    plane, for every k at once."""
    z = depth_for_labels(rays, planes)  # (m, N)
    pts = rays[:, None, :] * z[:, :, None]  # (m, N, 3)
    d = np.abs(pts @ bg_planes[:, :3].T - bg_planes[:, 3]).min(axis=2)
    return (np.nan_to_num(d, nan=np.inf) < tol_mm).mean(axis=0)


def claim_background(c, rays, planes, seg, seg_label, long_seg, bg_planes, n, min_rows: int = 15,
                      share: float = 0.95, tol_mm: float = 5.0) -> dict[int, int]:
    """Unlabelled segments that exactly one stripe index puts on a background plane (>= ``share`` of
    their points within ``tol_mm``); animal stripes are curved and fit no single plane that way."""
    labelled = np.zeros(seg.max() + 1, bool)
    labelled[list(seg_label)] = True
    cand = long_seg & ~labelled[seg]
    sizes = np.bincount(seg[cand], minlength=seg.max() + 1)
    out = {}
    for sid in np.nonzero(sizes >= min_rows)[0]:
        frac = on_plane_fractions(rays[seg == sid], planes, bg_planes, tol_mm)
        hits = np.nonzero(frac >= share)[0]
        if len(hits) == 1:
            out[int(sid)] = int(hits[0])
    return out


def background_like(rays, planes, seg, mask, bg_planes, exclude: set, share: float = 0.8) -> np.ndarray:
    """(M,) True for centres of segments (in ``mask``, not in ``exclude``) that some stripe index puts
    on a background plane for at least ``share`` of their points."""
    out = np.zeros(len(seg), bool)
    for sid in np.unique(seg[mask]):
        if int(sid) in exclude:
            continue
        idx = np.nonzero(seg == sid)[0]
        if on_plane_fractions(rays[idx], planes, bg_planes, 8.0).max() >= share:
            out[idx] = True
    return out


def segment_on_planes(rays, planes, seg, sid, k, bg_planes, share: float = 0.9) -> bool:
    idx = np.nonzero(seg == sid)[0]
    pts = intersect(rays[idx], planes[np.full(len(idx), k)])
    return bool(near_planes(pts, bg_planes).mean() >= share)


def split_foreground(c, seg, labels, on_bg, link, min_rows):
    """Unlabel centres off the background and re-link them into their own segments."""
    m = len(seg)
    fg = (labels < 0) | ~on_bg
    # near the junction of a merged segment the last background-looking centres are suspect too
    mixed = np.unique(seg[fg & (labels >= 0)])
    for s in mixed:
        idx = np.nonzero(seg == s)[0]
        fv = c.v[idx][fg[idx]]
        if len(fv) == 0:
            continue
        gap = np.min(np.abs(c.v[idx][:, None].astype(np.int64) - fv[None, :].astype(np.int64)), axis=1)
        fg[idx[gap <= 15]] = True
    fg_idx = np.nonzero(fg)[0]
    sub = c.take(fg)
    fseg = split_at_changes(sub, link_segments(sub, link)) if len(fg_idx) else np.zeros(0, np.int64)
    new = seg.copy()
    new[fg_idx] = fseg + seg.max() + 1
    long_seg = np.zeros(m, bool)
    long_seg[~fg] = np.bincount(seg[~fg])[seg[~fg]] >= min_rows if (~fg).any() else False
    if len(fg_idx):
        long_seg[fg_idx] = np.bincount(fseg)[fseg] >= min_rows
    seg_label = {int(s): int(k) for s, k in zip(new[~fg], labels[~fg], strict=True) if k >= 0}
    return new, long_seg, seg_label
