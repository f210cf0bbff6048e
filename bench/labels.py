"""Stripe-label correctness of the scan pipeline over several renders (quicker than bench/scan.py).

    python bench/labels.py [--size 1536x1024] [--cache /tmp/bodyscan-bench]

For each render (40/50 stripes, fur or clean, several seeds; side and top views): the share of the
animal's true crossings that got a label, the share of those labels that are right, the background's
label correctness, and the time of the labelling step.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.common import VIEWS, cached_capture, label_view, size_and_cache  # noqa: E402

RENDERS = ((40, True, 11), (40, False, 12), (50, True, 13), (40, True, 14))


def main() -> None:
    size, cache = size_and_cache(__doc__)
    rights = []
    print("render              view  animal labelled  right    background right  labelling ms")
    for stripes, fur, seed in RENDERS:
        cap = cached_capture(cache / f"labels-{size[0]}x{size[1]}-{stripes}-{'fur' if fur else 'clean'}-{seed}",
                             stripes=stripes, size=size, seed=seed, fur=fur)
        for view in VIEWS:
            v = label_view(cap, view)
            rights.append(v.right)
            print(f"{stripes} {'fur  ' if fur else 'clean'} seed {seed:3d}   {view:4s}  {v.labelled:13.1%}  "
                  f"{v.right:7.2%}  {v.background_right:15.2%}  {v.ms:10.0f}")
    print(f"animal labels right: median {np.nanmedian(rights):.2%}, worst {np.nanmin(rights):.2%}")


if __name__ == "__main__":
    main()
