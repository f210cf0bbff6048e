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

from bench.common import label_view, pieces_text  # noqa: E402
from measurement.simulate.capture import write_capture  # noqa: E402

RENDERS = (("fox.obj", 40, True, 3), ("cow.obj", 40, True, 3), ("horse.ply", 50, False, 5),
           ("shiba-inu.obj", 40, True, 6), ("fox.obj", 50, False, 7), ("cow.obj", 50, True, 8))


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
        for view in ("side", "top"):
            v = label_view(cap, view)
            rights.append(v.right)
            print(f"{name:25s} {view:4s}  {v.labelled:8.1%}  {v.right:7.2%}   {pieces_text(v.pieces)}", flush=True)
    r = np.array(rights)
    print(f"animal labels right: median {np.nanmedian(r):.2%}; views at least 95 % right: {(r >= 0.95).sum()} of {len(r)}")


if __name__ == "__main__":
    main()
