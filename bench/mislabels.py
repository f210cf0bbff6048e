"""Where a view's stripe labels go wrong: the animal's mislabelled segments and the row-order check's drops.

    python bench/mislabels.py CAPTURE [CAPTURE ...] [--view side|top] [--drops 10]

For each cached capture (a directory the benches rendered, e.g. ``/tmp/bodyscan-bench/scan-3072x2048-50-clean-4``)
and view, labels the view as the scan does (the faint-peak detector's centres, denoised) and prints the
animal's true crossings, how many got a label and how many of those are wrong; then each segment holding a
wrong label (its rows, median column, its labels and the truth's, the surface kinds of its centres: 0 no true
crossing within 1.5 px, 2 floor, 3 wall, 5 animal); then the ``--drops`` largest groups of centres the
row-order check unlabelled (``matching._enforce_row_order``: both sides of each break), with the label they
had and the truth. On 2026-12-03 it showed that every 50-stripe clean side view of the five seeds has one
wrong segment, the far leg's stripe 18 read as 17 (`docs/benchmarks.md`, that day's block).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import measurement.matching as matching  # noqa: E402
from bench.common import ANIMAL, captures_main, counts, scan_input  # noqa: E402
from measurement.matching import label_centres  # noqa: E402
from measurement.pipeline import ScanParams  # noqa: E402
from measurement.simulate.truth import match_crossings  # noqa: E402


def report(cap: Path, view: str, drops: int) -> None:
    inp = scan_input(cap, view)
    cal, c, rays = inp.cal, inp.centres, inp.rays
    before = np.full(len(c), -1, np.int64)  # the label a centre had where the row-order check dropped it
    check = matching._enforce_row_order

    def recorded(cc, labels, order):
        out = check(cc, labels, order)
        dropped = (labels >= 0) & (out < 0)
        before[dropped] = labels[dropped]
        return out

    matching._enforce_row_order = recorded
    try:
        lab = label_centres(c, rays, cal.planes, inp.shape, ScanParams().matching, view)
    finally:
        matching._enforce_row_order = check
    truth, kind = match_crossings(np.column_stack([c.u, c.v]), dict(np.load(cap / "truth" / f"{view}_stripes.npz")))
    seg, k = lab.segment, lab.stripe
    animal = kind == ANIMAL
    wrong = animal & (k >= 0) & (k != truth)
    print(f"{cap.name} {view}: animal crossings {animal.sum()}, labelled {(animal & (k >= 0)).sum()}, "
          f"wrong {wrong.sum()}")
    for s in np.unique(seg[wrong]):
        m = seg == s
        print(f"  wrong segment {s}: {m.sum()} centres, rows {c.v[m].min()}-{c.v[m].max()}, "
              f"u ~{np.median(c.u[m]):.0f}; labels {counts(k[m & wrong])}, truth {counts(truth[m & wrong])}, "
              f"{wrong[m].sum()} wrong; kinds {counts(kind[m])}")
    dropped = before >= 0
    print(f"  row order dropped {dropped.sum()} centres, {(dropped & animal).sum()} of the animal "
          f"({(dropped & animal & (before == truth)).sum()} of them right)")
    segs, n = np.unique(seg[dropped], return_counts=True)
    for s in segs[np.argsort(-n, kind="stable")][:drops]:
        d = dropped & (seg == s)
        print(f"    segment {s}: {d.sum()} of {(seg == s).sum()} centres, rows {c.v[d].min()}-{c.v[d].max()}, "
              f"u ~{np.median(c.u[d]):.0f}; had {counts(before[d])}, truth {counts(truth[d])}, "
              f"kinds {counts(kind[d])}")


def main() -> None:
    captures_main(__doc__, report, "drops", 10, "row-order drop groups to list per view")


if __name__ == "__main__":
    main()
