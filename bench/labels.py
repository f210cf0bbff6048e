"""Stripe-label correctness of the scan pipeline over several renders (quicker than bench/scan.py).

    python bench/labels.py [--size 1536x1024] [--cache /tmp/bodyscan-bench]

For each render (40/50 stripes, fur or clean, several seeds; side and top views): the share of the
animal's true crossings that got a label, the share of those labels that are right, the background's
label correctness, and the time of the labelling step.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from measurement.calibration import load_calibration  # noqa: E402
from measurement.detection import detect_centres  # noqa: E402
from measurement.images import read_image  # noqa: E402
from measurement.matching import denoise, label_centres  # noqa: E402
from measurement.simulate.capture import write_capture  # noqa: E402
from measurement.simulate.truth import match_crossings  # noqa: E402
from measurement.triangulation import ray_table, rays_at  # noqa: E402

RENDERS = ((40, True, 11), (40, False, 12), (50, True, 13), (40, True, 14))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", default="1536x1024")
    ap.add_argument("--cache", default="/tmp/bodyscan-bench")
    args = ap.parse_args()
    size = tuple(int(v) for v in args.size.split("x"))
    rights = []
    print("render              view  animal labelled  right    background right  labelling ms")
    for stripes, fur, seed in RENDERS:
        cap = Path(args.cache) / f"labels-{size[0]}x{size[1]}-{stripes}-{'fur' if fur else 'clean'}-{seed}"
        if not (cap / "truth" / "truth.json").exists():
            write_capture(cap, stripes=stripes, size=size, seed=seed, scenes=("side", "top"), poses=0, fur=fur)
        cal = load_calibration(cap / "truth" / "truth.json")
        table = ray_table(cal.intrinsics)
        for view in ("side", "top"):
            img = read_image(cap / "scan" / f"{view}.png")
            c = detect_centres(img)
            c = c.take(denoise(c, img.shape))
            rays = rays_at(c.u, c.v, table)
            t0 = time.perf_counter()
            lab = label_centres(c, rays, cal.planes, img.shape).stripe
            ms = 1000 * (time.perf_counter() - t0)
            truth, kind = match_crossings(np.column_stack([c.u, c.v]), dict(np.load(cap / "truth" / f"{view}_stripes.npz")))
            animal, bg = kind == 5, (kind == 2) | (kind == 3)
            got, bgot = animal & (lab >= 0), bg & (lab >= 0)
            right = float(np.mean(lab[got] == truth[got])) if got.any() else float("nan")
            rights.append(right)
            print(f"{stripes} {'fur  ' if fur else 'clean'} seed {seed:3d}   {view:4s}  {got.sum() / animal.sum():13.1%}  "
                  f"{right:7.2%}  {np.mean(lab[bgot] == truth[bgot]):15.2%}  {ms:10.0f}")
    print(f"animal labels right: median {np.nanmedian(rights):.2%}, worst {np.nanmin(rights):.2%}")


if __name__ == "__main__":
    main()
