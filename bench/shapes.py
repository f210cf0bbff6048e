"""Stripe-label correctness on cow-like animals built from primitives: a fresh probe of other shapes.

    python bench/shapes.py [--size 1536x1024] [--cache /tmp/bodyscan-bench]

The issue's figures will also be checked on other animals than the procedural quadruped. This builds
cow-like bodies from trimesh primitives (an ellipsoid body on four upright capsule legs, a neck raising the
head above the back, two ears), scales them to 430-560 mm (so that, head and tail included, the stripe
pattern spans them from the side and from above, as the rig is meant to be used: at 600 mm and more they
overflow it), renders a side and a top view of each (fur or clean, 40 or 50 stripes) and reports per view,
as ``bench/animals.py`` does, the share of the animal's true crossings labelled, the share of those right,
and per piece the offset chosen against the true one. Unlike the shared meshes, it needs nothing outside
the checkout. Added on 2026-12-04; its first version (sideways legs, 600-900 mm) is where
``offsets._edge_settled`` was found (docs/benchmarks.md). The render cache is keyed by name only: a change
to ``cow`` needs a new ``PREFIX``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import trimesh

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.common import cached_capture, print_pieces, summary  # noqa: E402

PREFIX = "cows"  # of the cached renders and meshes
# name, head raised (mm before scaling), body length the mesh is scaled to (mm), stripes, fur, seed
SHAPES = (("cow-a", 170, 450, 40, True, 41), ("cow-b", 170, 520, 40, True, 42), ("cow-c", 250, 500, 40, True, 43),
          ("cow-d", 170, 480, 40, False, 44), ("cow-e", 300, 540, 40, True, 45), ("cow-f", 250, 460, 50, True, 46),
          ("cow-g", 200, 430, 50, False, 47), ("cow-h", 120, 560, 50, True, 48))


def cow(head_raise: float) -> trimesh.Trimesh:
    """A cow-like mesh (mm, y up, x toward the head): an ellipsoid body 1000 x 420 x 340 mm whose back is
    640 mm above the feet, four legs, a neck and a head ``head_raise`` mm above the body's centre, two ears."""
    parts = []
    body = trimesh.creation.icosphere(subdivisions=4)
    body.apply_scale([500, 210, 170])
    body.apply_translation([0, 430, 0])
    parts.append(body)
    upright = trimesh.transformations.rotation_matrix(np.radians(-90), [1, 0, 0])  # a capsule's axis z -> y
    for lx in (330, -330):
        for lz in (110, -110):
            leg = trimesh.creation.capsule(height=300, radius=45)
            leg.apply_transform(upright)
            leg.apply_translation([lx, 150, lz])
            parts.append(leg)
    neck = trimesh.creation.capsule(height=260, radius=85)
    neck.apply_transform(upright)
    neck.apply_transform(trimesh.transformations.rotation_matrix(np.radians(-40), [0, 0, 1]))  # leaning forward
    neck.apply_translation([500, 430 + head_raise / 2, 0])
    parts.append(neck)
    head = trimesh.creation.icosphere(subdivisions=3)
    head.apply_scale([170, 110, 120])
    head.apply_translation([620, 430 + head_raise, 0])
    parts.append(head)
    for ez in (130, -130):
        ear = trimesh.creation.icosphere(subdivisions=2)
        ear.apply_scale([40, 60, 25])
        ear.apply_translation([590, 500 + head_raise, ez])
        parts.append(ear)
    return trimesh.util.concatenate(parts)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", default="1536x1024")
    ap.add_argument("--cache", default="/tmp/bodyscan-bench")
    args = ap.parse_args()
    size = tuple(int(v) for v in args.size.split("x"))
    rights: list[float] = []
    print("render                    view  labelled  right    pieces (centres: chosen offset / true)")
    for name, raise_mm, length, stripes, fur, seed in SHAPES:
        label = f"{name}-{stripes}-{'fur' if fur else 'clean'}-{seed}"
        out = Path(args.cache) / f"{PREFIX}-{size[0]}x{size[1]}-{label}"
        mesh = Path(args.cache) / f"{PREFIX}-{name}-{raise_mm}.ply"
        if not mesh.exists():
            mesh.parent.mkdir(parents=True, exist_ok=True)
            cow(raise_mm).export(mesh)
        cap = cached_capture(out, stripes=stripes, size=size, seed=seed, fur=fur, mesh=str(mesh),
                             mesh_length_mm=float(length))
        rights += print_pieces(label, cap)
    print(summary(rights))


if __name__ == "__main__":
    main()
