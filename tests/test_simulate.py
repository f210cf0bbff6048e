import json

import numpy as np

from measurement.camera import Intrinsics, project
from measurement.images import read_image


def test_capture_layout_and_truth_files_exist(small_capture):
    rig = json.loads((small_capture / "rig.json").read_text())
    assert rig == {"board_cols": 14, "board_rows": 10, "square_mm": 40.0, "stripes": 40}
    for i in range(1, 9):
        assert (small_capture / "calib" / f"pose_{i:02d}_board.png").exists()
        assert (small_capture / "calib" / f"pose_{i:02d}_stripes.png").exists()
    assert (small_capture / "scan" / "side.png").exists()
    for name in ("truth.json", "side_stripes.npz", "side_animal.ply"):
        assert (small_capture / "truth" / name).exists()


def test_true_stripe_points_lie_on_their_planes_and_project_to_their_pixels(small_capture, small_truth):
    t = np.load(small_capture / "truth" / "side_stripes.npz")
    planes = np.array(small_truth["planes"])
    d = np.einsum("ij,ij->i", t["points"], planes[t["stripe"], :3]) - planes[t["stripe"], 3]
    assert np.abs(d).max() < 1e-6
    uv = project(t["points"], Intrinsics.from_dict(small_truth))
    assert np.abs(uv - t["uv"]).max() < 0.05  # linear interpolation between neighbouring pixels
    assert {2, 3, 5} <= set(np.unique(t["kind"]))  # floor, wall and animal all catch stripes


def test_planes_pass_through_the_projector_centre(small_truth):
    planes = np.array(small_truth["planes"])
    c = np.array(small_truth["projector_centre"])
    assert np.abs(planes[:, :3] @ c - planes[:, 3]).max() < 1e-9


def test_stripes_are_much_dimmer_on_black_squares(small_capture, small_truth):
    img = read_image(small_capture / "calib" / "pose_01_stripes.png").astype(float)
    board = read_image(small_capture / "calib" / "pose_01_board.png").astype(float)
    t = np.load(small_capture / "truth" / "pose_01_stripes.npz")
    uv = np.rint(t["uv"][t["kind"] == 4]).astype(int)
    peak = img[uv[:, 1], uv[:, 0]]
    dark = board[uv[:, 1], uv[:, 0]] < np.percentile(board, 30)
    assert np.median(peak[~dark]) > 2.5 * np.median(peak[dark])


def test_anatomy_is_reported_in_camera_coordinates(small_truth):
    a = small_truth["views"]["side"]["anatomy"]
    assert 250 < a["torso_length_mm"] < 350
    tail = np.array(a["tail_centreline"])
    assert tail.shape[1] == 3 and 900 < tail[:, 2].mean() < 1500
    assert np.isclose(np.linalg.norm(np.subtract(*a["neck_landmarks"])), a["neck_width_mm"])


def test_a_mesh_is_stood_up_by_its_extents_whatever_axis_its_file_calls_up(tmp_path):
    """Length > height > width: the longest axis becomes x, the middle one up (y), feet on y = 0."""
    import trimesh

    from measurement.simulate.animal import from_mesh

    path = tmp_path / "z_long_x_up.obj"
    trimesh.creation.box(extents=(100.0, 40.0, 300.0)).export(path)
    a = from_mesh(str(path), length_mm=600.0)
    ext = a.vertices.max(axis=0) - a.vertices.min(axis=0)
    np.testing.assert_allclose(ext, [600.0, 200.0, 80.0], atol=1e-9)
    assert a.vertices[:, 1].min() == 0.0


def test_the_camera_steps_back_along_its_viewing_direction_and_the_projector_turns_about_its_axis():
    import numpy as np

    from measurement.simulate.animal import quadruped
    from measurement.simulate.capture import animal_scene
    from measurement.simulate.rig import default_rig

    animal = quadruped(seed=1)
    _, R0, t0 = animal_scene(animal, "side", fur=False, seed=1)
    _, R1, t1 = animal_scene(animal, "side", fur=False, seed=1, camera_back=400.0)
    c0, c1 = -R0.T @ t0, -R1.T @ t1  # camera centres in the world
    assert np.allclose(R0, R1)  # the same viewing direction
    assert np.allclose(c1 - c0, -400.0 * R0[2])  # 400 mm back along it
    rig, turned = default_rig((768, 512), 40), default_rig((768, 512), 40, roll_deg=10.0)
    assert np.allclose(rig.projector.centre_cam, turned.projector.centre_cam)
    # the stripe planes turn by 10 degrees about the projector's axis: their normals' image-plane direction
    n0, n1 = rig.projector.planes_cam()[20, :2], turned.projector.planes_cam()[20, :2]
    angle = np.degrees(np.arccos(n0 @ n1 / np.linalg.norm(n0) / np.linalg.norm(n1)))
    assert 8.0 < angle < 12.0
