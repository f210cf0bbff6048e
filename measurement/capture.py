"""The capture layout: rig.json, calib/pose_NN_board|stripes.*, scan/<view>.* — from a folder, files or a zip."""

from __future__ import annotations

import io
import json
import re
import zipfile
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

import numpy as np

from .errors import CaptureError
from .images import IMAGE_SUFFIXES, decode_image

POSE_RE = re.compile(r"^pose_(\d+)_(board|stripes)$")
VIEWS = ("side", "top", "front", "back")


@dataclass(frozen=True)
class RigSettings:
    """Chessboard inner corners (OpenCV pattern size), square size in mm and projector stripe count; and
    the camera's display gamma (optional in rig.json: 1.0, linear; 2.2 for a camera writing sRGB-like
    images), which the calibration records for its scans (``Calibration.gamma``)."""

    board_cols: int
    board_rows: int
    square_mm: float
    stripes: int
    camera_gamma: float = 1.0

    def __post_init__(self) -> None:
        for name in ("board_cols", "board_rows", "stripes"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 2:
                raise CaptureError(f"rig.json: {name} must be an integer >= 2, got {v!r}")
        if not (isinstance(self.square_mm, (int, float)) and 0 < self.square_mm < 1000):
            raise CaptureError(f"rig.json: square_mm must be a positive number of millimetres, got {self.square_mm!r}")
        problem = gamma_problem(self.camera_gamma)
        if problem:
            raise CaptureError(f"rig.json: {problem}")

    @classmethod
    def from_dict(cls, d: dict, source: str = "rig.json") -> RigSettings:
        if not isinstance(d, dict):
            raise CaptureError(f"{source}: expected a JSON object")
        missing = [k for k in ("board_cols", "board_rows", "square_mm", "stripes") if d.get(k) is None]
        if missing:
            raise CaptureError(f"{source}: missing field(s) {', '.join(missing)}")
        values: dict = {}
        for key, kind in (("board_cols", int), ("board_rows", int), ("square_mm", float), ("stripes", int)):
            v = d[key]
            try:
                if isinstance(v, bool) or (kind is int and isinstance(v, float) and not v.is_integer()):
                    raise ValueError
                values[key] = kind(v)
            except (TypeError, ValueError):
                raise CaptureError(f"{source}: {key} must be a{'n integer' if kind is int else ' number'}, "
                                   f"got {v!r}") from None
        gamma = d.get("camera_gamma")
        problem = gamma_problem(gamma) if gamma is not None else None
        if problem:
            raise CaptureError(f"{source}: {problem}")
        return cls(**values, camera_gamma=1.0 if gamma is None else float(gamma))

    def to_dict(self) -> dict:
        return {"board_cols": self.board_cols, "board_rows": self.board_rows,
                "square_mm": self.square_mm, "stripes": self.stripes, "camera_gamma": self.camera_gamma}


GAMMA_RANGE = (0.2, 5.0)  # display gammas a camera may write with (1.0: linear; sRGB is about 2.2)


def gamma_problem(value) -> str | None:
    """What is wrong with a camera display gamma ``value`` (None if it is a number in ``GAMMA_RANGE``)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
            GAMMA_RANGE[0] <= float(value) <= GAMMA_RANGE[1]):
        return (f"camera_gamma must be a number from {GAMMA_RANGE[0]} to {GAMMA_RANGE[1]} (1.0: the camera "
                f"writes light linearly; 2.2: sRGB), got {value!r}")
    return None


@dataclass(frozen=True, eq=False)
class Pose:
    """One calibration pose: board image (room light) and optional stripe image, (H, W) uint8/uint16."""

    name: str
    board_file: str
    board: np.ndarray
    stripes_file: str | None = None
    stripes: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class Capture:
    """A decoded capture: rig settings, calibration poses in name order, scan images by view name."""

    rig: RigSettings
    poses: list[Pose]
    scans: dict[str, np.ndarray] = field(default_factory=dict)


def read_capture(folder: str | Path) -> Capture:
    """Read a capture folder; CaptureError/ImageError name the offending file."""
    folder = Path(folder)
    if not folder.is_dir():
        raise CaptureError(f"{folder}: capture folder not found")
    files: dict[str, bytes] = {}
    for path in sorted(folder.rglob("*")):
        rel = path.relative_to(folder).as_posix()
        if path.is_file() and (rel == "rig.json" or _is_image_in(rel, ("calib", "scan"))):
            files[rel] = path.read_bytes()
    return capture_from_files(files)


def capture_from_zip(data: bytes, rig: RigSettings | None = None, max_bytes: int = 2 << 30) -> Capture:
    """Read a zip of a capture folder (optionally wrapped in one top folder); rejects path tricks."""
    try:
        zf = zipfile.ZipFile(io.BytesIO(data))
    except zipfile.BadZipFile:
        raise CaptureError("archive: not a zip file") from None
    files: dict[str, bytes] = {}
    total = 0
    with zf:
        for info in zf.infolist():
            if info.is_dir():
                continue
            name = _safe_member(info.filename)
            total += info.file_size
            if total > max_bytes:
                raise CaptureError(f"archive: uncompressed size exceeds {max_bytes} bytes")
            try:
                files[name] = zf.read(info)
            except (zipfile.BadZipFile, OSError, EOFError) as exc:
                raise CaptureError(f"archive: {name}: cannot extract ({exc})") from None
    return capture_from_files(_strip_common_top(files), rig)


def capture_from_files(files: dict[str, bytes], rig: RigSettings | None = None) -> Capture:
    """Build a capture from relative paths -> bytes.

    Accepts 'rig.json', 'calib/pose_01_board.png' or bare 'pose_01_board.png', 'scan/side.png'.
    ``rig`` overrides rig.json; one of the two is required.
    """
    if rig is None:
        if "rig.json" not in files:
            raise CaptureError("rig.json: missing (give board_cols, board_rows, square_mm, stripes)")
        try:
            rig = RigSettings.from_dict(json.loads(files["rig.json"].decode("utf-8")))
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise CaptureError(f"rig.json: not valid JSON ({exc})") from None
    boards: dict[str, tuple[str, bytes]] = {}
    stripes: dict[str, tuple[str, bytes]] = {}
    scans: dict[str, np.ndarray] = {}
    for rel, data in sorted(files.items()):
        p = PurePosixPath(rel)
        if rel == "rig.json" or p.suffix.lower() not in IMAGE_SUFFIXES:
            continue
        m = POSE_RE.match(p.stem)
        if m and (len(p.parts) == 1 or p.parts[-2] == "calib"):
            (boards if m.group(2) == "board" else stripes)[f"pose_{m.group(1)}"] = (p.name, data)
        elif len(p.parts) >= 2 and p.parts[-2] == "scan":
            scans[p.stem] = decode_image(data, rel)
        elif p.parts[0] == "calib":
            raise CaptureError(f"{rel}: calibration images must be named pose_NN_board or pose_NN_stripes")
    for name, (fname, _) in stripes.items():
        if name not in boards:
            raise CaptureError(f"{fname}: no matching {name}_board image")
    poses = []
    for name in sorted(boards, key=lambda n: int(n.split("_")[1])):
        bname, bdata = boards[name]
        sname, sdata = stripes.get(name, (None, None))
        stripes_img = decode_image(sdata, sname) if sdata is not None and sname is not None else None
        poses.append(Pose(name, bname, decode_image(bdata, bname), sname, stripes_img))
    if not poses and not scans:
        raise CaptureError("capture holds no calib/pose_NN_board images and no scan images")
    _check_sizes(poses)
    return Capture(rig, poses, scans)


def _check_sizes(poses: list[Pose]) -> None:
    if not poses:
        return
    ref = poses[0].board.shape
    for pose in poses:
        for fname, img in ((pose.board_file, pose.board), (pose.stripes_file, pose.stripes)):
            if img is not None and img.shape != ref:
                raise CaptureError(
                    f"{fname}: image is {img.shape[1]}x{img.shape[0]}, but {poses[0].board_file} is "
                    f"{ref[1]}x{ref[0]}: all calibration images must have one size"
                )


def _is_image_in(rel: str, folders: tuple[str, ...]) -> bool:
    p = PurePosixPath(rel)
    return len(p.parts) == 2 and p.parts[0] in folders and p.suffix.lower() in IMAGE_SUFFIXES


def _safe_member(name: str) -> str:
    p = PurePosixPath(name.replace("\\", "/"))
    if p.is_absolute() or ".." in p.parts or name.startswith(("/", "\\")) or ":" in p.parts[0]:
        raise CaptureError(f"archive: unsafe path {name!r} (absolute or '..' paths are refused)")
    return p.as_posix()


def _strip_common_top(files: dict[str, bytes]) -> dict[str, bytes]:
    """Allow a zip that wraps the capture in one folder (capture/rig.json ...)."""
    tops = {PurePosixPath(n).parts[0] for n in files}
    if len(tops) == 1 and all(len(PurePosixPath(n).parts) > 1 for n in files):
        top = tops.pop()
        inner = {n[len(top) + 1:]: d for n, d in files.items()}
        if "rig.json" in inner or any(n.startswith("calib/") for n in inner):
            return inner
    return files
