"""Calibration robustness: the same accuracy figures on re-rendered captures whose board, albedo, noise
and room light differ from the defaults (the method must not be tuned to one simulator setting).

    python bench/calibration_variants.py [--size 1536x1024] [--poses 8]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.calibration import plane_errors  # noqa: E402
from measurement.calibration import calibrate  # noqa: E402
from measurement.capture import read_capture  # noqa: E402
from measurement.errors import MeasurementError  # noqa: E402
from measurement.simulate.boards import Board  # noqa: E402
from measurement.simulate.capture import write_capture  # noqa: E402

VARIANTS = {
    "default": {},
    "board 11x8 of 50 mm": {"board": Board(cols=11, rows=8, square_mm=50.0, margin_mm=50.0)},
    "black squares at 2.5 %": {"board": Board(black=0.025)},
    "3x read noise, 3x shot noise": {"light": {"read_noise": 4.5, "gain": 2.0}},
    "no room light for stripes": {"light": {"stripe_ambient": 2.0}},
    "bright room, soft focus": {"light": {"stripe_ambient": 70.0, "blur_px": 1.6}},
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", default="1536x1024")
    ap.add_argument("--poses", type=int, default=8)
    ap.add_argument("--seed", type=int, default=21)
    args = ap.parse_args()
    size = tuple(int(v) for v in args.size.split("x"))
    root = Path(tempfile.mkdtemp(prefix="bench-variants-"))
    print(f"{'variant':32s} {'fx err %':>9s} {'E1 px':>7s} {'poses':>6s} {'normal max':>11s} {'offset max':>11s}")
    for i, (name, kw) in enumerate(VARIANTS.items()):
        cap = write_capture(root / f"v{i}", size=size, poses=args.poses, seed=args.seed, scenes=(), **kw)
        truth = json.loads((cap / "truth" / "truth.json").read_text())
        try:
            r = calibrate(read_capture(cap))
        except MeasurementError as exc:
            print(f"{name:32s} fails: {exc}")
            continue
        fx = abs(r.intrinsics.fx / truth["camera_matrix"][0][0] - 1) * 100
        ang, off = plane_errors(r.planes, np.array(truth["planes"]))
        used = f"{sum(p.used_for_planes for p in r.poses)}/{len(r.poses)}"
        print(f"{name:32s} {fx:9.4f} {r.reprojection_error_px:7.3f} {used:>6s} {ang.max():10.4f}° {off.max():8.3f} mm")


if __name__ == "__main__":
    main()
