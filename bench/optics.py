"""Scan robustness to the optics, the sensor and the scene: the same animal and rig geometry with other
stripe widths, another stripe fan, a noisy sensor, a bright room, a soft camera focus, no wall, a dark,
a white, a speckled (concrete) or a tiled floor, a feed box behind the animal, a black coat, a weighing
platform under the animal, the rails of a chute in front of it, and frames that went through JPEG
compression.

    python bench/optics.py [--size 1536x1024] [--cache /tmp/bodyscan-bench] [--seed 4] [--only wide,thin]

An independent renderer will differ from ours in exactly these ways, so the figures here say how much of
the scan's accuracy is tuned to the reference optics. Per variant and view: the share of the animal's
true crossings labelled right (and of the background's), per piece of the animal the offset chosen
against the true one, the share of animal points within 2 mm of the surface, and body length / height
against the same definitions on the simulator's true stripe points. Uses the true calibration.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import cv2

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.common import VIEWS, cached_capture, label_view, pieces_text  # noqa: E402
from bench.scan import evaluate, pct_err  # noqa: E402
from measurement.errors import ScanError  # noqa: E402
from measurement.simulate.rig import Rig, default_rig  # noqa: E402

# projector: stripe sigma (projector-normalised; the reference is 0.0009) and a scale of the stripe fan;
# light: Lighting overrides for every exposure; scene: options of the animal views' scene
VARIANTS: dict[str, dict] = {
    "reference": {},
    "wide stripes (2x sigma)": {"sigma": 0.0018},
    "thin stripes (0.5x sigma)": {"sigma": 0.00045},
    "sparse fan (1.5x spacing)": {"fan": 1.5},
    "dense fan (0.7x spacing)": {"fan": 0.7},
    "noisy sensor (2x read, 5x shot)": {"light": {"read_noise": 3.0, "gain": 1.25}},
    "noisy sensor (3x read, 5x shot)": {"light": {"read_noise": 4.5, "gain": 1.25}},
    "noisy sensor (4x read, 6x shot)": {"light": {"read_noise": 6.0, "gain": 1.5}},
    "bright room (2.5x ambient)": {"light": {"ambient": 150.0}},
    "soft focus (2.5x camera blur)": {"light": {"blur_px": 2.0}},
    "no wall": {"scene": {"wall": False}},
    "dark floor (albedo 0.12)": {"scene": {"floor_albedo": 0.12}},
    "white floor (albedo 0.85)": {"scene": {"floor_albedo": 0.85}},
    "concrete floor (fine speckle)": {"scene": {"floor": "concrete"}},
    "tiled floor (dark grout)": {"scene": {"floor": "tiles"}},
    "feed box behind the animal": {"scene": {"box": (0.0, 250.0)}},
    "black coat (albedo x0.25)": {"scene": {"coat": 0.25}},
    "weighing platform (100 mm)": {"scene": {"platform": 100.0}},
    "weighing platform, no wall": {"scene": {"platform": 100.0, "wall": False}},
    "chute rails in front": {"scene": {"rails": -300.0}},
    "JPEG quality 90": {"jpeg": 90},
    "JPEG quality 75": {"jpeg": 75},
}


def capture_for(cache: Path, name: str, variant: dict, size: tuple[int, int], seed: int) -> Path:
    slug = "-".join("".join(ch if ch.isalnum() else " " for ch in name).split())
    rig = default_rig(size, 40)
    p = rig.projector
    if "sigma" in variant:
        p = replace(p, sigma=variant["sigma"])
    if "fan" in variant:
        p = replace(p, stripe_x=p.stripe_x * variant["fan"])

    def through_jpeg(out: Path) -> None:  # the same frames through a lossy camera pipeline, decoded again
        for view in VIEWS:
            path = out / "scan" / f"{view}.png"
            _, buf = cv2.imencode(".jpg", cv2.imread(str(path), cv2.IMREAD_UNCHANGED),
                                   [cv2.IMWRITE_JPEG_QUALITY, variant["jpeg"]])
            cv2.imwrite(str(path), cv2.imdecode(buf, cv2.IMREAD_UNCHANGED))

    return cached_capture(cache / f"optics-{size[0]}x{size[1]}-{slug}-{seed}", through_jpeg if "jpeg" in variant else None,
                          stripes=40, size=size, seed=seed, fur=True, rig=Rig(rig.intrinsics, p),
                          light=variant.get("light"), scene=variant.get("scene"))

def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", default="1536x1024")
    ap.add_argument("--cache", default="/tmp/bodyscan-bench")
    ap.add_argument("--seed", type=int, default=4)
    ap.add_argument("--only", default=None, help="comma-separated substrings: the variants whose names hold one")
    args = ap.parse_args()
    size = tuple(int(v) for v in args.size.split("x"))
    cache = Path(args.cache)
    cache.mkdir(parents=True, exist_ok=True)
    print("variant                          view  labels right (animal/bg)  within 2 mm  length err  height err"
          "   pieces (centres: chosen offset / true)")
    good = total = 0
    for name, variant in VARIANTS.items():
        if args.only and not any(part in name for part in args.only.split(",")):
            continue
        cap = capture_for(cache, name, variant, size, args.seed)
        for view in VIEWS:
            total += 1
            s = label_view(cap, view)
            try:
                e = evaluate(cap, view)
                acc = (f"{e['within_2mm']:9.2%}  {pct_err(e['body_length_mm'], e['body_length_truth_mm'])}"
                       f"     {pct_err(e['body_height_mm'], e['body_height_truth_mm'])}")
            except ScanError as err:
                acc = f"scan refused: {err}"
            good += s.right >= 0.95
            print(f"{name:32s} {view:4s}  {s.right:8.2%} / {s.background_right:7.2%}   {acc}   "
                  f"{pieces_text(s.pieces, s.shift)}", flush=True)
    print(f"views with at least 95 % of the animal's labelled crossings right: {good} of {total}")


if __name__ == "__main__":
    main()
