"""Reading the simulator's ground truth back: which true stripe crossing a detected centre corresponds to."""

from __future__ import annotations

import numpy as np


def nearest_crossings(uv: np.ndarray, truth: dict) -> tuple[np.ndarray, np.ndarray]:
    """For pixels ``uv`` (M, 2): the index (M,) into ``truth``'s crossings of the one in the same image row
    nearest in column, and its distance in columns (M,) px (any row's crossing may be the nearest where a row
    holds none). truth : a ``<view>_stripes.npz`` loaded as a dict (points, stripe, uv, kind)"""
    order = np.lexsort((truth["uv"][:, 0], np.rint(truth["uv"][:, 1])))
    key = np.rint(truth["uv"][order, 1]) * 1e5 + truth["uv"][order, 0]
    q = np.rint(uv[:, 1]) * 1e5 + uv[:, 0]
    idx = np.clip(np.searchsorted(key, q), 1, len(key) - 1)
    cand = np.stack([idx - 1, idx], 1)
    d = np.abs(key[cand] - q[:, None])
    return order[cand[np.arange(len(q)), d.argmin(1)]], d.min(1)


def match_crossings(uv: np.ndarray, truth: dict, max_px: float = 1.5) -> tuple[np.ndarray, np.ndarray]:
    """Truth stripe index and surface kind for pixels ``uv`` (M, 2): the exact crossing in the same
    image row nearest in column, within ``max_px``; (-1, 0) where there is none.

    truth : a ``<view>_stripes.npz`` loaded as a dict (points, stripe, uv, kind)
    """
    best, d = nearest_crossings(uv, truth)
    near = d < max_px
    return np.where(near, truth["stripe"][best], -1), np.where(near, truth["kind"][best], 0)
