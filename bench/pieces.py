"""How labelling read a view, piece by piece: each foreground piece weighed for an offset, against the truth.

    python bench/pieces.py CAPTURE [CAPTURE ...] [--view side|top] [--most 12]

For each cached capture (a directory the benches rendered, e.g. ``/tmp/bodyscan-bench/scan-3072x2048-50-clean-9``)
and view, labels the view as the scan does and lists, in the order they were weighed (``matching._TRACE``:
the pieces ``_foreground`` placed or refused, then the small ones ``_place_small`` read by their own curve),
each piece's centres, how many of them are the animal's, its rows and columns, its span of relative labels,
the offset it was given (None: refused) and the offset the truth gives most of its animal centres (with how
many agree), and the surface kinds of its centres (0 no true crossing within 1.5 px, 2 floor, 3 wall,
5 animal). On 2026-12-03 it showed why the 50-stripe clean side view of seed 9 saved as a JPEG lost its head:
the first piece had stopped at the chest, so the head's stripes came out as a dozen one-stripe pieces, five
of them placed one low (`docs/benchmarks.md`, that day's fifth block).
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


def report(cap: Path, view: str, most: int) -> None:
    inp = scan_input(cap, view)
    c = inp.centres
    matching._TRACE = []
    try:
        label_centres(c, inp.rays, inp.cal.planes, inp.shape, ScanParams().matching, view)
        trace = matching._TRACE
    finally:
        matching._TRACE = None
    truth, kind = match_crossings(np.column_stack([c.u, c.v]), dict(np.load(cap / "truth" / f"{view}_stripes.npz")))
    print(f"{cap.name} {view}: {len(c)} centres, {int((kind == ANIMAL).sum())} of them the animal's")
    shown = 0
    for idx, rel, off in trace:
        if idx is None:  # the whole-animal recheck's shift
            print(f"  whole-animal shift {off}")
            continue
        if shown == most:
            continue
        shown += 1
        an = kind[idx] == ANIMAL
        d = truth[idx][an] - rel[an]
        vals, cnt = np.unique(d, return_counts=True)
        best = f"{vals[np.argmax(cnt)]} ({cnt.max()})" if len(vals) else "none"
        print(f"  piece of {len(idx)} centres ({int(an.sum())} animal), rows {c.v[idx].min()}-{c.v[idx].max()}, "
              f"u {c.u[idx].min():.0f}-{c.u[idx].max():.0f}, relative labels {rel.min()}..{rel.max()}: "
              f"offset {off}, the truth's {best}; kinds {counts(kind[idx])}")


def main() -> None:
    captures_main(__doc__, report, "most", 12, "pieces to list per view")


if __name__ == "__main__":
    main()
