"""Shared by the label benchmarks: label one view of a capture and score it against the simulator's
exact crossings."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import measurement.matching as matching
from measurement.calibration import load_calibration
from measurement.detection import detect_centres
from measurement.images import read_image
from measurement.matching import denoise, label_centres
from measurement.simulate.truth import match_crossings
from measurement.triangulation import ray_table, rays_at

ANIMAL = 5


@dataclass
class ViewLabels:
    """Scores of one view: share of the animal's crossings labelled, share of those right, background
    labels right, labelling time, and per piece of the animal (centres, chosen offset, true offset)."""

    labelled: float
    right: float
    background_right: float
    ms: float
    pieces: list[tuple[int, int | None, int]]


def label_view(cap: Path, view: str) -> ViewLabels:
    cal = load_calibration(cap / "truth" / "truth.json")
    img = read_image(cap / "scan" / f"{view}.png")
    c = detect_centres(img)
    c = c.take(denoise(c, img.shape))
    rays = rays_at(c.u, c.v, ray_table(cal.intrinsics))
    matching._TRACE = []
    t0 = time.perf_counter()
    lab = label_centres(c, rays, cal.planes, img.shape).stripe
    ms = 1000 * (time.perf_counter() - t0)
    trace, matching._TRACE = matching._TRACE, None
    truth, kind = match_crossings(np.column_stack([c.u, c.v]), dict(np.load(cap / "truth" / f"{view}_stripes.npz")))
    animal, bg = kind == ANIMAL, (kind == 2) | (kind == 3)
    got, bgot = animal & (lab >= 0), bg & (lab >= 0)
    pieces = []
    for idx, rel, off in trace:
        ok = animal[idx] & (truth[idx] >= 0)
        if ok.sum() >= 20:
            vals, cnt = np.unique(truth[idx][ok] - rel[ok], return_counts=True)
            pieces.append((len(idx), off, int(vals[np.argmax(cnt)])))
    return ViewLabels(float(got.sum() / max(animal.sum(), 1)),
                      float(np.mean(lab[got] == truth[got])) if got.any() else float("nan"),
                      float(np.mean(lab[bgot] == truth[bgot])) if bgot.any() else float("nan"), ms, pieces)


def pieces_text(pieces: list[tuple[int, int | None, int]]) -> str:
    return "; ".join(f"{n}: {off} / {true}" for n, off, true in pieces)
