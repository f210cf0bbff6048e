"""Shared by the benchmarks: render a capture once into the cache, label one view of it and score it
against the simulator's exact crossings."""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import measurement.matching as matching
from measurement.calibration import Calibration, load_calibration
from measurement.detection import Centres, detect_centres, detect_centres_and_faint
from measurement.images import read_image
from measurement.matching import denoise, label_centres
from measurement.pipeline import ScanParams
from measurement.simulate.capture import write_capture
from measurement.simulate.truth import match_crossings
from measurement.triangulation import ray_table, rays_and_cells, rays_at

ANIMAL = 5
VIEWS = ("side", "top")


@dataclass
class ScanInput:
    """What the scan labels in one cached view, made as ``pipeline.scan`` makes it: the calibration (the
    simulator's true one), the frame's shape, the faint-peak detector's centres denoised, and their rays."""

    cal: Calibration
    shape: tuple[int, ...]
    centres: Centres
    rays: np.ndarray


def scan_input(cap: Path, view: str) -> ScanInput:
    """``ScanInput`` of a cached view (no ambient image; the true calibration's camera is linear)."""
    cal = load_calibration(cap / "truth" / "truth.json")
    img = read_image(cap / "scan" / f"{view}.png")
    c, _ = detect_centres_and_faint(img, ScanParams().detection, None)
    c = c.take(denoise(c, img.shape[:2]))
    return ScanInput(cal, img.shape[:2], c, rays_and_cells(c.u, c.v, ray_table(cal.intrinsics, cal.transposed))[0])


def captures_main(doc: str | None, report, option: str, default: int, help_text: str) -> None:
    """The command line of a bench that reports on cached captures: CAPTURE [CAPTURE ...] [--view V] and one
    integer ``option``; calls ``report(capture, view, value)`` for each view a capture holds."""
    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("captures", nargs="+", type=Path)
    ap.add_argument("--view", choices=VIEWS, default=None, help="one view (default: both)")
    ap.add_argument(f"--{option}", type=int, default=default, help=help_text)
    args = ap.parse_args()
    for cap in args.captures:
        for view in (args.view,) if args.view else VIEWS:
            if (cap / "scan" / f"{view}.png").exists():
                report(cap, view, getattr(args, option))


def counts(values: np.ndarray) -> str:
    """``3x12 5x40``: each distinct value and how often it occurs."""
    ks, n = np.unique(values, return_counts=True)
    return " ".join(f"{k}x{c}" for k, c in zip(ks.tolist(), n.tolist(), strict=True))


def size_and_cache(doc: str | None, size: str = "1536x1024") -> tuple[tuple[int, int], Path]:
    """A bench's command line, --size WxH (default ``size``) and --cache DIR: the image size and the render
    cache."""
    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", default=size)
    ap.add_argument("--cache", default="/tmp/bodyscan-bench")
    args = ap.parse_args()
    w, h = (int(v) for v in args.size.split("x"))
    return (w, h), Path(args.cache)


def cached_capture(out: Path, post=None, views: tuple[str, ...] = VIEWS, **render) -> Path:
    """The ``views`` (a side and a top view by default; no calibration poses) rendered into ``out`` by
    ``write_capture(**render)`` unless the cache already holds them; ``post(out)`` runs once after a fresh
    render."""
    if not (out / "truth" / "truth.json").exists():
        t0 = time.perf_counter()
        write_capture(out, scenes=views, poses=0, **render)
        if post is not None:
            post(out)
        print(f"  rendered {out.name} in {time.perf_counter() - t0:.0f} s", flush=True)
    return out


@dataclass
class ViewLabels:
    """Scores of one view: share of the animal's crossings labelled, share of those right, background
    labels right, labelling time, per piece of the animal (centres, chosen offset, true offset), and the
    shift the whole-animal recheck gave every animal label afterwards (0: none)."""

    labelled: float
    right: float
    background_right: float
    ms: float
    pieces: list[tuple[int, int | None, int]]
    shift: int = 0


def label_view(cap: Path, view: str) -> ViewLabels:
    cal = load_calibration(cap / "truth" / "truth.json")
    img = read_image(cap / "scan" / f"{view}.png")
    c = detect_centres(img)
    c = c.take(denoise(c, img.shape))
    rays = rays_at(c.u, c.v, ray_table(cal.intrinsics))
    matching._TRACE = []
    t0 = time.perf_counter()
    lab = label_centres(c, rays, cal.planes, img.shape, view=view).stripe
    ms = 1000 * (time.perf_counter() - t0)
    trace, matching._TRACE = matching._TRACE, None
    truth, kind = match_crossings(np.column_stack([c.u, c.v]), dict(np.load(cap / "truth" / f"{view}_stripes.npz")))
    animal, bg = kind == ANIMAL, (kind == 2) | (kind == 3)
    got, bgot = animal & (lab >= 0), bg & (lab >= 0)
    pieces = []
    shift = 0
    for idx, rel, off in trace:
        if idx is None:
            shift = off
            continue
        ok = animal[idx] & (truth[idx] >= 0)
        if ok.sum() >= 20:
            vals, cnt = np.unique(truth[idx][ok] - rel[ok], return_counts=True)
            pieces.append((len(idx), off, int(vals[np.argmax(cnt)])))
    return ViewLabels(float(got.sum() / max(animal.sum(), 1)),
                      float(np.mean(lab[got] == truth[got])) if got.any() else float("nan"),
                      float(np.mean(lab[bgot] == truth[bgot])) if bgot.any() else float("nan"), ms, pieces,
                      shift)


def pieces_text(pieces: list[tuple[int, int | None, int]], shift: int = 0) -> str:
    text = "; ".join(f"{n}: {off} / {true}" for n, off, true in pieces)
    return f"{text}; then all {shift:+d}" if shift else text


def print_pieces(name: str, cap: Path, views: tuple[str, ...] = VIEWS) -> list[float]:
    """Label the ``views`` of ``cap``, print a row each (labelled, right, pieces) and return the shares right."""
    rights = []
    for view in views:
        v = label_view(cap, view)
        rights.append(v.right)
        print(f"{name:25s} {view:4s}  {v.labelled:8.1%}  {v.right:7.2%}   {pieces_text(v.pieces, v.shift)}", flush=True)
    return rights


def summary(rights: list[float]) -> str:
    r = np.array(rights)
    return f"animal labels right: median {np.nanmedian(r):.2%}; views at least 95 % right: {(r >= 0.95).sum()} of {len(r)}"
