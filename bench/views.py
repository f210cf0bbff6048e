"""Stripe-label correctness on the front and back views (the camera at the animal's head or tail end,
looking along its body), which `bodyscan scan --view front|back` offers and the other benches never render.

    python bench/views.py [--size 3072x2048] [--cache /tmp/bodyscan-bench]

Per view: the share of the animal's true crossings labelled, the share of those right, and per piece of
the animal the offset chosen against the true one. Four renders: 40 and 50 stripes, fur and clean.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.common import cached_capture, print_pieces, size_and_cache, summary  # noqa: E402

RENDERS = ((40, True, 21), (50, False, 22), (40, False, 23), (50, True, 24))
VIEWS = ("front", "back")


def main() -> None:
    size, cache = size_and_cache(__doc__, "3072x2048")
    rights: list[float] = []
    print("render                    view   labelled  right    pieces (centres: chosen offset / true)")
    for stripes, fur, seed in RENDERS:
        label = f"{stripes}-{'fur' if fur else 'clean'}-{seed}"
        cap = cached_capture(cache / f"views-{size[0]}x{size[1]}-{label}", views=VIEWS, stripes=stripes,
                             size=size, seed=seed, fur=fur)
        rights += print_pieces(label, cap, VIEWS)
    print(summary(rights))


if __name__ == "__main__":
    main()
