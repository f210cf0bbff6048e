import json
import shutil

import numpy as np
import pytest

from measurement.calibration import calibrate, load_calibration, load_intrinsics
from measurement.capture import read_capture
from measurement.errors import CalibrationError
from measurement.report import write_report
from measurement.simulate.capture import write_capture
from tests.conftest import SMALL, plane_angle_deg, plane_offset_at_1m


def test_camera_matches_truth(small_calibration, small_truth):
    K = small_calibration.intrinsics.camera_matrix
    Kt = np.array(small_truth["camera_matrix"])
    for (i, j) in ((0, 0), (1, 1), (0, 2), (1, 2)):
        assert abs(K[i, j] / Kt[i, j] - 1) < 0.003
    assert small_calibration.reprojection_error_px < 0.2


def test_light_planes_match_truth(small_calibration, small_truth):
    planes = small_calibration.planes
    true = np.array(small_truth["planes"])
    assert planes.shape == (40, 4)
    assert np.allclose(np.linalg.norm(planes[:, :3], axis=1), 1)
    # at a third of the full resolution, still well inside the full-resolution targets (0.05 deg, 0.3 mm)
    assert plane_angle_deg(planes, true).max() < 0.05
    assert plane_offset_at_1m(planes, true).max() < 0.5
    assert np.all(np.diff(planes[:, 3] / planes[:, 0]) != 0)


def test_calibration_json_holds_the_contract_fields(small_calibration, tmp_path):
    d = small_calibration.to_dict()
    for key in ("image_size", "camera_matrix", "dist_coeffs", "reprojection_error_px", "planes", "planes_abc",
                "plane_error", "poses"):
        assert key in d
    assert d["image_size"] == list(SMALL)
    assert len(d["planes_abc"]) == 40 and all(len(p) == 3 for p in d["planes_abc"])
    assert all({"name", "used", "reason", "reprojection_error_px"} <= set(p) for p in d["poses"])
    path = tmp_path / "calibration.json"
    path.write_text(json.dumps(d))
    back = load_calibration(path)
    assert np.allclose(back.planes, small_calibration.planes) and back.stripes == 40
    assert d["camera_gamma"] == 1.0 and back.gamma == 1.0
    assert write_report(small_calibration, tmp_path / "report.png").stat().st_size > 1000


def test_the_camera_s_display_gamma_is_recorded_read_and_checked(small_calibration, tmp_path):
    """``camera_gamma`` says how the camera encodes light (1.0: linearly; 2.2: sRGB-like); calibration.json
    records it, the scans read it (also in the transposed frame of a horizontal-stripe rig), a calibration
    made before it was recorded is linear, and a value that is not a plausible gamma is refused by name."""
    from dataclasses import replace

    d = {**small_calibration.to_dict(), "camera_gamma": 2.2}
    cal = load_calibration(d)
    assert cal.gamma == 2.2 and replace(cal, stripe_axis="horizontal").in_row_frame().gamma == 2.2
    assert load_calibration({k: v for k, v in d.items() if k != "camera_gamma"}).gamma == 1.0
    assert load_calibration({**d, "camera_gamma": None}).gamma == 1.0
    assert replace(small_calibration, camera_gamma=1.8).calibration().gamma == 1.8
    (tmp_path / "cal.json").write_text(json.dumps({**d, "camera_gamma": 0}))
    for bad in ("2.2", True, -1, 0, 9.0, [2.2]):
        with pytest.raises(CalibrationError, match="camera_gamma must be a number from 0.2 to 5.0"):
            load_calibration({**d, "camera_gamma": bad})
    with pytest.raises(CalibrationError, match="cal.json: camera_gamma"):
        load_calibration(tmp_path / "cal.json")


def test_paper_plane_form_and_pencil_agree_with_truth_within_targets(small_capture, small_truth):
    from measurement.calibration import CalibrationParams

    cap = read_capture(small_capture)
    true = np.array(small_truth["planes"])
    for method in ("abc", "robust"):
        r = calibrate(cap, params=CalibrationParams(plane_method=method))
        assert plane_angle_deg(r.planes, true).max() < 0.1, method


def test_unusable_poses_are_skipped_and_named(tmp_path):
    cap = write_capture(tmp_path / "cap", size=(800, 533), poses=6, seed=9, scenes=(),
                        defects={2: "no_board", 5: "no_stripes"})
    r = calibrate(read_capture(cap))
    by_name = {p.name: p for p in r.poses}
    assert not by_name["pose_02"].used and "chessboard 14x10 not found" in by_name["pose_02"].reason
    assert "pose_02_board.png" in by_name["pose_02"].reason
    assert by_name["pose_05"].used and not by_name["pose_05"].used_for_planes
    assert "pose_05_stripes.png" in by_name["pose_05"].reason
    assert sum(p.used_for_planes for p in r.poses) == 4


def test_fewer_than_three_poses_is_an_error_naming_them(small_capture, tmp_path):
    cap = tmp_path / "cap"
    shutil.copytree(small_capture, cap)
    for f in (cap / "calib").glob("pose_0[3-9]*"):
        f.unlink()
    with pytest.raises(CalibrationError, match="only 2 usable board pose"):
        calibrate(read_capture(cap))


def test_a_wrong_board_size_is_an_error_that_says_so(small_capture, tmp_path):
    cap = tmp_path / "cap"
    shutil.copytree(small_capture, cap)
    (cap / "rig.json").write_text(json.dumps({"board_cols": 11, "board_rows": 8, "square_mm": 40, "stripes": 40}))
    with pytest.raises(CalibrationError, match="chessboard 11x8 .* not found in (any|[0-9]+) of the 8 board images"):
        calibrate(read_capture(cap))


def test_board_images_alone_give_a_camera_only_calibration_that_a_later_capture_reuses(small_capture, tmp_path,
                                                                                        small_truth):
    cam_only = tmp_path / "camera"
    shutil.copytree(small_capture, cam_only)
    for f in (cam_only / "calib").glob("*_stripes.png"):
        f.unlink()
    r = calibrate(read_capture(cam_only))
    assert r.planes is None and r.to_dict()["planes"] is None
    path = tmp_path / "camera.json"
    path.write_text(json.dumps(r.to_dict()))
    again = calibrate(read_capture(small_capture), intrinsics=load_intrinsics(path))
    assert np.allclose(again.intrinsics.camera_matrix, r.intrinsics.camera_matrix)
    assert plane_angle_deg(again.planes, np.array(small_truth["planes"])).max() < 0.05


def test_intrinsics_of_another_image_size_are_refused(small_capture, small_calibration):
    from measurement.camera import Intrinsics

    k = small_calibration.intrinsics
    other = Intrinsics(k.camera_matrix, k.dist_coeffs, (640, 480))
    with pytest.raises(CalibrationError, match="640x480"):
        calibrate(read_capture(small_capture), intrinsics=other)


def test_progress_is_reported_in_order(small_capture):
    seen = []
    calibrate(read_capture(small_capture), progress=lambda f, s: seen.append((f, s)))
    fractions = [f for f, _ in seen]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    assert any("light planes" in s for _, s in seen)


def test_a_malformed_calibration_is_a_calibration_error_naming_it(tmp_path):
    good = {"image_size": [640, 480], "camera_matrix": [[500, 0, 320], [0, 500, 240], [0, 0, 1]],
            "dist_coeffs": [0, 0, 0, 0, 0], "planes": [[0.9, 0.0, -0.4, 100.0]]}
    assert load_calibration(good).planes.shape == (1, 4)
    for bad, says in (({**good, "dist_coeffs": [float("nan")] * 5}, "malformed field .*finite"),
                      ({**good, "planes": [[0.9, 0.0, float("inf"), 1.0]]}, "non-finite"),
                      ({k: v for k, v in good.items() if k != "camera_matrix"}, "missing or malformed")):
        with pytest.raises(CalibrationError, match=says):
            load_calibration(bad)
    (tmp_path / "calibration.json").write_text("[1, 2]")
    with pytest.raises(CalibrationError, match="calibration.json: expected a JSON object"):
        load_calibration(tmp_path / "calibration.json")
    with pytest.raises(CalibrationError, match="not list"):
        load_calibration([good])


def test_twelve_bit_samples_in_sixteen_bit_files_calibrate_as_the_eight_bit_capture(small_capture, small_calibration,
                                                                                    tmp_path):
    """A Mono12 camera's frames written unshifted into 16-bit PNGs (values 0-4095): before, the stripe images
    were scaled by 1/257 to 16 gray levels and each pose kept a tenth of its rows showing every stripe."""
    import cv2

    cap = tmp_path / "cap"
    shutil.copytree(small_capture, cap)
    for f in sorted((cap / "calib").glob("*.png")):
        img = cv2.imread(str(f), cv2.IMREAD_UNCHANGED)
        cv2.imwrite(str(f), np.round(img.astype(np.float64) * 4095.0 / 255.0).astype(np.uint16))
    twelve = calibrate(read_capture(cap))
    for a, b in zip(twelve.poses, small_calibration.poses, strict=True):  # the rounding to 12 bits moves a few
        assert abs(a.stripe_rows - b.stripe_rows) <= 0.02 * b.stripe_rows
    assert np.abs(twelve.planes - small_calibration.planes).max() < 0.01
