"""bodyscan's measurement core: calibration, scan pipeline and rig simulator (numpy, OpenCV, trimesh only).

Public API (what the CLI, the jobs and the benchmarks call):

- ``read_capture(folder)`` / ``capture_from_files(files, rig)`` / ``capture_from_zip(data)`` -> ``Capture``
- ``calibrate(capture, intrinsics=None, progress=None)`` -> ``CalibrationResult`` (``.to_dict()`` is calibration.json)
- ``load_calibration(path_or_dict)`` -> ``Calibration``
- ``scan(image, calibration, view="side", ambient=None)`` -> ``ScanResult``
"""

from .calibration import load_calibration
from .errors import (
    CalibrationError,
    CaptureError,
    ImageError,
    MeasurementError,
    ScanError,
    StripeDetectionError,
)
from .pipeline import ScanResult, scan

__all__ = [
    "CalibrationError",
    "CaptureError",
    "ImageError",
    "MeasurementError",
    "ScanError",
    "ScanResult",
    "StripeDetectionError",
    "load_calibration",
    "scan",
]
