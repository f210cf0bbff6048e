"""Rig calibration: camera intrinsics (Zhang) + one light plane per stripe; load/save calibration.json."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from .board import BoardParams, abc_to_plane, find_corners, fit_plane_abc, object_points
from .camera import Intrinsics, rays
from .capture import Capture, gamma_problem
from .errors import CalibrationError, StripeDetectionError
from .orientation import AXES, stripe_axis, swap_xy, transpose_image
from .planes import fit_planes_detailed, plane_error_e2, planes_to_abc, point_plane_distance
from .stripes import StripeParams, detect_board_stripes


@dataclass(frozen=True, eq=False)
class Calibration:
    """What a scan needs from a calibration.

    intrinsics : camera model
    planes     : (N, 4) float64 [nx, ny, nz, d] with n.X = d (mm, camera frame), left to right (top to bottom
                 when the stripes run across the image); None if camera-only
    meta       : the rest of calibration.json (errors, poses, ...)
    stripe_axis: "vertical" (the paper's rig: the stripes run down the image) or "horizontal"
    transposed : whether this is the frame a horizontal-stripe rig is measured in (``in_row_frame``):
                 the image's rows and columns swapped, and with them x and y of rays, planes and points
    gamma      : the camera's display gamma (calibration.json's ``camera_gamma``): 1.0 for a camera that
                 writes light linearly (a machine-vision camera's raw mode), 2.2 for one that writes sRGB-like
                 (light)^(1 / 2.2); scans linearise its frames with it (``DetectionParams.gamma``)
    """

    intrinsics: Intrinsics
    planes: np.ndarray | None
    meta: dict = field(default_factory=dict)
    stripe_axis: str = "vertical"
    transposed: bool = False
    gamma: float = 1.0

    @property
    def stripes(self) -> int:
        return 0 if self.planes is None else len(self.planes)

    def in_row_frame(self) -> Calibration:
        """This calibration in the frame whose image rows cross the stripes: itself for vertical stripes;
        for horizontal ones, the transposed frame (planes with x and y swapped; ``transposed`` set, which
        ``triangulation.ray_table`` and the scan read)."""
        if self.stripe_axis == "vertical" or self.transposed:
            return self
        planes = None if self.planes is None else swap_xy(self.planes)
        return Calibration(self.intrinsics, planes, self.meta, "vertical", True, gamma=self.gamma)


def load_calibration(src: str | Path | dict) -> Calibration:
    """Read calibration.json (a path or an already parsed dict); CalibrationError names what is wrong."""
    name = "calibration"
    if not isinstance(src, (str, Path, dict)):
        raise CalibrationError(f"a calibration is a calibration.json path or its parsed object, not {type(src).__name__}")
    if isinstance(src, dict):
        data = src
    else:
        name = Path(src).name
        try:
            data = json.loads(Path(src).read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise CalibrationError(f"{name}: cannot read calibration ({exc})") from None
    if not isinstance(data, dict):
        raise CalibrationError(f"{name}: expected a JSON object")
    try:
        intr = Intrinsics.from_dict(data)
        raw = data.get("planes")
        planes = None if not raw else np.asarray(raw, dtype=np.float64).reshape(-1, 4)
    except (KeyError, TypeError, ValueError) as exc:
        raise CalibrationError(f"{name}: missing or malformed field ({exc})") from None
    if planes is not None and not np.all(np.isfinite(planes)):
        raise CalibrationError(f"{name}: planes hold non-finite numbers")
    axis = data.get("stripe_axis") or "vertical"  # calibrations made before it was recorded: the paper's rig
    if axis not in AXES:
        raise CalibrationError(f"{name}: stripe_axis must be one of {', '.join(AXES)}, got {axis!r}")
    return Calibration(intr, planes, {k: v for k, v in data.items() if k != "planes"}, axis,
                       gamma=camera_gamma(data.get("camera_gamma", 1.0), name))


def camera_gamma(value, name: str = "calibration") -> float:
    """A camera's display gamma as a float; CalibrationError, naming ``name`` and the field, when it is not a
    number in ``capture.GAMMA_RANGE`` (None, as calibrations made before it was recorded have it: 1.0, linear)."""
    if value is None:
        return 1.0
    problem = gamma_problem(value)
    if problem:
        raise CalibrationError(f"{name}: {problem}")
    return float(value)


def load_intrinsics(src: str | Path | dict) -> Intrinsics:
    """The camera part of an earlier calibration.json."""
    return load_calibration(src).intrinsics


# --- calibrating ---------------------------------------------------------------------------------

@dataclass(frozen=True)
class CalibrationParams:
    """Knobs of the whole calibration.

    plane_method : "abc" (the paper's z = A x + B y + C), "tls", "robust" (RANSAC + trimmed TLS) or
                   "pencil" (robust, then all planes share one axis through the projector)
    min_poses    : fewer usable board poses than this is an error (Zhang's method needs 3)
    outlier_factor: a pose whose reprojection error exceeds this many times the median is dropped
    camera_gamma : the camera's display gamma, recorded for the scans (``Calibration.gamma``); None: the
                   capture's rig.json's (``RigSettings.camera_gamma``). The board's stripe centres are read as
                   they are: a stripe on the flat board is a symmetric peak, whose centre no monotonic
                   encoding moves
    """

    stripes: StripeParams = field(default_factory=StripeParams)
    board: BoardParams = field(default_factory=BoardParams)
    plane_method: str = "pencil"
    min_poses: int = 3
    outlier_factor: float = 4.0
    camera_gamma: float | None = None


@dataclass(frozen=True, eq=False)
class PoseReport:
    """What happened to one calibration pose.

    used            : the pose's corners took part in the camera calibration
    used_for_planes : its stripe centres took part in the light-plane fit
    reason          : why not, when one of the two is False
    """

    name: str
    used: bool
    used_for_planes: bool = False
    reason: str | None = None
    reprojection_error_px: float | None = None
    stripe_rows: int = 0
    stripe_points: int = 0
    board_plane: list | None = None

    def to_dict(self) -> dict:
        return {"name": self.name, "used": self.used, "used_for_planes": self.used_for_planes,
                "reason": self.reason, "reprojection_error_px": self.reprojection_error_px,
                "stripe_rows": self.stripe_rows, "stripe_points": self.stripe_points,
                "board_plane": self.board_plane}


@dataclass(frozen=True, eq=False)
class CalibrationResult:
    """A finished calibration.

    planes          : (N, 4) [nx, ny, nz, d], n.X = d, mm, camera frame, left to right; None if camera-only
    plane_error     : E2 (Algorithm 4) of the final planes; zero up to rounding for a pencil fit, whose
                      planes share an axis by construction
    plane_error_unconstrained : E2 of the independent per-stripe fits, the paper's consistency check
    plane_rms_mm    : (N,) RMS distance of each stripe's board points to its plane
    plane_points    : (N,) number of points behind each plane
    """

    intrinsics: Intrinsics
    reprojection_error_px: float
    poses: list[PoseReport]
    rig: dict
    planes: np.ndarray | None = None
    plane_error: float | None = None
    plane_error_unconstrained: float | None = None
    plane_rms_mm: np.ndarray | None = None
    plane_points: np.ndarray | None = None
    plane_method: str | None = None
    stripe_method: str | None = None
    stripe_axis: str = "vertical"
    seconds: float = 0.0
    camera_gamma: float = 1.0

    def calibration(self) -> Calibration:
        return Calibration(self.intrinsics, self.planes, self.to_dict(), self.stripe_axis, gamma=self.camera_gamma)

    def to_dict(self) -> dict:
        d = {
            **self.intrinsics.to_dict(),
            "reprojection_error_px": self.reprojection_error_px,
            "planes": None if self.planes is None else self.planes.tolist(),
            "planes_abc": None if self.planes is None else planes_to_abc(self.planes).tolist(),
            "plane_error": self.plane_error,
            "plane_error_unconstrained": self.plane_error_unconstrained,
            "plane_rms_mm": None if self.plane_rms_mm is None else self.plane_rms_mm.tolist(),
            "plane_points": None if self.plane_points is None else self.plane_points.tolist(),
            "stripes": 0 if self.planes is None else len(self.planes),
            "stripe_axis": self.stripe_axis,
            "camera_gamma": self.camera_gamma,
            "plane_method": self.plane_method,
            "stripe_method": self.stripe_method,
            "rig": self.rig,
            "poses": [p.to_dict() for p in self.poses],
            "seconds": round(self.seconds, 3),
            "software": "bodyscan " + _version(),
        }
        return d


def _version() -> str:
    try:
        from importlib.metadata import version

        return version("bodyscan")
    except Exception:  # noqa: BLE001  not installed (running from a checkout)
        return "dev"


Progress = Callable[[float, str], None]
_WORKERS = 2  # this product targets small lab PCs; two threads already hide most of the I/O-free work


def calibrate(capture: Capture, intrinsics: Intrinsics | None = None, params: CalibrationParams | None = None,
              progress: Progress | None = None) -> CalibrationResult:
    """Calibrate the camera (Zhang, unless ``intrinsics`` are given) and one light plane per stripe.

    Poses whose board is not found, whose reprojection error is an outlier, or whose stripe image does not
    show all N stripes are skipped and reported with the reason. Raises CalibrationError when fewer than
    ``params.min_poses`` poses remain, naming the files.
    """
    params = params or CalibrationParams()
    gamma = capture.rig.camera_gamma if params.camera_gamma is None else camera_gamma(params.camera_gamma, "calibrate")
    report = progress or (lambda f, s: None)
    t0 = time.perf_counter()
    rig = capture.rig
    pattern = (rig.board_cols, rig.board_rows)
    if not capture.poses:
        raise CalibrationError("capture holds no calib/pose_NN_board images")
    size = (capture.poses[0].board.shape[1], capture.poses[0].board.shape[0])
    if intrinsics is not None and tuple(intrinsics.image_size) != size:
        raise CalibrationError(f"{capture.poses[0].board_file}: images are {size[0]}x{size[1]} but the given "
                               f"intrinsics are for {intrinsics.image_size[0]}x{intrinsics.image_size[1]}")
    corners: dict[str, np.ndarray] = {}
    reasons: dict[str, str] = {}
    report(0.0, "finding the chessboard")
    with ThreadPoolExecutor(max_workers=_WORKERS) as pool:  # OpenCV releases the GIL
        found_all = list(pool.map(lambda p: find_corners(p.board, pattern, params.board), capture.poses))
    for pose, c in zip(capture.poses, found_all, strict=True):
        if c is None:
            reasons[pose.name] = f"{pose.board_file}: chessboard {pattern[0]}x{pattern[1]} not found"
        else:
            corners[pose.name] = c
    _require_poses(corners, reasons, params.min_poses, pattern, capture)
    report(0.5, "calibrating the camera")
    intr, extr, errors = _camera(corners, rig.square_mm, pattern, size, intrinsics, reasons, params)
    _require_poses(extr, reasons, params.min_poses, pattern, capture)
    total_sq = sum(e**2 * len(corners[n]) for n, e in errors.items())
    e1 = float(np.sqrt(total_sq / sum(len(corners[n]) for n in errors)))
    groups: list[list[np.ndarray]] = [[] for _ in range(rig.stripes)]
    report(0.6, "finding stripe centres on the board")
    axis = _stripe_axis(capture, corners)
    with ThreadPoolExecutor(max_workers=_WORKERS) as pool:
        done = list(pool.map(lambda p: _pose_stripes(p, corners, extr, errors, reasons, intr, rig, pattern, params,
                                                     axis), capture.poses))
    pose_reports = [r for r, _ in done]
    for _, pts_by_stripe in done:
        for k, pts in enumerate(pts_by_stripe):
            groups[k].append(pts)
    have_stripes = any(p.stripes is not None for p in capture.poses)
    result = dict(intrinsics=intr, reprojection_error_px=e1, poses=pose_reports, rig=rig.to_dict(),
                  stripe_method=params.stripes.method, stripe_axis=axis, camera_gamma=float(gamma))
    if not have_stripes:
        return CalibrationResult(**result, seconds=time.perf_counter() - t0)
    plane_poses = [p for p in pose_reports if p.used_for_planes]
    if len(plane_poses) < 2:
        why = "; ".join(p.reason for p in pose_reports if p.reason) or "no stripe images"
        raise CalibrationError(f"light planes need at least 2 poses showing all {rig.stripes} stripes on the "
                               f"board, found {len(plane_poses)} ({why})")
    report(0.92, f"fitting {rig.stripes} light planes ({params.plane_method})")
    stacked = [np.vstack(g) for g in groups]
    if axis == "horizontal":  # fitted in the transposed frame, where the planes are ordered (and oriented)
        # left to right as the paper's are, then swapped back
        planes_t, masks, independent_t = fit_planes_detailed([swap_xy(g) for g in stacked], params.plane_method)
        planes, independent = swap_xy(planes_t), swap_xy(independent_t)
    else:
        planes, masks, independent = fit_planes_detailed(stacked, params.plane_method)
    rms = np.array([np.sqrt(np.mean(point_plane_distance(g[m], p) ** 2))
                    for g, m, p in zip(stacked, masks, planes, strict=True)])
    report(1.0, "done")
    return CalibrationResult(**result, planes=planes, plane_error=plane_error_e2(planes),
                             plane_error_unconstrained=plane_error_e2(independent), plane_rms_mm=rms,
                             plane_points=np.array([len(g) for g in stacked]), plane_method=params.plane_method,
                             seconds=time.perf_counter() - t0)


def _require_poses(found: dict, reasons: dict, n: int, pattern: tuple[int, int], capture: Capture) -> None:
    if len(found) >= n:
        return
    missing = [r for r in reasons.values() if "not found" in r]
    if len(missing) > len(capture.poses) / 2:
        where = "any" if not found else f"{len(missing)}"
        raise CalibrationError(
            f"chessboard {pattern[0]}x{pattern[1]} (inner corners) not found in {where} of the "
            f"{len(capture.poses)} board images (e.g. {missing[0].split(':')[0]}): check board_cols and "
            "board_rows against the plate")
    listed = "; ".join(reasons.values())
    raise CalibrationError(f"only {len(found)} usable board pose(s), at least {n} needed: {listed}")


def _camera(corners, square_mm, pattern, size, intrinsics, reasons, params):
    """Zhang's calibration (or PnP with fixed intrinsics), dropping poses with outlier reprojection error."""
    names = sorted(corners)
    obj = object_points(pattern, square_mm)
    while True:
        imgp = [corners[n].astype(np.float32).reshape(-1, 1, 2) for n in names]
        if intrinsics is None:
            _, K, dist, rvecs, tvecs = cv2.calibrateCamera(
                [obj] * len(names), imgp, size, None, None,
                criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12))
            intr = Intrinsics(K, dist.ravel()[:5] if dist.size >= 5 else np.pad(dist.ravel(), (0, 5 - dist.size)),
                              size)
        else:
            intr = intrinsics
            rvecs, tvecs = [], []
            for p in imgp:
                ok, rv, tv = cv2.solvePnP(obj, p, intr.camera_matrix, intr.dist_coeffs, flags=cv2.SOLVEPNP_ITERATIVE)
                rvecs.append(rv)
                tvecs.append(tv)
        errors = {}
        extr = {}
        for n, p, rv, tv in zip(names, imgp, rvecs, tvecs, strict=True):
            proj, _ = cv2.projectPoints(obj, rv, tv, intr.camera_matrix, intr.dist_coeffs)
            errors[n] = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - p.reshape(-1, 2)) ** 2, axis=1))))
            extr[n] = (cv2.Rodrigues(rv)[0], tv.ravel())
        med = float(np.median(list(errors.values())))
        worst = max(errors, key=errors.get)
        if errors[worst] > max(params.outlier_factor * med, 0.5) and len(names) > params.min_poses:
            reasons[worst] = (f"reprojection error {errors[worst]:.2f} px is an outlier "
                              f"(median {med:.2f} px): corners misdetected or the board moved")
            names.remove(worst)
            continue
        return intr, extr, errors


def _stripe_axis(capture: Capture, corners: dict) -> str:
    """Which way the calibration's stripes run (``orientation.stripe_axis``): the majority over the poses
    whose board was found and which have a stripe image (vertical when none has)."""
    votes = [stripe_axis(p.stripes, p.board) for p in capture.poses if p.stripes is not None and p.name in corners]
    return "horizontal" if votes.count("horizontal") > len(votes) / 2 else "vertical"


def _pose_stripes(pose, corners, extr, errors, reasons, intr, rig, pattern, params, axis: str = "vertical"
                  ) -> tuple[PoseReport, list[np.ndarray]]:
    """One pose's report and its stripe centres on the board plane, grouped by stripe ((M_k, 3) mm each).
    With ``axis`` "horizontal" the stripes are found in the transposed images (labelled top to bottom)."""
    if pose.name not in extr:
        return PoseReport(pose.name, False, reason=reasons.get(pose.name)), []
    R, t = extr[pose.name]
    # the paper's board plane: least squares (eq. 2-4) through the corners in camera coordinates; the
    # corners are coplanar by construction, so it equals the extrinsics' plane to rounding
    corners_cam = object_points(pattern, rig.square_mm).astype(np.float64) @ R.T + t
    plane = abc_to_plane(fit_plane_abc(corners_cam))
    base = dict(name=pose.name, used=True, reprojection_error_px=errors[pose.name], board_plane=plane.tolist())
    if pose.stripes is None:
        return PoseReport(**base, reason="no stripe image"), []
    try:
        if axis == "horizontal":
            cols, rows = pattern
            grid_t = corners[pose.name].reshape(rows, cols, 2).transpose(1, 0, 2)[..., ::-1].reshape(-1, 2)
            found = detect_board_stripes(transpose_image(pose.stripes),
                                         None if pose.board is None else transpose_image(pose.board),
                                         np.ascontiguousarray(grid_t), (rows, cols), rig.stripes, params.stripes,
                                         pose.stripes_file or pose.name)
            uv = found.uv[:, ::-1]
        else:
            found = detect_board_stripes(pose.stripes, pose.board, corners[pose.name], pattern, rig.stripes,
                                         params.stripes, pose.stripes_file or pose.name)
            uv = found.uv
    except StripeDetectionError as exc:
        return PoseReport(**base, reason=str(exc)), []
    pts = backproject_to_plane(uv, plane, intr)
    by_stripe = [pts[found.stripe == k] for k in range(rig.stripes)]
    report = PoseReport(**base, used_for_planes=True, stripe_rows=found.rows_used, stripe_points=len(pts))
    return report, by_stripe


def backproject_to_plane(uv: np.ndarray, plane: np.ndarray, intr: Intrinsics) -> np.ndarray:
    """Intersect the viewing rays of distorted pixels with a plane (eq. 5-6 of the paper, after undistortion).

    uv : (N, 2) pixels; plane : [nx, ny, nz, d] with n.X = d; returns (N, 3) mm camera frame
    """
    r = rays(uv, intr)
    s = plane[3] / (r @ plane[:3])
    return r * s[:, None]
