"""A rig whose stripes run across the image (projector above or below the camera, or a camera on its side):
calibrated and scanned in the transposed image, with the same results as the paper's upright rig."""

from __future__ import annotations

import json

import numpy as np
import pytest

from measurement import load_calibration, scan
from measurement.calibration import calibrate
from measurement.capture import read_capture
from measurement.errors import CalibrationError, ScanError
from measurement.images import read_image
from measurement.orientation import stripe_axis, swap_xy, transpose_image
from measurement.simulate.capture import transpose_capture
from measurement.triangulation import ray_table


@pytest.fixture(scope="module")
def turned(small_capture, tmp_path_factory):
    """The small capture transposed: stripes across the image, the projector below the camera."""
    return transpose_capture(small_capture, tmp_path_factory.mktemp("turned") / "cap")


@pytest.fixture(scope="module")
def turned_calibration(turned):
    return calibrate(read_capture(turned))


def test_the_stripe_direction_is_read_off_the_stripe_light(small_capture):
    stripes = read_image(small_capture / "calib" / "pose_01_stripes.png")
    board = read_image(small_capture / "calib" / "pose_01_board.png")
    assert stripe_axis(stripes, board) == "vertical"
    assert stripe_axis(transpose_image(stripes), transpose_image(board)) == "horizontal"
    side = read_image(small_capture / "scan" / "side.png")
    assert stripe_axis(side) == "vertical" and stripe_axis(transpose_image(side)) == "horizontal"


def test_the_transposed_ray_table_is_the_table_of_the_transposed_camera(small_calibration):
    intr = small_calibration.intrinsics
    table, turned = ray_table(intr), ray_table(intr, transposed=True)
    assert turned.shape == (table.shape[1], table.shape[0], 2) and turned.flags["C_CONTIGUOUS"]
    assert np.array_equal(turned[17, 5], table[5, 17][::-1])
    assert np.array_equal(turned[..., 0], table[..., 1].T)


def test_a_rig_with_horizontal_stripes_calibrates_to_the_same_planes(small_calibration, turned_calibration):
    """Before, every pose was refused ("0 of 845 board rows show all 40 stripes")."""
    assert small_calibration.stripe_axis == "vertical"
    assert turned_calibration.stripe_axis == "horizontal"
    assert sum(p.used_for_planes for p in turned_calibration.poses) == 8
    # the same rig seen with swapped axes: the same planes with x and y swapped, ordered top to bottom
    assert np.allclose(turned_calibration.planes, swap_xy(small_calibration.planes), atol=1e-4)
    assert np.all(turned_calibration.planes[:, 1] > 0)
    assert turned_calibration.reprojection_error_px == pytest.approx(small_calibration.reprojection_error_px,
                                                                     abs=1e-3)
    d = turned_calibration.to_dict()
    assert d["stripe_axis"] == "horizontal"
    assert load_calibration(json.loads(json.dumps(d))).stripe_axis == "horizontal"


def test_a_rig_with_horizontal_stripes_scans_to_the_same_animal(small_capture, small_calibration, turned,
                                                                 turned_calibration):
    upright = scan(read_image(small_capture / "scan" / "side.png"), small_calibration.calibration(), "side")
    across = scan(read_image(turned / "scan" / "side.png"), turned_calibration.calibration(), "side",
                  ambient=read_image(turned / "scan" / "side_ambient.png"))
    plain = scan(read_image(turned / "scan" / "side.png"), turned_calibration.calibration(), "side")
    assert len(plain.points) == len(upright.points) > 2000
    # pixels in the turned camera's own coordinates, points in its own frame
    assert np.allclose(plain.uv, upright.uv[:, ::-1])
    assert np.allclose(plain.points, swap_xy(upright.points), atol=1e-3)
    assert np.array_equal(plain.stripe, upright.stripe)
    for key in ("body_length_mm", "body_height_mm", "point_count", "stripes_detected"):
        assert plain.measurements[key] == pytest.approx(upright.measurements[key], abs=0.01)
    ends = np.array(plain.measurements["body_height"]["points"])
    assert np.allclose(ends, swap_xy(np.array(upright.measurements["body_height"]["points"])), atol=1e-3)
    assert len(across.points) > 2000 and across.measurements["body_height_mm"] == pytest.approx(
        upright.measurements["body_height_mm"], rel=0.02)


def test_stripes_running_the_other_way_than_the_calibration_are_named(turned):
    """The turned camera's image with a calibration that says its stripes run down the image."""
    data = json.loads((turned / "truth" / "truth.json").read_text())
    data["stripe_axis"] = "vertical"
    with pytest.raises(ScanError, match="run across it, the calibration's down it"):
        scan(read_image(turned / "scan" / "side.png"), load_calibration(data), "side")
    data["stripe_axis"] = "diagonal"
    with pytest.raises(CalibrationError, match="stripe_axis"):
        load_calibration(data)


def test_the_picture_edges_are_named_as_the_turned_camera_has_them(tmp_path):
    """The side camera 200 mm higher cuts the feet at the bottom of the picture; transposed, the feet reach
    the turned camera's right edge, and that is the edge the warning names."""
    from measurement.simulate.capture import write_capture

    cap = write_capture(tmp_path / "high", size=(1024, 683), poses=0, seed=5, scenes=("side",),
                        scene={"camera_height": 200.0})
    turned = transpose_capture(cap, tmp_path / "turned")
    r = scan(read_image(turned / "scan" / "side.png"), load_calibration(turned / "truth" / "truth.json"), "side")
    assert r.measurements["frame_edges"] == ["right"]
    assert any("reaches the right edge of the picture" in w for w in r.measurements["warnings"])
