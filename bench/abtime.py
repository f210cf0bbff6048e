"""Two checkouts' scan times side by side, scan by scan: the way to tell a 2 ms change on a host whose speed drifts.

    python bench/abtime.py BEFORE_DIR AFTER_DIR [--capture scan-3072x2048-40-fur-4] [--turns 30]
                           [--cache /tmp/bodyscan-bench]

Each checkout (a directory holding ``measurement/``, e.g. a ``git worktree`` of the commit before) runs in a worker
process of its own that decodes the capture's side and top frames once and then scans whichever it is told to.
The two workers take turns, one scan each, the order flipped every turn, so both see the same minutes of this
host; medians per stage (``ScanResult.timings_ms``) and of the wall time around ``measurement.scan``. Timing two
checkouts one after another (``bench/scan.py`` in each) moved the same code by 10-25 ms between runs on
2026-12-04; taking turns, the medians of 30 turns agreed to about 1 ms.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

VIEWS = ("side", "top")
STAGES = ("detect", "denoise", "match", "triangulate", "measure", "total", "wall")


def worker(capture: Path) -> None:
    """Scan the view named on each stdin line; print its timings as one JSON line."""
    from measurement.calibration import load_calibration
    from measurement.images import read_image
    from measurement.pipeline import scan

    cal = load_calibration(capture / "truth" / "truth.json")
    frames = {v: read_image(capture / "scan" / f"{v}.png") for v in VIEWS}
    for v in VIEWS:  # (the ray table and the compiled kernels)
        scan(frames[v], cal, v)
    print("ready", flush=True)
    for line in sys.stdin:
        view = line.strip()
        t0 = time.perf_counter()
        r = scan(frames[view], cal, view)
        print(json.dumps({**r.timings_ms, "wall": 1000 * (time.perf_counter() - t0)}), flush=True)


def _start(tree: Path, capture: Path) -> subprocess.Popen:
    p = subprocess.Popen([sys.executable, __file__, "--worker", str(tree), str(capture)], stdin=subprocess.PIPE,
                         stdout=subprocess.PIPE, text=True, cwd=tree, env={**os.environ, "PYTHONPATH": ""})
    if p.stdout is None or p.stdout.readline().strip() != "ready":
        raise SystemExit(f"the worker for {tree} did not start")
    return p


def main() -> None:
    if len(sys.argv) == 4 and sys.argv[1] == "--worker":  # (one checkout's worker: its measurement/ first on the path)
        sys.path.insert(0, sys.argv[2])
        worker(Path(sys.argv[3]))
        return
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("before", type=Path)
    ap.add_argument("after", type=Path)
    ap.add_argument("--capture", default="scan-3072x2048-40-fur-4")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/bodyscan-bench"))
    ap.add_argument("--turns", type=int, default=30)
    args = ap.parse_args()
    capture = args.cache / args.capture
    if not (capture / "scan" / "side.png").exists():
        raise SystemExit(f"{capture}: no such capture (render it with bench/scan.py first)")
    workers = {"before": _start(args.before.resolve(), capture), "after": _start(args.after.resolve(), capture)}
    times: dict[tuple[str, str], list[dict]] = {(w, v): [] for w in workers for v in VIEWS}
    for turn in range(args.turns):
        for view in VIEWS:
            for name in (("before", "after") if turn % 2 == 0 else ("after", "before")):
                p = workers[name]
                p.stdin.write(view + "\n")  # type: ignore[union-attr]
                p.stdin.flush()  # type: ignore[union-attr]
                times[(name, view)].append(json.loads(p.stdout.readline()))  # type: ignore[union-attr]
    for p in workers.values():
        p.stdin.close()  # type: ignore[union-attr]
        p.wait()
    print(f"{args.capture}, {args.turns} turns (medians, ms)")
    for view in VIEWS:
        for stage in STAGES:
            a = statistics.median(t[stage] for t in times[("before", view)])
            b = statistics.median(t[stage] for t in times[("after", view)])
            print(f"  {view:4s} {stage:11s} before {a:7.2f}  after {b:7.2f}  change {b - a:+6.2f}")


if __name__ == "__main__":
    main()
