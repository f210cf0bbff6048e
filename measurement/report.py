"""The calibration report image: per-pose reprojection error (E1) and per-plane residuals, as the paper's
Figure 15a-b shows them, drawn with OpenCV (no plotting library needed)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from .calibration import CalibrationResult

_W, _H = 1200, 760
_FONT = cv2.FONT_HERSHEY_SIMPLEX


def _bars(canvas: np.ndarray, box: tuple[int, int, int, int], values: list, labels: list[str],
          title: str, unit: str, colours: list[tuple[int, int, int]]) -> None:
    x0, y0, x1, y1 = box
    cv2.putText(canvas, title, (x0, y0 - 12), _FONT, 0.6, (20, 20, 20), 1, cv2.LINE_AA)
    cv2.rectangle(canvas, (x0, y0), (x1, y1), (180, 180, 180), 1)
    finite = [v for v in values if v is not None and np.isfinite(v)]
    top = max(finite) * 1.15 if finite else 1.0
    n = max(len(values), 1)
    slot = (x1 - x0) / n
    for i, (v, lab, col) in enumerate(zip(values, labels, colours, strict=True)):
        bx = int(x0 + i * slot + slot * 0.15)
        bw = max(int(slot * 0.7), 1)
        if v is not None and np.isfinite(v):
            by = int(y1 - (y1 - y0) * v / top)
            cv2.rectangle(canvas, (bx, by), (bx + bw, y1), col, -1)
        else:
            cv2.line(canvas, (bx, y1 - 4), (bx + bw, y1 - 4), (0, 0, 200), 2)
        if n <= 24 or i % max(1, n // 20) == 0:
            cv2.putText(canvas, lab, (bx, y1 + 16), _FONT, 0.38, (60, 60, 60), 1, cv2.LINE_AA)
    for frac in (0.0, 0.5, 1.0):
        val = top * frac / 1.15
        y = int(y1 - (y1 - y0) * val / top)
        cv2.putText(canvas, f"{val:.3g} {unit}", (x1 + 6, y + 4), _FONT, 0.4, (90, 90, 90), 1, cv2.LINE_AA)


def render_report(result: CalibrationResult) -> np.ndarray:
    """(760, 1200, 3) uint8 BGR report image."""
    canvas = np.full((_H, _W, 3), 255, np.uint8)
    k = result.intrinsics
    head = (f"E1 = {result.reprojection_error_px:.4f} px   fx = {k.fx:.2f}  fy = {k.fy:.2f}  "
            f"cx = {k.cx:.2f}  cy = {k.cy:.2f}")
    cv2.putText(canvas, head, (30, 36), _FONT, 0.65, (0, 0, 0), 1, cv2.LINE_AA)
    if result.planes is not None and result.plane_rms_mm is not None:
        line2 = (f"{len(result.planes)} light planes ({result.plane_method}), E2 = {result.plane_error:.3g} "
                 f"(independent fits {result.plane_error_unconstrained:.3g}), "
                 f"median plane residual {np.median(result.plane_rms_mm):.3f} mm")
        cv2.putText(canvas, line2, (30, 64), _FONT, 0.55, (0, 0, 0), 1, cv2.LINE_AA)
    poses = result.poses
    colours = [(180, 120, 40) if p.used_for_planes else (120, 180, 60) if p.used else (60, 60, 200)
               for p in poses]
    _bars(canvas, (40, 120, 1080, 380), [p.reprojection_error_px for p in poses],
          [p.name.replace("pose_", "") for p in poses], "Reprojection error per pose (blue: camera + planes, "
          "green: camera only, red line: skipped)", "px", colours)
    if result.planes is not None and result.plane_rms_mm is not None:
        n = len(result.planes)
        _bars(canvas, (40, 460, 1080, 700), list(result.plane_rms_mm), [str(i) for i in range(n)],
              "RMS distance of each stripe's board points to its light plane", "mm", [(40, 120, 200)] * n)
    return canvas


def write_report(result: CalibrationResult, path: str | Path) -> Path:
    """Write the report PNG and return its path."""
    path = Path(path)
    cv2.imwrite(str(path), render_report(result))
    return path
