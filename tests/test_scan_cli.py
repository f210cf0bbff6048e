"""`bodyscan scan` writes the file contract: cloud.ply (animal + stripe), scene.ply, measurements.json."""

import json
import shutil
import subprocess
import sys

from measurement.ply import read_ply


def bodyscan(*args):
    return subprocess.run([sys.executable, "-m", "app.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=600)


def test_scan_writes_clouds_and_measurements(small_capture, tmp_path):
    cal = small_capture / "truth" / "truth.json"  # the simulator's calibration.json-shaped truth
    r = bodyscan("scan", cal, small_capture / "scan" / "side.png", "-o", tmp_path / "out")
    assert r.returncode == 0, r.stderr
    m = json.loads((tmp_path / "out" / "measurements.json").read_text())
    for key in ("point_count", "body_length_mm", "body_height_mm", "stripes_detected", "view"):
        assert key in m
    assert m["view"] == "side"
    cloud = read_ply((tmp_path / "out" / "cloud.ply").read_bytes())
    assert len(cloud["x"]) == m["point_count"] > 1000 and "stripe" in cloud
    assert len(read_ply((tmp_path / "out" / "scene.ply").read_bytes())["x"]) > m["point_count"]


def test_view_comes_from_the_file_name_or_must_be_given(small_capture, tmp_path):
    odd = tmp_path / "animal.png"
    shutil.copy(small_capture / "scan" / "side.png", odd)
    r = bodyscan("scan", small_capture / "truth" / "truth.json", odd, "-o", tmp_path / "o1")
    assert r.returncode == 2 and "--view" in r.stderr and "Traceback" not in r.stderr
    r = bodyscan("scan", small_capture / "truth" / "truth.json", odd, "--view", "side", "-o", tmp_path / "o2")
    assert r.returncode == 0, r.stderr


def test_a_camera_only_calibration_is_refused_plainly(small_capture, tmp_path):
    cal = json.loads((small_capture / "truth" / "truth.json").read_text())
    cal["planes"] = None
    path = tmp_path / "camera.json"
    path.write_text(json.dumps(cal))
    r = bodyscan("scan", path, small_capture / "scan" / "side.png", "-o", tmp_path / "o")
    assert r.returncode == 2 and "camera-only" in r.stderr and "Traceback" not in r.stderr
