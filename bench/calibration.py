"""Calibration accuracy and speed on the rig simulator (full resolution by default).

    python bench/calibration.py [--size 3072x2048] [--stripes 40] [--poses 12] [--seed 11] [--capture DIR]

Prints: camera error against truth (fx, fy, cx, cy in %), E1; per-plane normal angle and offset errors
at 1 m for each plane-fit method; stripe-centre errors (px) for each centre estimator; E2; and the
median wall time of `calibrate` over 12 poses (images already decoded) plus the time to read them.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from measurement.board import find_corners  # noqa: E402
from measurement.calibration import CalibrationParams, calibrate  # noqa: E402
from measurement.capture import read_capture  # noqa: E402
from measurement.errors import StripeDetectionError  # noqa: E402
from measurement.simulate.capture import write_capture  # noqa: E402
from measurement.stripes import METHODS, StripeParams, detect_board_stripes  # noqa: E402


def plane_errors(fit: np.ndarray, true: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ang = np.degrees(np.arccos(np.clip(np.abs(np.sum(fit[:, :3] * true[:, :3], 1)), 0, 1)))
    q = np.array([0.0, 0.0, 1000.0])
    x = q - (true[:, :3] @ q - true[:, 3])[:, None] * true[:, :3]
    return ang, np.abs(np.sum(x * fit[:, :3], 1) - fit[:, 3])


def centre_errors(cap_dir: Path, capture, truth: dict, method: str, n_poses: int = 4) -> tuple[float, float, int]:
    """Bias, RMS (px) of stripe centres against the exact plane crossings, and rows used, over a few poses."""
    errs, rows = [], 0
    pattern = (capture.rig.board_cols, capture.rig.board_rows)
    for pose in capture.poses[:n_poses]:
        corners = find_corners(pose.board, pattern)
        try:
            found = detect_board_stripes(pose.stripes, pose.board, corners, pattern, capture.rig.stripes,
                                         StripeParams(method=method), pose.stripes_file)
        except StripeDetectionError:
            continue
        t = np.load(cap_dir / "truth" / f"{pose.name}_stripes.npz")
        on = t["kind"] == 4
        lut = {(int(k), int(round(v))): u for k, (u, v) in zip(t["stripe"][on], t["uv"][on], strict=True)}
        for k, (u, v) in zip(found.stripe, found.uv, strict=True):
            ref = lut.get((int(k), int(v)))
            if ref is not None:
                errs.append(u - ref)
        rows += found.rows_used
    if not errs:
        return float("nan"), float("nan"), 0
    e = np.array(errs)
    return float(e.mean()), float(np.sqrt(np.mean(e**2))), rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", default="3072x2048")
    ap.add_argument("--stripes", type=int, default=40)
    ap.add_argument("--poses", type=int, default=12)
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--capture", default=None, help="reuse (or create) this capture folder")
    args = ap.parse_args()
    size = tuple(int(v) for v in args.size.split("x"))
    cap_dir = Path(args.capture) if args.capture else Path(tempfile.mkdtemp(prefix="bench-cal-")) / "cap"
    if not (cap_dir / "truth" / "truth.json").exists():
        t0 = time.perf_counter()
        write_capture(cap_dir, stripes=args.stripes, size=size, seed=args.seed, scenes=(), poses=args.poses)
        print(f"rendered {args.poses} poses at {args.size} in {time.perf_counter() - t0:.1f} s -> {cap_dir}")
    truth = json.loads((cap_dir / "truth" / "truth.json").read_text())
    t0 = time.perf_counter()
    capture = read_capture(cap_dir)
    read_s = time.perf_counter() - t0
    Kt = np.array(truth["camera_matrix"])
    true_planes = np.array(truth["planes"])
    print(f"\n== {len(capture.poses)} poses, {capture.rig.stripes} stripes, {args.size}")

    times = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        result = calibrate(capture)
        times.append(time.perf_counter() - t0)
    K = result.intrinsics.camera_matrix
    rel = [abs(K[0, 0] / Kt[0, 0] - 1), abs(K[1, 1] / Kt[1, 1] - 1), abs(K[0, 2] / Kt[0, 2] - 1),
           abs(K[1, 2] / Kt[1, 2] - 1)]
    print(f"camera: fx {rel[0]:.4%}  fy {rel[1]:.4%}  cx {rel[2]:.4%}  cy {rel[3]:.4%} off truth "
          f"(target 0.3 %); E1 = {result.reprojection_error_px:.4f} px RMS (target 0.15)")
    print(f"poses used: {sum(p.used for p in result.poses)} camera, {sum(p.used_for_planes for p in result.poses)} "
          f"planes; E2 = {result.plane_error:.3g} (pencil), {result.plane_error_unconstrained:.3g} (independent fits)")
    print(f"time: calibrate median {statistics.median(times):.2f} s over {args.repeats} runs "
          f"(+ {read_s:.2f} s to read {2 * len(capture.poses)} PNGs) (target 15 s)")

    print("\nplane fit (centres: weighted)      normal err max / mean (deg)   offset@1m max / mean (mm)")
    for method in ("abc", "tls", "robust", "pencil"):
        r = result if method == "pencil" else calibrate(capture, params=CalibrationParams(plane_method=method))
        ang, off = plane_errors(r.planes, true_planes)
        print(f"  {method:8s}                        {ang.max():.4f} / {ang.mean():.4f}"
              f"                 {off.max():.3f} / {off.mean():.3f}")
    print("  targets: 0.05 deg, 0.3 mm")

    print("\nstripe centres (4 poses)   bias px   RMS px   rows with all N    planes: normal max (deg) / offset max (mm)")
    for method in METHODS:
        bias, rms, rows = centre_errors(cap_dir, capture, truth, method)
        try:
            r = calibrate(capture, params=CalibrationParams(stripes=StripeParams(method=method)))
            ang, off = plane_errors(r.planes, true_planes)
            tail = f"{ang.max():.4f} / {off.max():.3f}"
        except Exception as exc:  # noqa: BLE001  the paper's binarisation may find no complete row
            tail = f"fails: {str(exc)[:70]}..."
        print(f"  {method:9s}               {bias:+.4f}   {rms:.4f}   {rows:8d}           {tail}")


if __name__ == "__main__":
    main()
