"""`bodyscan scan`: image files in, cloud.ply, scene.ply and measurements.json out."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

from .calibration import camera_gamma, load_calibration
from .errors import MeasurementError, ScanError, naming_files
from .images import read_image
from .pipeline import VIEWS, scan
from .ply import write_ply


def view_of(path: Path, given: str | None) -> str:
    """The view named on the command line, else the image's file name (side.png -> side)."""
    if given:
        return given
    stem = path.stem.lower()
    for v in VIEWS:
        if stem == v or stem.startswith(v + "_") or stem.startswith(v + "-"):
            return v
    raise ScanError(f"{path.name}: cannot tell the view from the file name; pass --view side|top|front|back")


def scan_files(calibration_path: Path, images: list[Path], out: Path, view: str | None = None,
               gamma: float | None = None) -> list[str]:
    """Scan each image; one image writes into OUT, several into OUT/<image stem>/. Returns summary lines.

    An ``<name>_ambient.<ext>`` beside an image (projector off) is used to cancel room light. ``gamma``: the
    camera's display gamma for these images, instead of the calibration's ``camera_gamma``. Every error
    names the image file it is about (the core's own messages say "image" or "ambient image").
    """
    cal = load_calibration(calibration_path)
    if gamma is not None:  # the camera's encoding, given for this scan (a calibration made without it)
        cal = replace(cal, gamma=camera_gamma(gamma, "--gamma"))
    if len(images) > 1:
        seen: dict[str, Path] = {}
        for path in images:
            if path.stem in seen:
                raise ScanError(f"{seen[path.stem]} and {path} would both be written to {out / path.stem}: "
                                "give the images different names, or scan them one at a time")
            seen[path.stem] = path
    lines = []
    for path in images:
        target = out if len(images) == 1 else out / path.stem
        v = view_of(path, view)
        image = read_image(path)
        ambient_path = next(iter(sorted(path.parent.glob(f"{path.stem}_ambient.*"))), None)
        ambient = read_image(ambient_path) if ambient_path else None
        try:
            result = scan(image, cal, v, ambient)
        except MeasurementError as exc:
            raise naming_files(exc, path.name, ambient_path.name if ambient_path else None) from None
        target.mkdir(parents=True, exist_ok=True)
        (target / "cloud.ply").write_bytes(write_ply(result.points, result.stripe))
        (target / "scene.ply").write_bytes(write_ply(result.scene_points, result.scene_stripe))
        meas = dict(result.measurements, image=path.name, timings_ms=result.timings_ms)
        (target / "measurements.json").write_text(json.dumps(meas, indent=1))
        m = result.measurements
        lines.append(f"{path.name} ({v}): {m['point_count']} animal points, {m['stripes_detected']} stripes, "
                     f"body length {m['body_length_mm']} mm, body height {m['body_height_mm']} mm -> {target}")
    return lines
