"""How far from the animal the small pieces lie that side-view labelling reads by their own conflict curve.

    python bench/smallpieces.py CAPTURE [CAPTURE ...]

For each cached capture's side view (a directory the benches rendered, e.g. ``/tmp/bodyscan-bench/scan-3072x2048-
40-fur-4``), labels it as the scan does and lists every small piece ``_place_small`` weighed for its offset by its
own curve (``matching._NearAnimal``): its centres, how many are the animal's, the labels read and how far the
truth's labels of most of its animal centres lie from them, and the distance of its nearest point from the labelled animal (and the
small pieces placed before it) as a share of the animal's size, with whether it was placed (the share at most
``matching.SMALL_APART``). Then the shares of the pieces read right, read wrong and holding none of the animal.
On 2026-12-03 (the render caches' 288 views, before the rule existed) right pieces lay 0.001-0.124 of the size
away, 17 of 28 wrong ones 0.23-160 (`docs/benchmarks.md`, that day's sixth block): ``SMALL_APART`` 0.2.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import measurement.matching as matching  # noqa: E402
from bench.common import ANIMAL, ScanInput, scan_input  # noqa: E402
from measurement.matching import label_centres  # noqa: E402
from measurement.pipeline import ScanParams  # noqa: E402
from measurement.simulate.truth import match_crossings  # noqa: E402


def weighed_pieces(inp: ScanInput) -> list[tuple[np.ndarray, np.ndarray, float, bool]]:
    """The small pieces ``_NearAnimal`` weighed in a side view (``scan_input``): centres (K,), labels (K,), the
    nearest point's distance as a share of the animal's size, and whether the piece was placed."""
    seen: list[tuple[np.ndarray, np.ndarray, float, bool]] = []
    takes = matching._NearAnimal.takes

    def recorded(self, idx: np.ndarray, lab: np.ndarray) -> bool:
        placed = takes(self, idx, lab)
        inside = (lab >= 0) & (lab < len(self.planes))
        trees = self.trees[:-1] if placed and self.trees else self.trees
        if trees and inside.any():
            p = self._points(idx[inside], lab[inside], matching.NEAR_POINTS // 10)
            gap = min(float(t.query(p)[0].min()) for t in trees)
            seen.append((idx, lab, gap * matching.SMALL_APART / self.reach, placed))
        return placed

    matching._NearAnimal.takes = recorded  # type: ignore[method-assign]
    try:
        label_centres(inp.centres, inp.rays, inp.cal.planes, inp.shape, ScanParams().matching, "side")
    finally:
        matching._NearAnimal.takes = takes  # type: ignore[method-assign]
    return seen


def main() -> None:
    caps = [Path(a) for a in sys.argv[1:] if not a.startswith("-")]
    if not caps:
        sys.exit(__doc__)
    shares: dict[str, list[float]] = {"right": [], "wrong": [], "no animal": []}
    for cap in caps:
        if not (cap / "scan" / "side.png").exists():
            continue
        inp = scan_input(cap, "side")
        pieces = weighed_pieces(inp)
        if not pieces:
            continue
        c = inp.centres
        truth, kind = match_crossings(np.column_stack([c.u, c.v]), dict(np.load(cap / "truth" / "side_stripes.npz")))
        for idx, lab, share, placed in pieces:
            an = kind[idx] == ANIMAL
            vals, cnt = np.unique(truth[idx][an] - lab[an], return_counts=True)
            off_by = int(vals[np.argmax(cnt)]) if len(vals) else None  # the truth's label minus the one read
            verdict = "no animal" if off_by is None else "right" if off_by == 0 else "wrong"
            shares[verdict].append(share)
            print(f"{cap.name}: piece of {len(idx)} centres ({int(an.sum())} animal), labels {lab.min()}..{lab.max()}"
                  f" ({verdict}" + ("" if off_by in (None, 0) else f", the truth's {off_by:+d}") + f"); nearest point "
                  f"{share:.3f} of the animal's size, {'placed' if placed else 'refused'}")
    for verdict, values in shares.items():
        v = np.sort(values)
        print(f"{verdict}: {len(v)} pieces" + (f", shares {v.min():.3f}-{v.max():.3f}, over {matching.SMALL_APART}: "
                                               f"{int((v > matching.SMALL_APART).sum())}" if len(v) else ""))


if __name__ == "__main__":
    main()
