"""Stripe-label correctness on other animals: the shared real meshes under the rig simulator.

    python bench/animals.py [--meshes /work/shared/meshes] [--size 1536x1024] [--cache /tmp/bodyscan-bench]

The issue's figures will also be checked on other animals than the procedural quadruped; this renders
the meshes in ``--meshes`` (fox, cow, horse, shiba-inu; a side and a top view each, fur or clean, 40 or 50
stripes) and reports, per view, the share of the animal's true crossings that got a label and the share
of those that are right, and per isolated piece of the animal the offset chosen against the true one.
Not part of the tests (they must not depend on ../shared).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import measurement.matching as matching  # noqa: E402
from measurement.calibration import load_calibration  # noqa: E402
from measurement.detection import detect_centres  # noqa: E402
from measurement.images import read_image  # noqa: E402
from measurement.matching import denoise, label_centres  # noqa: E402
from measurement.simulate.capture import write_capture  # noqa: E402
from measurement.simulate.truth import match_crossings  # noqa: E402
from measurement.triangulation import ray_table, rays_at  # noqa: E402

RENDERS = (("fox.obj", 40, True, 3), ("cow.obj", 40, True, 3), ("horse.ply", 50, False, 5),
           ("shiba-inu.obj", 40, True, 6), ("fox.obj", 50, False, 7), ("cow.obj", 50, True, 8))
ANIMAL = 5


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--meshes", default=str(Path(__file__).resolve().parents[2] / "shared" / "meshes"))
    ap.add_argument("--size", default="1536x1024")
    ap.add_argument("--cache", default="/tmp/bodyscan-bench")
    args = ap.parse_args()
    size = tuple(int(v) for v in args.size.split("x"))
    rights = []
    print("render                    view  labelled  right    pieces (centres: chosen offset / true)")
    for mesh, stripes, fur, seed in RENDERS:
        name = f"{Path(mesh).stem}-{stripes}-{'fur' if fur else 'clean'}-{seed}"
        cap = Path(args.cache) / f"animal-{size[0]}x{size[1]}-{name}"
        if not (cap / "truth" / "truth.json").exists():
            write_capture(cap, stripes=stripes, size=size, seed=seed, scenes=("side", "top"), poses=0, fur=fur,
                          mesh=str(Path(args.meshes) / mesh))
        cal = load_calibration(cap / "truth" / "truth.json")
        table = ray_table(cal.intrinsics)
        for view in ("side", "top"):
            img = read_image(cap / "scan" / f"{view}.png")
            c = detect_centres(img)
            c = c.take(denoise(c, img.shape))
            matching._TRACE = []
            lab = label_centres(c, rays_at(c.u, c.v, table), cal.planes, img.shape).stripe
            trace, matching._TRACE = matching._TRACE, None
            truth, kind = match_crossings(np.column_stack([c.u, c.v]),
                                          dict(np.load(cap / "truth" / f"{view}_stripes.npz")))
            animal = kind == ANIMAL
            got = animal & (lab >= 0)
            right = float(np.mean(lab[got] == truth[got])) if got.any() else float("nan")
            rights.append(right)
            pieces = []
            for idx, rel, off in trace:
                ok = animal[idx] & (truth[idx] >= 0)
                if ok.sum() < 20:
                    continue
                vals, cnt = np.unique(truth[idx][ok] - rel[ok], return_counts=True)
                pieces.append(f"{len(idx)}: {off} / {vals[np.argmax(cnt)]}")
            print(f"{name:25s} {view:4s}  {got.sum() / max(animal.sum(), 1):8.1%}  {right:7.2%}   {'; '.join(pieces)}",
                  flush=True)
    r = np.array(rights)
    print(f"animal labels right: median {np.nanmedian(r):.2%}; views at least 95 % right: {(r >= 0.95).sum()} of {len(r)}")


if __name__ == "__main__":
    main()
