"""A starting worker compiles the scan kernels, so that the first scan job does not wait for them."""

from __future__ import annotations

import logging
import subprocess
import sys
import threading
import time
from pathlib import Path

from app import jobs as runner
from tests.backend_support import settings_for

ROOT = Path(__file__).resolve().parents[1]
# kernels on every step of a scan: detection, matching (growth, pieces, offsets), triangulation, measurement
KERNELS = ("first_peaks", "refine_peaks", "link_components", "grow_piece", "distinct_cells", "gap_votes",
           "grow_by_slope", "cloud_points", "group_extents", "walk_ends", "group_extent_with", "walk_stops")


def test_warm_up_compiles_the_kernels_of_every_scan_step_in_a_fresh_process():
    code = ("from measurement import _kernels\n"
            f"names = {KERNELS!r}\n"
            "before = [n for n in names if getattr(_kernels, n).signatures]\n"
            "from measurement.warmup import warm_up\n"
            "seconds = warm_up()\n"
            "after = [n for n in names if not getattr(_kernels, n).signatures]\n"
            "print(before, after, seconds)\n")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("[] [] "), out.stdout  # none compiled before, none left uncompiled after


def test_a_worker_started_with_warm_up_reports_its_kernels_ready(tmp_path, caplog):
    settings = settings_for(tmp_path, warm_up=True, poll_s=0.05)
    stop = threading.Event()
    with caplog.at_level(logging.INFO, logger="app.jobs"):
        worker = threading.Thread(target=runner.run_worker, args=(settings, stop), daemon=True)
        worker.start()
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline and not any("scan kernels ready" in r.message for r in caplog.records):
            time.sleep(0.1)
        stop.set()
        worker.join(30)
    assert any("scan kernels ready" in r.message for r in caplog.records)
