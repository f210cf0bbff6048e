import io
import json
import zipfile

import cv2
import numpy as np
import pytest

from measurement.capture import RigSettings, capture_from_files, capture_from_zip, read_capture
from measurement.errors import CaptureError, ImageError

RIG = {"board_cols": 14, "board_rows": 10, "square_mm": 40.0, "stripes": 40}


def _png(h=60, w=80, value=100) -> bytes:
    return cv2.imencode(".png", np.full((h, w), value, np.uint8))[1].tobytes()


def _files(**extra) -> dict:
    files = {"rig.json": json.dumps(RIG).encode()}
    for i in (1, 2, 3):
        files[f"calib/pose_0{i}_board.png"] = _png()
        files[f"calib/pose_0{i}_stripes.png"] = _png()
    files["scan/side.png"] = _png()
    files.update(extra)
    return files


def test_layout_is_read_into_poses_in_number_order_and_views():
    files = _files()
    files["calib/pose_10_board.png"] = _png()
    cap = capture_from_files(files)
    assert [p.name for p in cap.poses] == ["pose_01", "pose_02", "pose_03", "pose_10"]
    assert cap.poses[3].stripes is None
    assert set(cap.scans) == {"side"}
    assert cap.rig == RigSettings(14, 10, 40.0, 40)


def test_colour_16bit_jpeg_tiff_and_bmp_images_are_accepted():
    colour = cv2.imencode(".png", np.full((60, 80, 3), 90, np.uint8))[1].tobytes()
    deep = cv2.imencode(".png", np.full((60, 80), 30000, np.uint16))[1].tobytes()
    jpg = cv2.imencode(".jpg", np.full((60, 80), 90, np.uint8))[1].tobytes()
    tif = cv2.imencode(".tiff", np.full((60, 80), 90, np.uint8))[1].tobytes()
    bmp = cv2.imencode(".bmp", np.full((60, 80), 90, np.uint8))[1].tobytes()
    files = {"rig.json": json.dumps(RIG).encode(), "calib/pose_01_board.png": colour,
             "calib/pose_01_stripes.png": deep, "calib/pose_02_board.jpg": jpg, "calib/pose_03_board.tiff": tif,
             "calib/pose_04_board.bmp": bmp}
    cap = capture_from_files(files)
    assert cap.poses[0].board.ndim == 2 and cap.poses[0].stripes.dtype == np.uint16
    assert len(cap.poses) == 4


def test_a_truncated_png_is_named():
    bad = _png()[:-30]
    with pytest.raises(ImageError, match="pose_02_board.png"):
        capture_from_files(_files(**{"calib/pose_02_board.png": bad}))


def test_a_non_image_is_named():
    with pytest.raises(ImageError, match="pose_01_stripes.png: not a readable image"):
        capture_from_files(_files(**{"calib/pose_01_stripes.png": b"hello, I am text"}))


def test_images_of_different_sizes_are_refused_naming_the_file():
    with pytest.raises(CaptureError, match="pose_03_stripes.png: image is 90x60"):
        capture_from_files(_files(**{"calib/pose_03_stripes.png": _png(60, 90)}))


def test_rig_json_problems_name_the_field():
    with pytest.raises(CaptureError, match="rig.json: missing"):
        capture_from_files({k: v for k, v in _files().items() if k != "rig.json"})
    with pytest.raises(CaptureError, match="stripes"):
        capture_from_files(_files(**{"rig.json": json.dumps({**RIG, "stripes": "many"}).encode()}))
    with pytest.raises(CaptureError, match="square_mm"):
        capture_from_files(_files(**{"rig.json": json.dumps({**RIG, "square_mm": -4}).encode()}))


def test_a_stripe_image_without_its_board_image_is_refused():
    files = _files()
    del files["calib/pose_02_board.png"]
    with pytest.raises(CaptureError, match="pose_02_stripes.png: no matching pose_02_board"):
        capture_from_files(files)


def _zip(files: dict) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for name, data in files.items():
            zf.writestr(name, data)
    return buf.getvalue()


def test_zip_with_or_without_a_top_folder_is_read():
    flat = capture_from_zip(_zip(_files()))
    wrapped = capture_from_zip(_zip({f"mycapture/{k}": v for k, v in _files().items()}))
    assert len(flat.poses) == len(wrapped.poses) == 3


@pytest.mark.parametrize("evil", ["../etc/passwd", "/abs/rig.json", "calib/../../x.png", "C:/x.png"])
def test_zip_path_tricks_are_refused(evil):
    with pytest.raises(CaptureError, match="unsafe path"):
        capture_from_zip(_zip(_files(**{evil: b"x"})))


def test_not_a_zip_is_refused():
    with pytest.raises(CaptureError, match="not a zip"):
        capture_from_zip(b"PK but not really")


def test_read_capture_reads_a_simulated_folder(small_capture):
    cap = read_capture(small_capture)
    assert len(cap.poses) == 8 and "side" in cap.scans and "side_ambient" in cap.scans
    with pytest.raises(CaptureError, match="not found"):
        read_capture(small_capture / "nope")
