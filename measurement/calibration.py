"""Rig calibration: camera intrinsics (Zhang) + one light plane per stripe; load/save calibration.json."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .camera import Intrinsics
from .errors import CalibrationError


@dataclass(frozen=True, eq=False)
class Calibration:
    """What a scan needs from a calibration.

    intrinsics : camera model
    planes     : (N, 4) float64 [nx, ny, nz, d] with n.X = d (mm, camera frame), left to right; None if camera-only
    meta       : the rest of calibration.json (errors, poses, ...)
    """

    intrinsics: Intrinsics
    planes: np.ndarray | None
    meta: dict = field(default_factory=dict)

    @property
    def stripes(self) -> int:
        return 0 if self.planes is None else len(self.planes)


def load_calibration(src: str | Path | dict) -> Calibration:
    """Read calibration.json (a path or an already parsed dict); CalibrationError names what is wrong."""
    name = "calibration"
    if not isinstance(src, dict):
        name = Path(src).name
        try:
            src = json.loads(Path(src).read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise CalibrationError(f"{name}: cannot read calibration ({exc})") from None
    try:
        intr = Intrinsics.from_dict(src)
        planes = src.get("planes")
        planes = None if not planes else np.asarray(planes, dtype=np.float64).reshape(-1, 4)
    except (KeyError, TypeError, ValueError) as exc:
        raise CalibrationError(f"{name}: missing or malformed field ({exc})") from None
    return Calibration(intr, planes, {k: v for k, v in src.items() if k != "planes"})


def load_intrinsics(src: str | Path | dict) -> Intrinsics:
    """The camera part of an earlier calibration.json."""
    return load_calibration(src).intrinsics
