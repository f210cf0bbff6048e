"""Compile the scan's kernels before a technician's first scan.

The compiled kernels (``measurement._kernels``) are built on their first call: about 40 s on this 2-core
machine without numba's on-disk cache, 2-3 s to load them from it. A job worker calls ``warm_up`` when it
starts, so the first scan job does not wait for it.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path


def warm_up(size: tuple[int, int] = (768, 512)) -> float:
    """Render a small simulated side view (the procedural quadruped under 40 stripes) and scan it, so that
    every kernel on the scan's path is compiled or loaded now. Returns the seconds it took."""
    from .calibration import load_calibration
    from .images import read_image
    from .pipeline import scan
    from .simulate.capture import write_capture

    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="bodyscan-warm-up-") as tmp:
        cap = write_capture(Path(tmp) / "capture", size=size, poses=0, seed=1, scenes=("side",))
        calibration = load_calibration(cap / "truth" / "truth.json")
        image = read_image(cap / "scan" / "side.png")
    scan(image, calibration, "side")
    return time.perf_counter() - start
