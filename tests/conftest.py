"""Shared fixtures: one small simulated rig capture per test session (real renders, real OpenCV)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

# the database fixtures (db_url on SQLite and PostgreSQL, a migrated engine) live with the backend helpers
pytest_plugins = ("tests.backend_support",)

# workers started by the tests (and the servers they spawn) skip compiling the scan kernels at start:
# every test would pay a small scan for it; tests/test_warmup.py runs the warm-up itself
os.environ.setdefault("BODYSCAN_WARM_UP", "0")

SMALL = (1024, 683)


@pytest.fixture(scope="session")
def small_capture(tmp_path_factory) -> Path:
    """A 1024x683 capture: 8 calibration poses (40 stripes) and a side view with fur, plus truth/."""
    from measurement.simulate.capture import write_capture

    return write_capture(tmp_path_factory.mktemp("capture") / "cap", size=SMALL, poses=8, seed=5,
                         scenes=("side",))


@pytest.fixture(scope="session")
def small_truth(small_capture) -> dict:
    return json.loads((small_capture / "truth" / "truth.json").read_text())


@pytest.fixture(scope="session")
def small_calibration(small_capture):
    """The CalibrationResult of the small capture (computed once)."""
    from measurement.calibration import calibrate
    from measurement.capture import read_capture

    return calibrate(read_capture(small_capture))


def plane_angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle (deg) between the normals of plane rows a and b, (N,)."""
    return np.degrees(np.arccos(np.clip(np.abs(np.sum(a[:, :3] * b[:, :3], axis=1)), 0, 1)))


def plane_offset_at_1m(fit: np.ndarray, true: np.ndarray) -> np.ndarray:
    """Distance (mm) from the true plane's point nearest (0, 0, 1000) to the fitted plane, (N,)."""
    q = np.array([0.0, 0.0, 1000.0])
    x = q - (true[:, :3] @ q - true[:, 3])[:, None] * true[:, :3]
    return np.abs(np.sum(x * fit[:, :3], axis=1) - fit[:, 3])
