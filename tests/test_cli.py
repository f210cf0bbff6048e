"""The `bodyscan` command line: real subprocesses, clear errors, never a traceback."""

import json
import shutil
import subprocess
import sys

import pytest


def bodyscan(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "app.cli", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, timeout=600)


def test_simulate_then_calibrate_writes_calibration_json_and_report(tmp_path):
    cap = tmp_path / "cap"
    r = bodyscan("simulate", cap, "--size", "800x533", "--poses", "5", "--seed", "3", "--scene", "side")
    assert r.returncode == 0, r.stderr
    r = bodyscan("calibrate", cap, "-o", tmp_path / "out" / "calibration.json")
    assert r.returncode == 0, r.stderr
    cal = json.loads((tmp_path / "out" / "calibration.json").read_text())
    assert len(cal["planes"]) == 40 and len(cal["poses"]) == 5
    assert (tmp_path / "out" / "calibration.png").exists()
    assert "reprojection error" in r.stdout


def test_a_camera_writing_srgb_is_simulated_calibrated_and_scanned_with_its_gamma(tmp_path):
    """`simulate --gamma 2.2` writes every image as an sRGB-like camera would, and rig.json says so;
    `calibrate` records camera_gamma from rig.json and calibrates as well as from linear images; the scan
    linearises with it and labels the animal as the simulator's truth has it."""
    import numpy as np

    from measurement import load_calibration, scan
    from measurement.images import read_image
    from measurement.simulate.truth import match_crossings

    cap = tmp_path / "cap"
    r = bodyscan("simulate", cap, "--size", "1024x683", "--poses", "6", "--seed", "5", "--scene", "side",
                 "--gamma", "2.2")
    assert r.returncode == 0, r.stderr
    assert json.loads((cap / "rig.json").read_text())["camera_gamma"] == 2.2
    assert read_image(cap / "scan" / "side_ambient.png").mean() > 40  # dim room light lifted by the encoding
    assert bodyscan("calibrate", cap, "-o", tmp_path / "calibration.json").returncode == 0
    cal, truth = (json.loads(p.read_text()) for p in (tmp_path / "calibration.json", cap / "truth" / "truth.json"))
    assert cal["camera_gamma"] == 2.2 and cal["reprojection_error_px"] < 0.2
    normals = np.array(cal["planes"])[:, :3], np.array(truth["planes"])[:, :3]
    assert np.degrees(np.arccos(np.clip(np.abs(np.sum(normals[0] * normals[1], axis=1)), 0, 1))).max() < 0.1
    r = bodyscan("scan", tmp_path / "calibration.json", cap / "scan" / "side.png", "-o", tmp_path / "out")
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "out" / "measurements.json").read_text())["point_count"] > 1000
    result = scan(read_image(cap / "scan" / "side.png"), load_calibration(tmp_path / "calibration.json"), "side")
    tk, kind = match_crossings(result.scene_uv, dict(np.load(cap / "truth" / "side_stripes.npz")))
    animal = kind == 5
    assert animal.sum() > 1000 and np.mean(result.scene_stripe[animal] == tk[animal]) > 0.98
    r = bodyscan("simulate", tmp_path / "x", "--gamma", "0")
    assert r.returncode == 2 and "--gamma: camera_gamma must be a number from 0.2 to 5.0" in r.stderr


@pytest.mark.parametrize("damage, message", [
    ("truncate", "pose_02_board.png: image file is truncated"),
    ("text", "pose_02_board.png: not a readable image"),
    ("resize", "pose_02_board.png: image is"),
    ("rig", "rig.json: stripes must be an integer"),
])
def test_bad_captures_give_one_clear_line_and_exit_2(small_capture, tmp_path, damage, message):
    cap = tmp_path / "cap"
    shutil.copytree(small_capture, cap)
    target = cap / "calib" / "pose_02_board.png"
    if damage == "truncate":
        target.write_bytes(target.read_bytes()[:5000])
    elif damage == "text":
        target.write_bytes(b"not an image at all")
    elif damage == "resize":
        import cv2

        cv2.imwrite(str(target), cv2.resize(cv2.imread(str(target)), (500, 300)))
    else:
        (cap / "rig.json").write_text(json.dumps({"board_cols": 14, "board_rows": 10, "square_mm": 40,
                                                  "stripes": 4.5}))
    r = bodyscan("calibrate", cap, "-o", tmp_path / "c.json")
    assert r.returncode == 2
    assert message in r.stderr
    assert "Traceback" not in r.stderr
    assert not (tmp_path / "c.json").exists()


def test_missing_capture_and_bad_size_flag_are_reported_plainly(tmp_path):
    r = bodyscan("calibrate", tmp_path / "nowhere")
    assert r.returncode == 2 and "capture folder not found" in r.stderr and "Traceback" not in r.stderr
    r = bodyscan("simulate", tmp_path / "x", "--size", "big")
    assert r.returncode == 2 and "--size must look like" in r.stderr


@pytest.mark.parametrize("given, expected", [(None, "1"), ("2", "2")])
def test_the_command_line_runs_numpy_on_one_blas_thread_unless_told_otherwise(given, expected):
    """Two job workers on two cores: BLAS threads on three-column products only wait for each other."""
    import os

    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if given is not None:
        env["OPENBLAS_NUM_THREADS"] = given
    code = "import app.cli, os, numpy; print(os.environ['OPENBLAS_NUM_THREADS'])"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == expected
