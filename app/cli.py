"""The `bodyscan` command line: simulate, calibrate, scan, demo, serve, worker."""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
from pathlib import Path

# A scan's BLAS products are over three columns, where a second BLAS thread only waits on the other core:
# with two scans at once on a 2-core machine (two job workers) one thread each finishes both 18-24 %
# sooner (docs/benchmarks.md). Set before NumPy is loaded; a setting in the environment wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from measurement.errors import MeasurementError  # noqa: E402


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--size must look like 3072x2048, got {text!r}") from None
    if w < 320 or h < 240:
        raise argparse.ArgumentTypeError(f"--size {text} is too small (at least 320x240)")
    return w, h


def _gamma(text: str) -> float:
    from measurement.capture import gamma_problem

    value: float | str = text  # (named as it was given when it is no number)
    try:
        value = float(text)
    except ValueError:
        pass
    problem = gamma_problem(value)
    if problem:
        raise argparse.ArgumentTypeError(f"--gamma: {problem}")
    return float(value)


def cmd_simulate(args: argparse.Namespace) -> None:
    from measurement.simulate.capture import write_capture

    scenes = tuple(s.strip() for s in args.scene.split(",")) if args.scene else ("side", "top")
    out = write_capture(
        Path(args.out_dir), stripes=args.stripes, size=args.size, seed=args.seed, scenes=scenes,
        poses=args.poses, mesh=args.mesh, fur=not args.no_fur, gamma=args.gamma,
    )
    print(f"wrote capture to {out}")


def cmd_calibrate(args: argparse.Namespace) -> None:
    from measurement.calibration import CalibrationParams, calibrate, load_intrinsics
    from measurement.capture import read_capture
    from measurement.report import write_report

    capture = read_capture(Path(args.capture))
    intr = load_intrinsics(Path(args.intrinsics)) if args.intrinsics else None
    result = calibrate(capture, intrinsics=intr, params=CalibrationParams(camera_gamma=args.gamma),
                       progress=_progress if args.verbose else None)
    out = Path(args.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result.to_dict(), indent=1))
    report = write_report(result, out.with_suffix(".png"))
    skipped = [p for p in result.poses if not p.used]
    print(f"calibration written to {out} (report {report})")
    print(f"reprojection error E1 = {result.reprojection_error_px:.4f} px over {len(result.poses) - len(skipped)} poses")
    if result.planes is not None:
        across = " (the stripes run across the image: planes numbered top to bottom)" \
            if result.stripe_axis == "horizontal" else ""
        print(f"{len(result.planes)} light planes, plane error E2 = {result.plane_error:.4g}{across}")
    for p in skipped:
        print(f"skipped {p.name}: {p.reason}")


def cmd_scan(args: argparse.Namespace) -> None:
    from measurement.scanfiles import scan_files

    summary = scan_files(Path(args.calibration), [Path(p) for p in args.images], Path(args.output), args.view,
                         args.gamma)
    for line in summary:
        print(line)


def cmd_demo(args: argparse.Namespace) -> None:
    from app.demo import run_demo

    run_demo(Path(args.workdir), size=args.size, serve=not args.no_serve, host=args.host, port=args.port)


def _progress(fraction: float, stage: str) -> None:
    print(f"[{fraction:5.1%}] {stage}", file=sys.stderr)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="bodyscan", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("simulate", help="render a capture folder (calibration poses + animal scans) with ground truth")
    s.add_argument("out_dir")
    s.add_argument("--stripes", type=int, default=40)
    s.add_argument("--size", type=_size, default=(3072, 2048), help="WxH, default 3072x2048")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--scene", default=None, help="comma-separated views: side, top, front, back (default side,top)")
    s.add_argument("--poses", type=int, default=12, help="calibration poses (default 12)")
    s.add_argument("--mesh", default=None, help="any trimesh-loadable animal mesh instead of the procedural quadruped")
    s.add_argument("--no-fur", action="store_true", help="smooth albedo, no scatter (clean scene)")
    s.add_argument("--gamma", type=_gamma, default=1.0,
                   help="write the images as a camera with this display gamma would (2.2: sRGB-like; rig.json says so)")
    s.set_defaults(func=cmd_simulate)

    c = sub.add_parser("calibrate", help="calibrate camera and light planes from a capture folder")
    c.add_argument("capture")
    c.add_argument("-o", "--output", default="calibration.json")
    c.add_argument("--intrinsics", default=None, help="reuse the camera of an earlier calibration.json")
    c.add_argument("-v", "--verbose", action="store_true")
    c.add_argument("--gamma", type=_gamma, default=None,
                   help="the camera's display gamma, recorded for its scans: 1.0 if it writes light linearly, "
                        "2.2 if it writes sRGB-like images (default: rig.json's camera_gamma, else 1.0)")
    c.set_defaults(func=cmd_calibrate)

    sc = sub.add_parser("scan", help="reconstruct a point cloud and body size from stripe images")
    sc.add_argument("calibration")
    sc.add_argument("images", nargs="+")
    sc.add_argument("--view", choices=["side", "top", "front", "back"], default=None)
    sc.add_argument("-o", "--output", default="scan_out")
    sc.add_argument("--gamma", type=_gamma, default=None,
                    help="the camera's display gamma for these images (default: the calibration's camera_gamma)")
    sc.set_defaults(func=cmd_scan)

    d = sub.add_parser("demo", help="simulate a rig, calibrate, scan, load demo records and serve the app")
    d.add_argument("--workdir", default="data/demo")
    d.add_argument("--size", type=_size, default=(1536, 1024))
    d.add_argument("--no-serve", action="store_true", help="only prepare the demo data and print results")
    d.add_argument("--host", default="127.0.0.1")
    d.add_argument("--port", type=int, default=8000)
    d.set_defaults(func=cmd_demo)

    try:
        from app.service_cli import register
    except ImportError:  # the web service is optional while it is being built
        register = None
    if register is not None:
        register(sub)
    return p


def _quiet_opencv() -> None:
    """OpenCV prints its own warnings for damaged files; ours already name the file."""
    try:
        import cv2

        cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)
    except AttributeError:
        pass


def main(argv: list[str] | None = None) -> int:
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    _quiet_opencv()
    args = build_parser().parse_args(argv)
    try:
        args.func(args)
    except MeasurementError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except (FileNotFoundError, IsADirectoryError, NotADirectoryError, PermissionError) as exc:
        print(f"error: {exc.filename or exc}: {exc.strerror or 'cannot open'}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
