"""The scan pipeline on the simulator: input checks, stripe labels against the exact plane crossings
(background and animal), and body size against the same definitions applied to the true stripe points."""

import numpy as np
import pytest

from measurement.calibration import Calibration, load_calibration
from measurement.detection import DetectionParams, detect_centres
from measurement.errors import ImageError, ScanError, StripeDetectionError
from measurement.images import read_image
from measurement.matching import denoise, label_centres
from measurement.pipeline import scan
from measurement.simulate.truth import match_crossings
from measurement.triangulation import intersect, ray_table, rays_at


@pytest.fixture(scope="module")
def truth_cal(small_capture) -> Calibration:
    return load_calibration(small_capture / "truth" / "truth.json")


def _truth_labels(small_capture, c):
    return match_crossings(np.column_stack([c.u, c.v]), dict(np.load(small_capture / "truth" / "side_stripes.npz")))


def _labelled_side(small_capture, truth_cal):
    """Rays, labels and the truth (stripe, kind) of every centre of the small capture's side view."""
    img = read_image(small_capture / "scan" / "side.png")
    c = detect_centres(img)
    c = c.take(denoise(c, img.shape))
    rays = rays_at(c.u, c.v, ray_table(truth_cal.intrinsics))
    labels = label_centres(c, rays, truth_cal.planes, img.shape)
    return (rays, labels, *_truth_labels(small_capture, c))


def test_background_stripes_are_labelled_and_placed_exactly(small_capture, truth_cal):
    rays, labels, truth, kind = _labelled_side(small_capture, truth_cal)
    for code in (2, 3):  # floor, wall
        m = (kind == code) & (labels.stripe >= 0)
        assert m.sum() > 0.6 * (kind == code).sum()
        assert np.mean(labels.stripe[m] == truth[m]) > 0.99
    assert labels.background is not None and len(labels.background) == 2
    wall = (kind == 3) & (labels.stripe >= 0)
    pts = intersect(rays[wall], truth_cal.planes[labels.stripe[wall]])
    resid = np.abs(pts @ labels.background[:, :3].T - labels.background[:, 3]).min(axis=1)
    assert np.median(resid) < 1.5


def test_animal_stripes_get_the_right_index_across_the_outline(small_capture, truth_cal):
    rays, labels, truth, kind = _labelled_side(small_capture, truth_cal)
    animal = kind == 5
    got = animal & (labels.stripe >= 0)
    assert got.sum() > 0.6 * animal.sum()
    # 98.0 % on this 1024 px render (99.99 % at 3072 px, docs/benchmarks.md); the offset of a whole
    # animal piece being wrong would put this near zero
    assert np.mean(labels.stripe[got] == truth[got]) > 0.97


def test_paper_definitions_match_the_true_stripe_points(small_capture, truth_cal):
    from measurement.body import measure

    r = scan(read_image(small_capture / "scan" / "side.png"), truth_cal, "side")
    t = np.load(small_capture / "truth" / "side_stripes.npz")
    on = t["kind"] == 5
    ref = measure(t["points"][on], t["stripe"][on], np.rint(t["uv"][on, 1]).astype(np.int64), "side")
    # the paper's length hangs on the outermost stripe groups (here the tail tip, which the scan loses at
    # 1024 px): 10 % off here, the 1 % is not met yet (docs/benchmarks.md)
    assert r.measurements["body_length_mm"] == pytest.approx(ref["body_length_mm"], rel=0.12)
    assert r.measurements["body_height_mm"] == pytest.approx(ref["body_height_mm"], rel=0.03)
    assert len(r.measurements["body_length"]["points"]) == 2


def test_clipped_centres_stay_out_of_the_cloud_but_not_out_of_the_measurement(small_capture, truth_cal):
    from dataclasses import replace

    from measurement.pipeline import ScanParams

    img = read_image(small_capture / "scan" / "side.png")

    def scanned(min_width: float):
        p = ScanParams()
        return scan(img, truth_cal, "side", params=replace(p, detection=replace(p.detection, min_width=min_width)))

    # this 1024 px render's stripes are 3 px wide: at the default share only 1 px runs count as cut; ask for more
    every, strict = scanned(0.0), scanned(0.9)
    assert len(strict.points) < 0.97 * len(every.points) and len(strict.scene_points) < len(every.scene_points)
    kept = {(round(u, 3), v) for u, v in every.uv.tolist()}
    assert all((round(u, 3), v) in kept for u, v in strict.uv.tolist())  # a subset of the same points
    assert strict.measurements["point_count"] == len(strict.points)
    for name in ("body_length_mm", "body_height_mm", "stripes_detected"):
        assert strict.measurements[name] == every.measurements[name]


def test_a_tiled_floor_is_told_from_the_animal(tmp_path):
    """Dark grout lines every 150 mm: their edges beside the stripe field are peaks in every row, and the
    floor used to go unlabelled and join the animal (body height +100 % on this render)."""
    from measurement.body import measure
    from measurement.simulate.capture import write_capture

    cap = write_capture(tmp_path / "tiles", size=(1024, 683), seed=4, poses=0, scenes=("side",),
                        scene={"floor": "tiles"})
    cal = load_calibration(cap / "truth" / "truth.json")
    r = scan(read_image(cap / "scan" / "side.png"), cal, "side")
    t = dict(np.load(cap / "truth" / "side_stripes.npz"))
    tk, kind = match_crossings(r.scene_uv, t)
    floor = kind == 2
    assert np.mean(r.scene_stripe[floor] == tk[floor]) > 0.98
    on = t["kind"] == 5
    ref = measure(t["points"][on], t["stripe"][on], np.rint(t["uv"][on, 1]).astype(np.int64), "side")
    assert r.measurements["body_height_mm"] == pytest.approx(ref["body_height_mm"], rel=0.05)


def test_a_low_camera_claims_the_wall_it_sees_face_on(tmp_path):
    """The side camera 150 mm lower: the floor, seen at a grazing angle, is labelled from complete rows and
    lies within 0.05 mm of its plane, while the wall's stripes scatter 0.7 mm about theirs. Held to the
    floor's flatness, the wall went unclaimed, joined the animal and the scan was refused; each plane is
    now held to its own."""
    from measurement.simulate.capture import write_capture

    cap = write_capture(tmp_path / "low", size=(1024, 683), poses=0, seed=5, scenes=("side",),
                        scene={"camera_height": -150.0})
    r = scan(read_image(cap / "scan" / "side.png"), load_calibration(cap / "truth" / "truth.json"), "side")
    tk, kind = match_crossings(r.scene_uv, dict(np.load(cap / "truth" / "side_stripes.npz")))
    wall, animal = kind == 3, kind == 5
    assert np.mean(r.scene_stripe[wall] == tk[wall]) > 0.98
    assert animal.sum() > 2000 and np.mean(r.scene_stripe[animal] == tk[animal]) > 0.98


@pytest.mark.parametrize("wall", [True, False])
def test_an_animal_on_a_weighing_platform_is_placed_on_its_own_stripes(tmp_path, wall):
    """A 100 mm platform under the animal: its front is a background plane (parallel to the wall), and the
    animal standing behind that plane (but nowhere behind the platform) was pushed forward to get in front
    of it (0 % right at 1024 px on seeds 4, 5 and 7 with the wall; without it too)."""
    from measurement.simulate.capture import write_capture

    cap = write_capture(tmp_path / "platform", size=(1024, 683), seed=4, poses=0, scenes=("side",),
                        scene={"platform": 100.0, "wall": wall})
    r = scan(read_image(cap / "scan" / "side.png"), load_calibration(cap / "truth" / "truth.json"), "side")
    tk, kind = match_crossings(r.scene_uv, dict(np.load(cap / "truth" / "side_stripes.npz")))
    animal = kind == 5
    assert np.mean(r.scene_stripe[animal] == tk[animal]) > 0.95


def test_an_animal_seen_between_the_rails_of_a_chute_is_not_pushed_in_front_of_them(tmp_path):
    """Two rails between the camera and the animal: their fronts make a background plane before the wall,
    and the animal's points seen just beside a rail were counted behind it (0 % right on this render);
    only the interior of where a bounded plane was seen counts."""
    from measurement.simulate.capture import write_capture

    cap = write_capture(tmp_path / "rails", size=(1024, 683), seed=5, poses=0, scenes=("side",),
                        scene={"rails": -300.0})
    r = scan(read_image(cap / "scan" / "side.png"), load_calibration(cap / "truth" / "truth.json"), "side")
    tk, kind = match_crossings(r.scene_uv, dict(np.load(cap / "truth" / "side_stripes.npz")))
    animal = kind == 5
    assert np.mean(r.scene_stripe[animal] == tk[animal]) > 0.95


def test_scan_returns_a_contract_shaped_result(small_capture, truth_cal):
    r = scan(read_image(small_capture / "scan" / "side.png"), truth_cal, "side")
    m = r.measurements
    for key in ("point_count", "body_length_mm", "body_height_mm", "stripes_detected", "view"):
        assert key in m
    assert m["point_count"] == len(r.points) == len(r.stripe) == len(r.uv)
    assert len(r.scene_points) > 1000 and m["view"] == "side"


def test_blank_saturated_and_wrong_size_images_are_refused(truth_cal):
    w, h = truth_cal.intrinsics.image_size
    with pytest.raises(StripeDetectionError, match="blank"):
        scan(np.full((h, w), 17, np.uint8), truth_cal)
    with pytest.raises(StripeDetectionError, match="saturated"):
        scan(np.full((h, w), 255, np.uint8), truth_cal)
    with pytest.raises(ImageError, match="calibration is for"):
        scan(np.zeros((100, 120), np.uint8), truth_cal)


def test_arrays_of_other_shapes_and_types_are_refused_by_name(small_capture, truth_cal):
    """A two-channel or integer colour array, or such an ambient image, is an ImageError naming which of
    the two it was, never OpenCV's own error (a two-channel frame raised cv2.error before)."""
    img = read_image(small_capture / "scan" / "side.png")
    h, w = img.shape
    with pytest.raises(ImageError, match=r"^image must be .* got shape \(.*, 2\)"):
        scan(np.dstack([img] * 2), truth_cal)
    with pytest.raises(ImageError, match="^image must be uint8 or uint16, got int32"):
        scan(np.dstack([img] * 3).astype(np.int32), truth_cal)
    with pytest.raises(ImageError, match="^ambient image must be .* got shape"):
        scan(img, truth_cal, ambient=np.zeros((h, w, 2), np.uint8))
    with pytest.raises(ImageError, match="^ambient image must be uint8 or uint16, got float32"):
        scan(img, truth_cal, ambient=np.zeros((h, w), np.float32))
    one_channel = scan(img[:, :, None], truth_cal, "side")
    np.testing.assert_array_equal(one_channel.stripe, scan(img, truth_cal, "side").stripe)


def test_a_swapped_or_lit_ambient_image_is_named(small_capture, truth_cal):
    """The stripe and ambient images swapped (the stripes would be read as dark lines between 55 'stripes'
    and the scan blamed the calibration), or the projector on for both, is said as such."""
    img = read_image(small_capture / "scan" / "side.png")
    ambient = read_image(small_capture / "scan" / "side_ambient.png")
    with pytest.raises(ImageError, match="brighter than the stripe image: are the two swapped"):
        scan(ambient, truth_cal, ambient=img)
    with pytest.raises(StripeDetectionError, match="nothing is left of the stripe image"):
        scan(img, truth_cal, ambient=img)
    assert len(scan(img, truth_cal, "side", ambient=ambient).points) > 1000


def test_camera_only_or_other_stripe_count_calibrations_are_refused(small_capture, truth_cal):
    img = read_image(small_capture / "scan" / "side.png")
    with pytest.raises(ScanError, match="camera-only"):
        scan(img, Calibration(truth_cal.intrinsics, None))
    with pytest.raises(ScanError, match="light planes"):
        scan(img, Calibration(truth_cal.intrinsics, truth_cal.planes[::3]))
    with pytest.raises(ScanError, match="view"):
        scan(img, truth_cal, "under")


def test_a_pattern_reaching_past_the_image_is_named_in_the_refusal(small_capture, truth_cal):
    """The indices are read from rows that show every stripe; when the outer stripes fall outside the
    view (here: the left third of the frame is dark) the refusal says so instead of only doubting the
    calibration."""
    img = read_image(small_capture / "scan" / "side.png").copy()
    img[:, : img.shape[1] // 3] = 0
    with pytest.raises(ScanError, match="fall inside the image"):
        scan(img, truth_cal)


def test_a_scan_says_when_the_animal_could_not_be_placed(small_capture, monkeypatch):
    """When nothing fixes the animal's stripe indices the scan gives no numbers and says why, rather
    than numbers from a guessed index. Simulated by taking back every index the labeller gave off the
    floor and wall planes, as a refused piece leaves them."""
    import measurement.pipeline as pipeline
    from measurement.matching import Labels

    cal = load_calibration(small_capture / "truth" / "truth.json")
    img = read_image(small_capture / "scan" / "side.png")
    ok = scan(img, cal, "side")
    assert ok.measurements["warnings"] == [] and ok.measurements["body_height_mm"] is not None

    def refuse_the_animal(c, rays, planes, shape, params, view="side"):
        rays = rays() if callable(rays) else rays  # the scan may hand over a lookup to run while linking
        lab = label_centres(c, rays, planes, shape, params, view)
        placed = np.nonzero(lab.stripe >= 0)[0]
        p = intersect(rays[placed], planes[lab.stripe[placed]])
        off_bg = np.abs(p @ lab.background[:, :3].T - lab.background[:, 3]).min(axis=1) > 15
        stripe = lab.stripe.copy()
        stripe[placed[off_bg]] = -1
        return Labels(stripe, lab.background, lab.segment, int(off_bg.sum()), int(off_bg.sum()))

    monkeypatch.setattr(pipeline, "label_centres", refuse_the_animal)
    r = scan(img, cal, "side")
    assert r.measurements["unplaced_share"] == 1.0
    assert r.measurements["body_height_mm"] is None
    assert any("could not be matched to a light plane" in w for w in r.measurements["warnings"])


def test_a_faint_shadow_reading_is_named_in_the_warnings():
    from measurement.matching import Labels
    from measurement.pipeline import _warnings

    meas = {"body_length_mm": 500.0, "body_height_mm": 280.0}
    assert _warnings(meas, Labels(np.zeros(3, np.int64), None, None, 100, 0)) == []
    warned = _warnings(meas, Labels(np.zeros(3, np.int64), None, None, 100, 0, faint_shadow=True))
    assert len(warned) == 1 and "faint shadow" in warned[0] and "off by one stripe" in warned[0]


def test_faint_stripes_on_a_dark_coat_are_named_in_the_warnings(small_capture, truth_cal):
    """A black coat (stripe contrast about 17 gray levels against 30-70 on the usual renders) loses its
    outline and, from above, its placement: the scan says so. The small capture's own coat does not warn."""
    from measurement.matching import Labels
    from measurement.pipeline import _warnings

    r = scan(read_image(small_capture / "scan" / "side.png"), truth_cal, "side")
    assert r.measurements["animal_contrast"] > 30 and not any("faint (" in w for w in r.measurements["warnings"])
    meas = {"body_length_mm": 500.0, "body_height_mm": 280.0, "animal_contrast": 17.0}
    warned = _warnings(meas, Labels(np.zeros(3, np.int64), None, None, 100, 0))
    assert len(warned) == 1 and "stripes on the animal are faint (median 17 gray levels" in warned[0]


def test_an_overexposed_frame_is_named_in_the_warnings(small_capture, truth_cal):
    """Clipped stripes (the frame 2.5 times over its exposure) left two of the five seeds' 40 views with all or
    part of the animal one stripe off: the scan counts the animal's points on saturated pixels and says so; as exposed it has a few. A 12-bit
    frame is saturated at 4095, not at 65535."""
    img = read_image(small_capture / "scan" / "side.png")
    plain = scan(img, truth_cal, "side")
    assert plain.measurements["saturated_share"] < 0.01  # a few crests of the brightest floor stripes
    assert not any("saturated" in w for w in plain.measurements["warnings"])
    bright = np.clip(img.astype(np.float64) * 2.5, 0, 255).astype(np.uint8)
    r = scan(bright, truth_cal, "side")
    assert r.measurements["saturated_share"] >= 0.05
    assert any("saturated pixels" in w and "lower the exposure" in w for w in r.measurements["warnings"])
    twelve = scan(bright.astype(np.uint16) * 16 + bright.astype(np.uint16) // 16, truth_cal, "side")  # 0..4095
    assert twelve.measurements["saturated_share"] == r.measurements["saturated_share"]


def test_sixteen_bit_and_colour_frames_scan_as_their_eight_bit_gray(small_capture, truth_cal):
    """A 16-bit camera frame (the same light, x257) or a 3-channel one gives the same cloud."""
    img = read_image(small_capture / "scan" / "side.png")
    gray = scan(img, truth_cal, "side")
    for other in (img.astype(np.uint16) * 257, np.dstack([img] * 3)):
        r = scan(other, truth_cal, "side")
        np.testing.assert_array_equal(r.stripe, gray.stripe)
        np.testing.assert_allclose(r.points, gray.points)


def test_a_frame_exposed_half_as_long_scans_as_the_full_one(small_capture, truth_cal):
    """Every gray level halved (another camera's gain, another renderer's light): the detector's thresholds
    follow the stripes' level (``detection.exposure_scale``), so the dark coat's stripes are kept. At the
    full thresholds this view kept 84 % of its animal points and measured its height 4.5 % high (now 99.5 %
    and +0.8 %)."""
    from measurement.detection import STRIPE_LEVEL, stripe_level, to_gray8

    img = read_image(small_capture / "scan" / "side.png")
    dark = img // 2
    assert stripe_level(to_gray8(dark), DetectionParams(), 0.0) < 0.7 * STRIPE_LEVEL
    full, half = scan(img, truth_cal, "side"), scan(dark, truth_cal, "side")
    t = dict(np.load(small_capture / "truth" / "side_stripes.npz"))
    tk, kind = match_crossings(half.uv, t)
    assert len(half.points) >= 0.9 * len(full.points)
    assert np.mean(half.stripe[kind == 5] == tk[kind == 5]) >= 0.99
    assert abs(half.measurements["body_height_mm"] / full.measurements["body_height_mm"] - 1) < 0.015


def test_twelve_bit_samples_in_a_sixteen_bit_frame_scan_as_the_eight_bit_frame(small_capture, truth_cal):
    """A machine-vision camera's Mono12 frame written unshifted into a 16-bit file (values 0-4095), with its
    ambient image: before, both were scaled by 1/257 to 16 gray levels and no stripe was found."""
    img = read_image(small_capture / "scan" / "side.png")
    ambient = read_image(small_capture / "scan" / "side_ambient.png")
    assert img.max() == 255

    def twelve(a):
        return np.round(a.astype(np.float64) * 4095.0 / 255.0).astype(np.uint16)

    for amb in (None, ambient):
        eight = scan(img, truth_cal, "side", ambient=amb)
        r = scan(twelve(img), truth_cal, "side", ambient=None if amb is None else twelve(amb))
        np.testing.assert_array_equal(r.stripe, eight.stripe)
        np.testing.assert_allclose(r.points, eight.points)


def test_scans_in_several_threads_at_once_give_each_its_own_result(small_capture, truth_cal):
    """The scan's helper threads (detection's bands, the second core) are shared by every scan in the
    process: scans from several threads at once queue on them and each gets what it gets alone."""
    from concurrent.futures import ThreadPoolExecutor

    side = read_image(small_capture / "scan" / "side.png")
    rng = np.random.default_rng(1)
    noisier = np.clip(side.astype(np.int16) + rng.integers(-3, 4, side.shape), 0, 255).astype(np.uint8)
    frames = [side, noisier]
    alone = [scan(f, truth_cal) for f in frames]
    assert not np.array_equal(alone[0].points, alone[1].points)
    with ThreadPoolExecutor(4) as pool:
        results = list(pool.map(lambda i: scan(frames[i % 2], truth_cal), range(8)))
    for i, r in enumerate(results):
        own = alone[i % 2]
        assert np.array_equal(r.points, own.points) and np.array_equal(r.stripe, own.stripe)
        assert r.measurements["body_height_mm"] == own.measurements["body_height_mm"]


def test_the_patterns_outermost_stripes_on_the_animal_are_named(small_capture, truth_cal):
    """Where the pattern's first or last stripe lights the animal, the animal may go on past the light and the
    length spans only the pattern's reach: ``pattern_edges`` names those ends, as the simulator's truth has them."""
    from measurement.pipeline import pattern_edges

    r = scan(read_image(small_capture / "scan" / "side.png"), truth_cal, "side")
    t = dict(np.load(small_capture / "truth" / "side_stripes.npz"))
    on = t["stripe"][t["kind"] == 5]
    truth = [name for name, k in (("first", 0), ("last", truth_cal.stripes - 1)) if (on == k).sum() >= 10]
    assert truth and r.measurements["pattern_edges"] == truth
    assert pattern_edges(np.array([0] * 10 + [5] * 30 + [39] * 9), 40) == ["first"]
    assert pattern_edges(np.zeros(0, np.int64), 40) == []


def test_an_animal_cut_by_the_picture_edge_is_named_in_the_warnings(small_capture, truth_cal, tmp_path):
    """With the side camera 200 mm higher the feet reach the bottom of the picture: the scan names the
    edge and warns that the length and height may be short. The small capture's centred animal does not."""
    from measurement.simulate.capture import write_capture

    r = scan(read_image(small_capture / "scan" / "side.png"), truth_cal, "side")
    assert r.measurements["frame_edges"] == [] and not any("edge of the picture" in w for w in r.measurements["warnings"])
    cap = write_capture(tmp_path / "high", size=(1024, 683), poses=0, seed=5, scenes=("side",),
                        scene={"camera_height": 200.0})
    high = scan(read_image(cap / "scan" / "side.png"), load_calibration(cap / "truth" / "truth.json"), "side")
    assert high.measurements["frame_edges"] == ["bottom"]
    assert any("reaches the bottom edge of the picture" in w for w in high.measurements["warnings"])


def test_a_scene_without_an_animal_says_so(small_capture, truth_cal, tmp_path, monkeypatch):
    """The pen empty (the simulator's animal moved 10 m aside, out of view): the few stray points left
    off the floor and wall are not reported as an animal without a warning that says so; the small
    capture's animal is not warned about."""
    import measurement.simulate.capture as sim
    from measurement.simulate.animal import Animal, quadruped

    def far_away(seed: int = 0) -> Animal:
        a = quadruped(seed=seed)
        return Animal(a.vertices + np.array([10000.0, 0.0, 0.0]), a.faces, a.anatomy)

    r = scan(read_image(small_capture / "scan" / "side.png"), truth_cal, "side")
    assert not any("hardly anything" in w for w in r.measurements["warnings"])
    monkeypatch.setattr(sim, "quadruped", far_away)
    cap = sim.write_capture(tmp_path / "empty", size=(1024, 683), poses=0, seed=5, scenes=("side",))
    r = scan(read_image(cap / "scan" / "side.png"), load_calibration(cap / "truth" / "truth.json"), "side")
    assert r.measurements["point_count"] < 300
    assert any("hardly anything was found off the floor and wall" in w for w in r.measurements["warnings"])


def test_front_and_back_views_are_named_as_not_yet_reliable(small_capture, truth_cal):
    """bench/views.py: no simulated front or back view has 95 % of its stripes right."""
    img = read_image(small_capture / "scan" / "side.png")
    assert not any("views are not yet reliable" in w for w in scan(img, truth_cal, "side").measurements["warnings"])
    for view in ("front", "back"):
        warnings = scan(img, truth_cal, view).measurements["warnings"]
        assert any(w.startswith(f"{view} views are not yet reliable") for w in warnings)


def test_a_top_view_whose_shadow_ramp_ends_in_a_weak_step_is_placed_at_the_bottom_of_its_curve(tmp_path):
    """The rig with a 150 mm baseline, 50 stripes, seen from above at 1536 px (bench/geometry.py's
    narrow-50-clean-22): read up the shadow ramp the whole animal lands one stripe low (0.02 % of its
    centres right); read at the bottom of its V, as a top view now is, it is placed right."""
    from measurement.simulate.capture import write_capture
    from measurement.simulate.rig import default_rig
    from measurement.simulate.truth import match_crossings

    size = (1536, 1024)
    cap = write_capture(tmp_path / "narrow", stripes=50, size=size, seed=22, fur=False, scenes=("side", "top"),
                        poses=0, rig=default_rig(size, 50, baseline_mm=150.0))
    cal = load_calibration(cap / "truth" / "truth.json")
    img = read_image(cap / "scan" / "top.png")
    truth = dict(np.load(cap / "truth" / "top_stripes.npz"))
    right = {}
    for view in ("top", "side"):  # the same image, read as a top view and (the old reading) as a side view
        r = scan(img, cal, view)
        tk, kind = match_crossings(r.scene_uv.astype(float), truth)
        animal = kind == 5
        right[view] = float(np.mean(r.scene_stripe[animal] == tk[animal]))
    assert right["top"] > 0.95 > 0.05 > right["side"]


def _fur_side_view_right(tmp_path, stripes: int, seed: int) -> float:
    """The share of the animal's centres labelled right in the simulator's 1536 px fur side view."""
    from measurement.simulate.capture import write_capture
    from measurement.simulate.truth import match_crossings

    cap = write_capture(tmp_path / f"fur{seed}", stripes=stripes, size=(1536, 1024), seed=seed, fur=True,
                        scenes=("side",), poses=0)
    r = scan(read_image(cap / "scan" / "side.png"), load_calibration(cap / "truth" / "truth.json"), "side")
    tk, kind = match_crossings(r.scene_uv.astype(float), dict(np.load(cap / "truth" / "side_stripes.npz")))
    animal = kind == 5
    return float(np.mean(r.scene_stripe[animal] == tk[animal]))


def test_a_body_and_a_thigh_read_apart_are_read_as_one_where_they_touch(tmp_path):
    """The 50-stripe fur side view, seed 12, at 1536 px: the depth step between the hind thigh and the body
    splits the animal into two large pieces, and reading each on its own put the body one stripe low (18 %
    of the animal's centres right). One stripe up it touches the thigh in 3-D; read as one piece at that
    relative offset, both are placed right."""
    assert _fur_side_view_right(tmp_path, 50, 12) > 0.95


def test_a_leg_grown_across_a_depth_step_agrees_with_the_stripe_it_continues(tmp_path):
    """The 40-stripe fur side view, seed 11, at 1536 px: growth across a row from the chest to the leg in
    front of it aliased at the depth step, and part of the animal came out one stripe off the stripes it
    continues below the neck (96.9 % of the labelled animal centres right). Made to agree along the
    stripes (``matching._along_stripe``), 99.2 % are."""
    assert _fur_side_view_right(tmp_path, 40, 11) > 0.985


def test_a_leg_held_to_the_chest_by_a_few_aliased_rows_is_cut_off_and_agrees_along_its_stripes(tmp_path):
    """The 50-stripe fur side view, seed 8, at 1536 px (the five-seed bench's one side view placed wrong at
    3072 px): the front leg came out one stripe off the neck it continues, still joined to the rest by
    other aliased row neighbours, and its feet then sank through the floor at the right offset, so the
    whole animal was placed one stripe low (10 % right). Cut off at the least cut between the two and made
    to agree with the neck, the animal is placed right (98.5 %)."""
    assert _fur_side_view_right(tmp_path, 50, 8) > 0.95


def test_a_head_seen_from_above_that_growth_only_reached_at_the_neck_follows_the_neck(tmp_path):
    """The 50-stripe fur top view, seed 12, at 1536 px: the head is a piece of its own (under a quarter of
    the body's size, so left to growth from the placed body), and growth labelled only its neck end, a
    third of it; the head's last four stripes stayed unlabelled and the body length ended at stripe 45
    (463 mm against 535 on the true stripe points). The labelled third fixes the whole piece's offset
    (``matching._anchored``): the head is labelled, and right."""
    from measurement.simulate.capture import write_capture

    cap = write_capture(tmp_path / "top", stripes=50, size=(1536, 1024), seed=12, fur=True, scenes=("top",), poses=0)
    r = scan(read_image(cap / "scan" / "top.png"), load_calibration(cap / "truth" / "truth.json"), "top")
    t = dict(np.load(cap / "truth" / "top_stripes.npz"))
    tk, kind = match_crossings(r.scene_uv.astype(float), t)
    animal = kind == 5
    head = animal & (tk >= 46)
    assert head.sum() >= 0.8 * np.sum((t["kind"] == 5) & (t["stripe"] >= 46))
    assert np.mean(r.scene_stripe[head] == tk[head]) > 0.99
    assert np.mean(r.scene_stripe[animal] == tk[animal]) > 0.99
    assert r.measurements["body_length"]["stripes"][1] == 49


def test_a_side_view_s_tail_that_growth_only_reached_in_part_follows_that_part(tmp_path):
    """The 40-stripe fur side view, seed 12, at 1536 px through a softer lens (a Gaussian blur of 0.6 px):
    the hind leg and tail come apart from the body as a piece under a quarter of its size, growth from the
    placed body labelled only part of it, and the tail's last stripes stayed unlabelled: the body length
    ended at stripe 37, 2.9 % short of the same definition on the true stripe points. The labelled part fixes
    the rest of the piece's offset (``matching._anchored``, from the side leaving the floor and wall alone):
    the tail's stripes are labelled, and right, and the length ends at the true end stripe."""
    import cv2

    from measurement.simulate.capture import write_capture

    cap = write_capture(tmp_path / "side", stripes=40, size=(1536, 1024), seed=12, fur=True, scenes=("side",),
                        poses=0)
    cal, img, t, ref = _view_and_truth(cap, "side")
    soft = np.clip(np.rint(cv2.GaussianBlur(img.astype(np.float64), (0, 0), 0.6)), 0, 255).astype(np.uint8)
    r = scan(soft, cal, "side")
    tk, kind = match_crossings(r.scene_uv.astype(float), t)
    tail = (kind == 5) & (tk >= 38)
    assert tail.sum() >= 0.8 * np.sum((t["kind"] == 5) & (t["stripe"] >= 38))
    assert np.mean(r.scene_stripe[tail] == tk[tail]) > 0.99
    assert r.measurements["body_length"]["stripes"] == ref["body_length"]["stripes"]
    assert abs(r.measurements["body_length_mm"] / ref["body_length_mm"] - 1) < 0.01


def test_a_side_view_s_tail_split_off_with_the_hind_leg_is_read_from_the_leg(tmp_path):
    """The 50-stripe fur side view, seed 9, at 1536 px as rendered: the hind leg and the tail are a small piece
    of their own, and growth from the body labelled the leg's side of it only; the tail stayed unlabelled
    and the body length ended at stripe 35, 26 % short. Read from the labelled part (its rest lands on 1 %
    of lit cells), the tail is labelled right and the length lies within 1.5 % of the true points'."""
    from measurement.simulate.capture import write_capture

    cap = write_capture(tmp_path / "side", stripes=50, size=(1536, 1024), seed=9, fur=True, scenes=("side",),
                        poses=0)
    cal, img, t, ref = _view_and_truth(cap, "side")
    r = scan(img, cal, "side")
    tk, kind = match_crossings(r.scene_uv.astype(float), t)
    tail = (kind == 5) & (tk >= 40)
    assert tail.sum() >= 0.5 * np.sum((t["kind"] == 5) & (t["stripe"] >= 40))
    assert np.mean(r.scene_stripe[tail] == tk[tail]) > 0.99
    assert abs(r.measurements["body_length_mm"] / ref["body_length_mm"] - 1) < 0.015


def test_a_top_view_s_body_width_reads_the_stripes_faint_ends_at_the_flank(tmp_path):
    """Seen from above, each stripe fades where it turns down the flank, and its last rows fall under the
    detector's threshold: the body width (the largest per-stripe extent) of this 1536 px clean render
    came out 3.0 % short of the same definition on the true stripe points. Followed over the faint peaks
    past their last centres (``measurement.ends``), the stripes measure it 1.0 % short; the cloud is the
    same point for point (the faint ends stay out of it)."""
    from measurement.pipeline import ScanParams
    from measurement.simulate.capture import write_capture

    cap = write_capture(tmp_path / "top", stripes=40, size=(1536, 1024), seed=12, fur=False, scenes=("top",), poses=0)
    cal, img, t, ref = _view_and_truth(cap, "top")
    plain = scan(img, cal, "top", params=ScanParams(faint_ends=False))
    ended = scan(img, cal, "top")
    short = abs(plain.measurements["body_height_mm"] / ref["body_height_mm"] - 1)
    now = abs(ended.measurements["body_height_mm"] / ref["body_height_mm"] - 1)
    assert short > 0.02 and now < 0.015 and now < 0.5 * short
    assert ended.measurements["faint_end_points"] > 0
    assert np.array_equal(plain.points, ended.points) and np.array_equal(plain.stripe, ended.stripe)
    assert ended.measurements["body_length_mm"] == plain.measurements["body_length_mm"]


def test_from_the_side_a_drooping_tails_last_stripes_are_in_the_cloud(tmp_path):
    """From the side a drooping tail's last stripes each end below the stripe before, so no row neighbour
    reaches them; read as the tail's tip past the animal's end stripe (``matching._tips``, once read from
    above only), this 1536 px clean render's tail keeps its stripes 38 and 39 (they were out, and the body
    length 1.7 % long: the length's pair is the tail's last stripe and the chest's)."""
    from measurement.simulate.capture import write_capture

    cap = write_capture(tmp_path / "side", stripes=40, size=(1536, 1024), seed=12, fur=False, scenes=("side",),
                        poses=0)
    cal, img, t, ref = _view_and_truth(cap, "side")
    r = scan(img, cal, "side")
    tk, kind = match_crossings(r.uv, t)
    for k in (38, 39):
        crossed = tk[r.stripe == k]  # the true stripe of each point's crossing (-1: none within 1.5 px)
        assert (crossed >= 0).sum() >= 20 and np.all(crossed[crossed >= 0] == k)
    assert r.measurements["body_length"]["stripes"][1] == 39
    assert abs(r.measurements["body_length_mm"] / ref["body_length_mm"] - 1) < 0.005


def test_seen_from_above_a_stripe_end_is_followed_over_the_floor_stripe_it_merges_with(tmp_path, monkeypatch):
    """Seen from above, where a stripe ends at the flank it runs into the floor's stripe four or five over
    (the depth alias) and labelling gave the merged rows to the floor's segment; the walk past the
    stripe's last centre stopped at them, and this 1536 px fur render's body width came out 3.7 % short.
    Stepping over the floor's points as well (three rows into such a merge at most) it is 2.3 % short;
    the cloud is the same point for point. Labelling now leaves such rows unlabelled where it sees the
    floor's segment run on into the animal (``matching._touching_background``), which alone also ends the
    walk's stop there; with that rule off the merge is as it was."""
    import measurement.matching as matching
    import measurement.pipeline as pipeline
    from measurement.simulate.capture import write_capture

    cap = write_capture(tmp_path / "top", stripes=40, size=(1536, 1024), seed=4, fur=True, scenes=("side", "top"),
                        poses=0)
    cal, img, t, ref = _view_and_truth(cap, "top")
    over = scan(img, cal, "top")
    walk = pipeline.faint_ends
    monkeypatch.setattr(pipeline, "faint_ends", lambda *a, **k: walk(*a, **{**k, "over_background": False}))
    unmerged = scan(img, cal, "top")
    monkeypatch.setattr(matching, "_touching_background", lambda c, seg, labels, *a: labels)
    stopped = scan(img, cal, "top")
    before = stopped.measurements["body_height_mm"] / ref["body_height_mm"] - 1
    after = over.measurements["body_height_mm"] / ref["body_height_mm"] - 1
    assert before < -0.03 and -0.025 < after < 0
    assert -0.03 < unmerged.measurements["body_height_mm"] / ref["body_height_mm"] - 1 < 0
    assert np.array_equal(over.points, stopped.points) and np.array_equal(over.stripe, stopped.stripe)


def test_a_side_view_s_stripes_are_followed_down_the_hoof_to_5_mm_above_the_floor(tmp_path, monkeypatch):
    """From the side the tallest stripe runs down a leg to the hoof, whose last rows are faint peaks left
    out of the cloud; the walk past the stripe's last centre stopped at its first point within 12 mm of the
    floor (the background margin's cap), and this 1536 px fur render with a soft camera focus measured the
    body height 2.3 % short of the same definition on the true stripe points. Stopped within 5 mm of the
    floor (``ends.FLOOR_STOP_MM``) the hoof's rows count and it is 0.8 % short; the cloud is the same point
    for point."""
    import measurement.pipeline as pipeline
    from measurement.simulate.capture import write_capture

    cap = write_capture(tmp_path / "side", stripes=40, size=(1536, 1024), seed=4, fur=True, scenes=("side",),
                        poses=0, light={"blur_px": 2.0})
    cal, img, t, ref = _view_and_truth(cap, "side")
    down = scan(img, cal, "side")
    monkeypatch.setattr(pipeline, "FLOOR_STOP_MM", 12.0)
    stopped = scan(img, cal, "side")
    before = stopped.measurements["body_height_mm"] / ref["body_height_mm"] - 1
    after = down.measurements["body_height_mm"] / ref["body_height_mm"] - 1
    assert before < -0.02 and abs(after) < 0.01
    assert np.array_equal(down.points, stopped.points) and np.array_equal(down.stripe, stopped.stripe)


def test_seen_from_above_a_tail_tip_beyond_the_last_labelled_stripe_takes_the_next_index(tmp_path, monkeypatch):
    """From above the tail tip's stripe is a short segment or two beside the floor's stripes, too small to
    be placed by its own shadow, and the body length (first to last stripe group) ran from the next stripe
    in. This 1536 px render with a denser fan (0.7 times the stripe spacing) measured it 3.3 % short of the
    same definition on the true stripe points. A segment one index past the animal's end stripe, beside
    that stripe's points and off the floor, takes that index (``matching._tips``): the length is within
    1 %, and the segments so labelled are right.

    Since pieces grow past the pattern's edge (``matching.PIECE_PAD``) this view's tip stripe (stripe 0)
    joins the body's piece and ``_tips`` has nothing left to take; held to the pattern (``PIECE_PAD`` 0) the
    piece stops one stripe short of it, as every piece did before, and ``_tips`` is tested there."""
    from dataclasses import replace

    import measurement.matching as matching
    from measurement.simulate.capture import write_capture
    from measurement.simulate.rig import Rig, default_rig

    rig = default_rig((1536, 1024), 40)
    dense = Rig(rig.intrinsics, replace(rig.projector, stripe_x=rig.projector.stripe_x * 0.7))
    cap = write_capture(tmp_path / "top", stripes=40, size=(1536, 1024), seed=4, fur=True, scenes=("side", "top"),
                        poses=0, rig=dense)
    cal, img, t, ref = _view_and_truth(cap, "top")
    tips = matching._tips
    monkeypatch.setattr(matching, "_tips", lambda *a, **k: {})
    grown = scan(img, cal, "top")
    assert abs(grown.measurements["body_length_mm"] / ref["body_length_mm"] - 1) < 0.01
    monkeypatch.setattr(matching, "PIECE_PAD", 0.0)
    found: dict = {}
    monkeypatch.setattr(matching, "_tips", lambda *a, **k: found.update(tips(*a, **k)) or dict(found))
    tipped = scan(img, cal, "top")
    monkeypatch.setattr(matching, "_tips", lambda *a, **k: {})
    plain = scan(img, cal, "top")
    before = plain.measurements["body_length_mm"] / ref["body_length_mm"] - 1
    after = tipped.measurements["body_length_mm"] / ref["body_length_mm"] - 1
    assert before < -0.025 and abs(after) < 0.01 and found
    tk, kind = match_crossings(tipped.uv.astype(float), t)
    new = np.isin(tipped.stripe, list(set(found.values()))) & (kind == 5) & (tk >= 0)
    assert new.sum() >= 10 and np.mean(tipped.stripe[new] == tk[new]) > 0.95
    # a drooping tail's stripes lie farther apart than the cloud's connectivity: the tip, cut off from the
    # animal's cluster (here by hand), stays with it
    import measurement.pipeline as pipeline

    monkeypatch.setattr(matching, "_tips", tips)
    isolate = pipeline.isolate_with_margin
    tip_k = np.array(sorted(set(found.values())))

    def cut(pts, *a, **k):
        animal, margin = isolate(pts, *a, **k)
        return animal & ~np.isin(np.arange(len(pts)), np.flatnonzero(np.isin(cut.stripe, tip_k))), margin

    cut.stripe = tipped.scene_stripe
    monkeypatch.setattr(pipeline, "isolate_with_margin", cut)
    kept = scan(img, cal, "top")
    assert np.isin(kept.stripe, tip_k).sum() == np.isin(tipped.stripe, tip_k).sum() > 0


def _view_and_truth(cap, view: str):
    """A rendered capture's true calibration, the view's image, its true stripe crossings and the paper's
    measurements on the true animal points (the figures a scan is held to)."""
    from measurement.body import measure

    t = dict(np.load(cap / "truth" / f"{view}_stripes.npz"))
    on = t["kind"] == 5
    ref = measure(t["points"][on], t["stripe"][on], np.rint(t["uv"][on, 1]).astype(np.int64), view)
    return load_calibration(cap / "truth" / "truth.json"), read_image(cap / "scan" / f"{view}.png"), t, ref


def _column_errors(r, truth: dict) -> np.ndarray:
    """|column| (px) from each animal point of the scan ``r`` to the true crossing nearest it in its row (the
    points within 3 px of one)."""
    from measurement.simulate.truth import nearest_crossings

    best, du = nearest_crossings(r.uv, truth)
    return du[(du < 3) & (truth["kind"][best] == 5)]


def test_under_stripes_twice_as_wide_the_shaded_centres_look_for_the_room_light_farther_out(tmp_path, monkeypatch):
    """A projector whose stripes are twice as wide (the optics bench's variant, at 1536 px): the fixed reach of
    the shaded centroid ended on the stripes' own flanks. Widened with the frame's median stripe width, the
    animal's points lie nearer their true crossings; at the reference width nothing changes."""
    from dataclasses import replace

    import measurement.detection as det
    from measurement.simulate.capture import write_capture
    from measurement.simulate.rig import Rig, default_rig

    rig = default_rig((1536, 1024), 40)
    cap = write_capture(tmp_path / "wide", size=(1536, 1024), seed=4, poses=0, scenes=("side",),
                        rig=Rig(rig.intrinsics, replace(rig.projector, sigma=2 * rig.projector.sigma)))
    cal = load_calibration(cap / "truth" / "truth.json")
    img = read_image(cap / "scan" / "side.png")
    truth = dict(np.load(cap / "truth" / "side_stripes.npz"))
    c = detect_centres(img)
    assert det._shade_for_width(DetectionParams(), c, img.shape[1]).shade_px > DetectionParams().shade_px
    widened = _column_errors(scan(img, cal, "side"), truth)
    monkeypatch.setattr(det, "SHADE_WIDER", np.inf)
    fixed = _column_errors(scan(img, cal, "side"), truth)
    assert np.median(widened) < 0.8 * np.median(fixed)
    assert np.mean(widened < 1.0) > np.mean(fixed < 1.0) + 0.05


def test_at_the_reference_stripe_width_the_shaded_centres_keep_their_reach(small_capture):
    import measurement.detection as det

    img = read_image(small_capture / "scan" / "side.png")
    assert det._shade_for_width(DetectionParams(), detect_centres(img), img.shape[1]) is None


def test_stripes_much_wider_than_the_detector_is_set_for_are_named_in_the_warnings(small_capture, truth_cal):
    from measurement.matching import Labels
    from measurement.pipeline import _warnings

    r = scan(read_image(small_capture / "scan" / "side.png"), truth_cal, "side")
    assert r.measurements["stripe_width_px"] > 0 and not any("as wide as" in w for w in r.measurements["warnings"])
    meas = {"body_length_mm": 500.0, "body_height_mm": 280.0, "stripe_width_px": 11.0}
    warned = _warnings(meas, Labels(np.zeros(3, np.int64), None, None, 100, 0), 11.0 / 8.0)
    assert len(warned) == 1 and "the stripes are 1.4 times as wide as the scan is made for (11 px" in warned[0]
    assert _warnings(meas, Labels(np.zeros(3, np.int64), None, None, 100, 0), 1.0) == []


def test_a_tail_tips_centres_merged_with_a_floor_stripe_feed_the_length_off_the_floor_only():
    """``Labels.merged``: a tip's stripe merged with a floor stripe in the image is off by 1-3 mm, so its
    centres stay out of the cloud and reach the length as wide peaks do (``pipeline._with_merged``), those
    that lie on the floor (the merge's own rows) left out."""
    from measurement.detection import Centres
    from measurement.matching import Labels
    from measurement.pipeline import _with_merged
    from measurement.simulate.rig import default_rig

    rig = default_rig((1536, 1024), 40)
    table = ray_table(rig.intrinsics)
    planes = rig.projector.planes_cam()
    u = np.array([400.0, 430.0, 700.0])
    v = np.array([500, 501, 300], np.int32)
    c = Centres(u, v, np.full(3, 20.0, np.float32), np.full(3, 4.0, np.float32))
    stripe = np.array([3, 3, 12])
    on = intersect(rays_at(u, v, table), planes[stripe])
    floor = np.array([[0.0, 0.0, 1.0, on[0, 2]]])  # the first centre's point lies on the floor
    assert abs(on[1, 2] - on[0, 2]) > 10.0  # the second's well off it
    labels = Labels(stripe, floor, merged=np.array([7]))
    got = _with_merged(None, np.array([0, 1]), c, labels, u, None, table, planes, 3.0)
    assert got is not None
    np.testing.assert_allclose(got[0], on[1:2])
    assert got[1].tolist() == [3] and got[2].tolist() == [501]
    wide = (on[2:3], np.array([12]), np.array([300]))
    got = _with_merged(wide, np.array([0, 1]), c, labels, u, None, table, planes, 3.0)
    assert got[1].tolist() == [12, 3] and got[2].tolist() == [300, 501]
    assert _with_merged(None, np.array([0]), c, labels, u, None, table, planes, 3.0) is None


def test_only_left_out_peaks_past_their_stripes_rows_in_the_cloud_reach_the_extents():
    from measurement.pipeline import _thin_and_past

    animal_stripe = np.array([2, 2, 2, 5, 5] + [3] * 12)
    animal_rows = np.array([10, 11, 12, 40, 41] + list(range(100, 112)))
    stripe, rows = np.array([2, 2, 2, 5, 3, 4]), np.array([9, 11, 13, 39, 105, 7])
    thin, past = _thin_and_past(stripe, rows, animal_stripe, animal_rows, 6, 10, True)
    # rows 9 and 13 lie past stripe 2's rows 10-12, row 39 before stripe 5's; row 11 and 105 inside; stripe 4
    # has no cloud rows, so its centre lies past them
    assert past.tolist() == [True, False, True, True, False, True]
    # the length's wide peaks are those of the stripes the cloud makes no group of (under 10 points)
    assert thin.tolist() == [True, True, True, True, False, True]
    assert not _thin_and_past(stripe, rows, animal_stripe, animal_rows, 6, 10, False)[1].any()
