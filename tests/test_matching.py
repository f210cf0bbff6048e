"""Stripe labels: the paper's Algorithm 3 baseline and ours, against the simulator's exact crossings."""

import numpy as np
import pytest

from measurement.calibration import load_calibration
from measurement.detection import detect_centres
from measurement.images import read_image
from measurement.matching import denoise, label_centres
from measurement.paper import match_paper
from measurement.simulate.truth import match_crossings
from measurement.triangulation import ray_table, rays_at


@pytest.fixture(scope="module")
def side(small_capture):
    img = read_image(small_capture / "scan" / "side.png")
    c = detect_centres(img)
    c = c.take(denoise(c, img.shape))
    truth, kind = match_crossings(np.column_stack([c.u, c.v]),
                                  dict(np.load(small_capture / "truth" / "side_stripes.npz")))
    return img, c, truth, kind


def test_paper_matching_follows_straight_stripes():
    # 8 slanted stripes over 50 rows, all present: Algorithm 3 labels them all, in order
    v = np.repeat(np.arange(50), 8)
    u = np.tile(np.arange(8) * 30.0 + 20, 50) + 0.4 * v
    lab = match_paper(u, v, 8)
    assert (lab == np.tile(np.arange(8), 50)).all()


def test_denoising_drops_isolated_specks_and_keeps_stripes():
    from measurement.detection import Centres

    v = np.repeat(np.arange(60), 4).astype(np.int32)
    u = np.tile([20.0, 50.0, 80.0, 110.0], 60)
    u = np.concatenate([u, [35.0, 95.0]])
    v = np.concatenate([v, np.array([30, 10], np.int32)])
    order = np.lexsort((u, v))
    c = Centres(u[order], v[order], np.full(len(u), 50.0, np.float32), np.full(len(u), 6.0, np.float32))
    keep = denoise(c, (60, 130))
    assert not keep[np.isin(c.u, [35.0, 95.0])].any()
    assert keep[~np.isin(c.u, [35.0, 95.0])].mean() > 0.9


def test_our_labels_beat_the_paper_on_the_animal(small_capture, side):
    img, c, truth, kind = side
    cal = load_calibration(small_capture / "truth" / "truth.json")
    ours = label_centres(c, rays_at(c.u, c.v, ray_table(cal.intrinsics)), cal.planes, img.shape).stripe
    paper = match_paper(c.u, c.v, cal.stripes)
    animal = kind == 5

    def right(lab):
        got = animal & (lab >= 0)
        return float(np.mean(lab[got] == truth[got])) if got.any() else 0.0

    assert right(ours) > 0.97
    assert right(paper) < right(ours)  # image continuity carries the wall's indices into the body
