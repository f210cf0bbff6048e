"""Stripe-label correctness on other rig geometries: projector left of the camera, a narrower and a
wider baseline than the reference rig's 250 mm, and the rig 150 mm lower or 200 mm higher (the side camera
keeps its viewing direction, so 200 mm higher cuts the feet off at the bottom of the picture; the top
camera comes 150 mm nearer the floor or goes 200 mm farther), or 450 mm higher and aimed down at the animal;
and the projector turned 10 degrees either way about its axis (stripes slanted in the image); and the camera
200 mm nearer, 400 and 800 mm farther (the projector re-aimed at the animal).

    python bench/geometry.py [--size 1536x1024] [--cache /tmp/bodyscan-bench]

The issue's figures will also be checked on an independent renderer with other geometry; the method
must not depend on the reference rig. Per view: the share of the animal's true crossings labelled, the
share of those right, and per piece of the animal the offset chosen against the true one.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.common import cached_capture, print_pieces, size_and_cache, summary  # noqa: E402
from measurement.simulate.rig import default_rig  # noqa: E402

GEOMETRIES = {"left": -250.0, "narrow": 150.0, "wide": 400.0}  # projector baseline, mm (negative: left)
ROLLS = {"roll+10": 10.0, "roll-10": -10.0}  # the projector turned about its axis: slanted stripes, degrees
# the camera (and projector) stepped back along the viewing direction, mm, the projector re-aimed to meet the
# camera axis at the animal (the reference rig: 1150 mm)
DISTANCES = {"near": (-200.0, 950.0), "far": (400.0, 1550.0), "farther": (800.0, 1950.0)}
HEIGHTS = {"low": ({"camera_height": -150.0}), "high": ({"camera_height": 200.0}),  # the rig's height, mm
           "aimed": ({"camera_height": 450.0, "camera_aimed": True})}
RENDERS = ((40, True, 21), (50, False, 22))


def main() -> None:
    size, cache = size_and_cache(__doc__)
    rights: list[float] = []
    print("rig                       view  labelled  right    pieces (centres: chosen offset / true)")
    variants = ([(name, {"rig": default_rig(size, stripes, baseline_mm=baseline)}, stripes)
                 for name, baseline in GEOMETRIES.items() for stripes, _, _ in RENDERS]
                + [(name, {"rig": default_rig(size, stripes, roll_deg=roll)}, stripes)
                   for name, roll in ROLLS.items() for stripes, _, _ in RENDERS]
                + [(name, {"scene": scene}, stripes) for name, scene in HEIGHTS.items() for stripes, _, _ in RENDERS]
                + [(name, {"rig": default_rig(size, stripes, aim_mm=aim), "scene": {"camera_back": back}}, stripes)
                   for name, (back, aim) in DISTANCES.items() for stripes, _, _ in RENDERS])
    renders = {stripes: (fur, seed) for stripes, fur, seed in RENDERS}
    for name, how, stripes in variants:
        fur, seed = renders[stripes]
        label = f"{name}-{stripes}-{'fur' if fur else 'clean'}-{seed}"
        cap = cached_capture(cache / f"geometry-{size[0]}x{size[1]}-{label}", stripes=stripes,
                             size=size, seed=seed, fur=fur, **how)
        rights += print_pieces(label, cap)
    print(summary(rights))

if __name__ == "__main__":
    main()
