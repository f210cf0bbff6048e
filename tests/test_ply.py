import numpy as np

from measurement.ply import read_ply, write_ply


def test_points_and_stripes_round_trip():
    rng = np.random.default_rng(0)
    pts = rng.uniform(-500, 1500, (100, 3))
    stripe = rng.integers(0, 40, 100)
    data = write_ply(pts, stripe)
    assert data.startswith(b"ply\nformat binary_little_endian 1.0\n")
    back = read_ply(data)
    assert np.allclose(np.column_stack([back["x"], back["y"], back["z"]]), pts, atol=1e-3)
    assert (back["stripe"] == stripe).all()


def test_an_empty_cloud_is_a_valid_file():
    back = read_ply(write_ply(np.zeros((0, 3)), np.zeros(0, int)))
    assert len(back["x"]) == 0
