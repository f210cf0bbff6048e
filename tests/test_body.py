import numpy as np
import pytest

from measurement.body import background_margin, isolate, measure


def _barrel(length=400.0, radius=100.0, n_stripes=20, rows=60):
    """Vertical stripe profiles across a horizontal half-cylinder (the animal's flank seen from the side):
    stripe k at x = k * length / (n - 1), each a vertical arc of height 2 * radius."""
    pts, stripe, row = [], [], []
    for k in range(n_stripes):
        x = k * length / (n_stripes - 1)
        ang = np.linspace(-np.pi / 2, np.pi / 2, rows)
        y, z = radius * np.sin(ang), 1200 - radius * np.cos(ang)
        pts.append(np.column_stack([np.full(rows, x), y, z]))
        stripe.append(np.full(rows, k))
        row.append(np.arange(rows))
    return np.vstack(pts), np.concatenate(stripe), np.concatenate(row)


def test_height_is_the_largest_stripe_extent_and_length_the_end_groups_distance():
    pts, stripe, rows = _barrel()
    m = measure(pts, stripe, rows, "side")
    assert abs(m["body_height_mm"] - 200.0) < 200.0 * 0.03  # robust 1 %-99 % quantiles trim the ends
    assert abs(m["body_length_mm"] - 400.0) < 0.01
    assert m["stripes_detected"] == 20 and m["body_length"]["stripes"] == [0, 19]
    assert len(m["body_height"]["points"]) == 2


def test_a_stray_speck_does_not_move_the_extremes():
    pts, stripe, rows = _barrel()
    clean = measure(pts, stripe, rows, "side")["body_height_mm"]
    pts = np.vstack([pts, [[200.0, 400.0, 1200.0]]])
    stripe = np.append(stripe, 10)
    rows = np.append(rows, 30)
    assert abs(measure(pts, stripe, rows, "side")["body_height_mm"] - clean) < 3.0


def test_top_view_names_the_extent_body_width():
    pts, stripe, rows = _barrel()
    m = measure(pts, stripe, rows, "top")
    assert "body_width" in m and m["body_height_is"] == "body_width"


def test_isolation_drops_the_floor_and_stray_clusters():
    pts, _, _ = _barrel()
    floor = np.column_stack([np.random.default_rng(0).uniform(-300, 700, (500, 2)), np.zeros(500)])[:, [0, 2, 1]]
    floor[:, 1] = -150.0
    floor[:, 2] += 1200
    stray = np.array([[2000.0, 0, 1500], [2005.0, 0, 1500]])
    allp = np.vstack([pts, floor, stray])
    keep = isolate(allp, np.array([[0.0, 1.0, 0.0, -150.0]]))
    assert keep[: len(pts)].all() and not keep[len(pts):].any()


def test_isolation_passes_over_a_larger_box_for_the_curved_animal():
    """A feed box beside the animal can hold more points than the animal: the largest cluster that does
    not lie on three planes is kept."""
    from measurement.body import planar_share

    rng = np.random.default_rng(1)
    animal, _, _ = _barrel(length=300.0, radius=80.0, n_stripes=15, rows=60)  # 900 points
    faces = [np.column_stack([rng.uniform(0, 260, 700), rng.uniform(-90, 90, 700), np.full(700, 1000.0)]),
             np.column_stack([np.full(500, 260.0), rng.uniform(-90, 90, 500), rng.uniform(1000, 1220, 500)]),
             np.column_stack([rng.uniform(0, 260, 500), np.full(500, -90.0), rng.uniform(1000, 1220, 500)])]
    box = np.vstack(faces) + np.array([600.0, 0.0, 0.0])  # 1700 points, 300 mm away from the animal
    pts = np.vstack([animal, box]) + rng.normal(0, 0.3, (len(animal) + len(box), 3))
    assert planar_share(pts[len(animal):]) > 0.95 and planar_share(pts[:len(animal)]) < 0.6
    keep = isolate(pts, None)
    assert keep[:len(animal)].all() and not keep[len(animal):].any()
    # no box beside it: the largest cluster, as before
    assert isolate(pts[:len(animal)], None).all()


def test_isolation_keeps_a_foot_down_to_a_few_noise_widths_above_the_floor():
    pts, _, _ = _barrel()
    leg = np.column_stack([np.full(200, 200.0), np.linspace(-100.0, -150.0, 200), np.full(200, 1200.0)])
    rng = np.random.default_rng(1)
    floor = np.column_stack([rng.uniform(-300, 700, 3000), -150.0 + rng.normal(0, 0.3, 3000),
                             rng.uniform(1000, 1400, 3000)])
    keep = isolate(np.vstack([pts, leg, floor]), np.array([[0.0, 1.0, 0.0, -150.0]]))
    height = leg[:, 1] + 150.0
    leg_kept = keep[len(pts): len(pts) + len(leg)]
    assert keep[: len(pts)].all() and not keep[len(pts) + len(leg):].any()
    assert leg_kept[height > 4.0].all() and not leg_kept[height < 2.5].any()


def test_background_margin_follows_the_planes_noise():
    rng = np.random.default_rng(2)
    quiet = np.abs(rng.normal(0, 0.2, 5000))
    noisy = np.abs(rng.normal(0, 0.8, 5000))
    assert background_margin(quiet) == 3.0  # 10 sigma = 2 mm, never under 3 mm
    assert abs(background_margin(noisy) - 8.0) < 0.5  # 10 sigma
    assert background_margin(np.abs(rng.normal(0, 5.0, 5000))) == 12.0  # never over background_mm


def test_column_medians_equal_np_median_bit_for_bit():
    from measurement.body import _column_medians

    rng = np.random.default_rng(3)
    for n in (1, 2, 3, 4, 57, 100, 733):
        x = rng.normal(500.0, 80.0, (n, 3)).round(rng.integers(0, 4))  # ties too
        assert _column_medians(x).tobytes() == np.median(x, axis=0).tobytes()
    x = rng.normal(size=(9, 3))
    x[4, 1] = np.nan
    assert np.array_equal(_column_medians(x), np.median(x, axis=0), equal_nan=True)


def _groups(seed: int, n_groups: int = 12):
    """Stripe groups of a few to several hundred points along random directions, some with specks, some
    with tied coordinates, in stripe order."""
    rng = np.random.default_rng(seed)
    pts, stripe = [], []
    for k in range(n_groups):
        n = int(rng.integers(5, 700))
        g = rng.normal(size=(n, 3)) * rng.uniform(0.1, 100, 3)
        g = g @ np.linalg.qr(rng.normal(size=(3, 3)))[0] + rng.normal(size=3) * 300
        if k % 3 == 0:
            g[:4] += rng.normal(size=(4, 3)) * 500
        if k % 4 == 1:
            g = g.round(0)
        pts.append(g)
        stripe.append(np.full(n, k))
    return np.vstack(pts), np.concatenate(stripe)


def test_compiled_extents_equal_the_numpy_extent_of_each_group():
    from measurement.body import _extent, _extents

    for seed in range(8):
        pts, stripe = _groups(seed)
        first = np.searchsorted(stripe, np.unique(stripe))
        last = np.searchsorted(stripe, np.unique(stripe), side="right")
        ext, ends = _extents(pts, first, last, 0.01)
        for g, (a, b) in enumerate(zip(first, last, strict=True)):
            want, want_ends = _extent(pts[a:b], 0.01)
            assert abs(ext[g] - want) <= 1e-12 * abs(want)
            assert np.allclose(ends[g], want_ends, rtol=1e-12, atol=1e-9)  # the same sign of the direction


def test_extents_of_tiny_or_non_finite_groups_fall_back_to_numpy():
    import pytest

    from measurement.body import _extent, _extents

    pts, _ = _groups(1, 2)
    ext, ends = _extents(pts, np.array([0, 3]), np.array([3, 40]), 0.01)
    for g, (a, b) in enumerate([(0, 3), (3, 40)]):
        want, want_ends = _extent(pts[a:b], 0.01)
        assert abs(ext[g] - want) <= 1e-12 * abs(want) and np.allclose(ends[g], want_ends, rtol=1e-12)
    pts[7, 1] = np.nan  # as np.linalg.svd does, refused
    with pytest.raises(np.linalg.LinAlgError):
        _extents(pts, np.array([0, 3]), np.array([3, 40]), 0.01)


def _length_reference(points, stripe, rows, groups, min_rows):
    """The outermost pair of groups sharing at least min_rows image rows, by set intersections."""
    row_sets = {k: np.unique(rows[stripe == k]) for k in groups}
    for span in range(len(groups) - 1, 0, -1):
        best = None
        for a_i in range(len(groups) - span):
            a, b = groups[a_i], groups[a_i + span]
            shared = np.intersect1d(row_sets[a], row_sets[b], assume_unique=True)
            if len(shared) >= min_rows and (best is None or len(shared) > len(best[2])):
                best = (a, b, shared)
        if best is not None:
            return best[0], best[1], len(best[2])
    return None


def test_length_takes_the_pair_the_row_set_intersections_take():
    from measurement.body import _length

    rng = np.random.default_rng(5)
    for _ in range(20):
        pts, stripe, rows = _barrel(n_stripes=int(rng.integers(2, 15)), rows=40)
        rows = rows + rng.integers(-25, 25, len(stripe)).clip(-10, 10) * (stripe % 3)  # shifted, with repeats
        keep = rng.random(len(stripe)) > 0.3
        pts, stripe, rows = pts[keep], stripe[keep], rows[keep] + 100
        groups = [int(k) for k in np.unique(stripe)]
        got, want = _length(pts, stripe, rows, groups, 10), _length_reference(pts, stripe, rows, groups, 10)
        assert (got is None) == (want is None)
        if got is not None:
            assert (got["stripes"][0], got["stripes"][1], got["rows"]) == want


def test_oriented_box_axes_are_np_linalg_svd_s_to_the_bit():
    from measurement.body import _box

    pts, _, _ = _barrel()
    c = pts.mean(axis=0)
    assert np.array_equal(np.array(_box(pts)["axes"]), np.linalg.svd(pts - c, full_matrices=False)[2])


def test_plane_products_in_blocks_equal_one_matrix_product_to_the_bit():
    from measurement.body import _plane_products

    rng = np.random.default_rng(7)
    for n in (1, 4095, 4096, 4097, 30_000, 87_565):
        for planes in (1, 2, 3):
            pts = rng.normal(size=(n, 3)) * 400 + [0, 100, 1500]
            bg = rng.normal(size=(planes, 4))
            assert np.array_equal(_plane_products(pts, bg[:, :3].T), pts @ bg[:, :3].T)


def test_compiled_voxel_cells_equal_the_numpy_floor_of_the_offsets():
    from measurement import _kernels

    rng = np.random.default_rng(9)
    for n in (1, 2, 50, 20_000):
        pts = rng.normal(size=(n, 3)) * rng.uniform(1, 400, 3) + [0, 50, 1200]
        pts[: n // 3] = pts[: n // 3].round(-1)  # on voxel borders too
        idx = np.flatnonzero(rng.random(n) < 0.7) if n > 2 else np.arange(n)
        if len(idx) == 0:
            continue
        kept = pts[idx]
        ijk = np.floor((kept - kept.min(axis=0)) / 25.0).astype(np.int64)
        shape = tuple(ijk.max(axis=0) + 1)
        flat, got_shape = _kernels.voxel_cells(pts, idx, 25.0)
        assert tuple(got_shape) == shape and np.array_equal(flat, np.ravel_multi_index(tuple(ijk.T), shape))


def test_stripe_counts_are_np_unique_s():
    from measurement.body import _stripe_counts

    rng = np.random.default_rng(4)
    for stripe in (rng.integers(0, 60, 5000), rng.integers(-3, 5, 50).astype(np.int32), np.zeros(0, np.int64),
                   rng.integers(0, 9, 30).astype(np.float64)):
        ks, counts = _stripe_counts(stripe)
        want_ks, want_counts = np.unique(stripe, return_counts=True)
        assert np.array_equal(ks, want_ks) and ks.dtype == want_ks.dtype and np.array_equal(counts, want_counts)


def test_oriented_box_extents_are_np_quantile_s():
    from measurement.body import _box

    pts, _, _ = _barrel()
    pts = pts + np.random.default_rng(2).normal(0, 3.0, pts.shape)
    c = pts.mean(axis=0)
    vt = np.linalg.svd(pts - c, full_matrices=False)[2]
    lo, hi = np.quantile((pts - c) @ vt.T, [0.01, 0.99], axis=0)
    box = _box(pts)
    assert [box["length_mm"], box["height_mm"], box["width_mm"]] == [round(float(v), 2) for v in hi - lo]


def test_compiled_plane_distances_equal_the_numpy_minimum_of_the_planes():
    from measurement import _kernels
    from measurement.body import _plane_products

    rng = np.random.default_rng(10)
    for planes in (1, 2, 3):
        pts = rng.normal(size=(5000, 3)) * 300 + [0, 100, 1400]
        pts[::97, rng.integers(0, 3)] = np.nan
        bg = np.column_stack([rng.normal(size=(planes, 3)), rng.uniform(-800, 800, planes)])
        bg[:, :3] /= np.linalg.norm(bg[:, :3], axis=1, keepdims=True)
        d = np.abs(_plane_products(pts, bg[:, :3].T) - bg[:, 3])
        d = np.minimum.reduce(list(d.T)) if planes > 1 else d[:, 0]
        finite = np.isfinite(pts).all(axis=1)
        got_finite, got_d = np.empty(len(pts), bool), np.empty(len(pts))
        near = _kernels.plane_distances(pts, _plane_products(pts, bg[:, :3].T), np.ascontiguousarray(bg[:, 3]),
                                        150.0, got_finite, got_d)
        assert np.array_equal(got_finite, finite) and np.array_equal(got_d, d, equal_nan=True)
        assert np.array_equal(near, d[finite][d[finite] <= 150.0])


def test_stripe_groups_are_ordered_as_a_stable_argsort_orders_them():
    from measurement.body import _stable_order

    rng = np.random.default_rng(12)
    for stripe in (rng.integers(0, 50, 3000), rng.integers(0, 50, 3000).astype(np.int32), np.zeros(0, np.int64)):
        assert np.array_equal(_stable_order(stripe), np.argsort(stripe, kind="stable"))


def _line(n=101, length=100.0):
    """A stripe group of n points along x from 0 to ``length`` mm (a straight stripe seen end to end)."""
    x = np.linspace(0.0, length, n)
    return np.column_stack([x, 0.01 * np.sin(x), np.full(n, 1200.0)])


def test_a_faint_end_continuing_a_stripe_extends_its_extent():
    from measurement.body import _extent, _extent_with

    pts = _line()
    extra = np.column_stack([np.arange(101.0, 121.0), np.zeros(20), np.full(20, 1200.0)])
    alone, _ = _extent(pts, 0.01)
    with_end, ends, used = _extent_with(pts, extra, np.zeros(20, np.int64), 0.01)
    assert used == 20 and with_end > alone + 15.0
    assert ends[:, 0].max() > 118.0


def test_the_end_of_a_stray_bit_past_the_trimmed_extremes_extends_nothing():
    from measurement.body import _extent, _extent_with

    pts = np.vstack([_line(), [[140.0, 0.0, 1200.0]]])  # a speck the 1 % trim leaves out, within the fences
    extra = np.column_stack([np.arange(141.0, 149.0), np.zeros(8), np.full(8, 1200.0)])  # walked on from it
    alone, _ = _extent(pts, 0.01)
    with_end, _, used = _extent_with(pts, extra, np.zeros(8, np.int64), 0.01)
    assert used == 0 and with_end == alone
    # walked on from the group's end instead, the same kind of points count
    extra = np.column_stack([np.arange(101.0, 109.0), np.zeros(8), np.full(8, 1200.0)])
    assert _extent_with(pts, extra, np.zeros(8, np.int64), 0.01)[2] == 8


def test_faint_ends_change_the_extents_only():
    pts, stripe, rows = _barrel()
    keep = np.abs(pts[:, 1]) < 80  # every stripe loses its last rows at both ends
    plain = measure(pts[keep], stripe[keep], rows[keep], "side")
    up = np.flatnonzero(~keep & (stripe == 7) & (pts[:, 1] > 0))
    down = np.flatnonzero(~keep & (stripe == 7) & (pts[:, 1] < 0))[::-1]  # each walk from the stripe's end out
    lost = np.r_[up, down]
    walk = np.r_[np.zeros(len(up), np.int64), np.ones(len(down), np.int64)]
    ended = measure(pts[keep], stripe[keep], rows[keep], "side", ends=(pts[lost], stripe[lost], walk))
    assert ended["body_height_mm"] > plain["body_height_mm"] + 30.0
    assert ended["body_height"]["stripe"] == 7 and ended["faint_end_points"] == len(lost)
    assert ended["body_length_mm"] == plain["body_length_mm"]
    assert ended["stripes_detected"] == plain["stripes_detected"]


def test_left_out_peaks_past_a_stripes_rows_extend_the_extents_only():
    pts, stripe, rows = _barrel(rows=240)
    keep = np.abs(pts[:, 1]) < 94  # every stripe loses its last rows at both ends, as at a grazing flank
    plain = measure(pts[keep], stripe[keep], rows[keep], "top")
    lost = np.flatnonzero(~keep & (stripe == 7))
    past = measure(pts[keep], stripe[keep], rows[keep], "top", past_ends=(pts[lost], stripe[lost]))
    # (each point counts within ENDS_STEP_MM of the group's trimmed extremes: here all of them)
    assert past["body_height_mm"] > plain["body_height_mm"] + 8.0 and past["body_width"]["stripe"] == 7
    assert past["faint_end_points"] == len(lost)
    assert past["body_length_mm"] == plain["body_length_mm"] and past["stripes_detected"] == plain["stripes_detected"]
    # with faint ends as well, each left-out point is a walk of its own beside theirs
    up = np.flatnonzero(~keep & (stripe == 7) & (pts[:, 1] > 0))
    both = measure(pts[keep], stripe[keep], rows[keep], "top", ends=(pts[up], stripe[up], np.zeros(len(up), np.int64)),
                   past_ends=(pts[lost], stripe[lost]))
    assert both["faint_end_points"] == len(up) + len(lost) and abs(both["body_height_mm"] - past["body_height_mm"]) < 0.1
    # a speck far past the stripe's end (beyond its fences) moves nothing
    speck = np.array([[0.0, 400.0, 1200.0]])
    far = measure(pts[keep], stripe[keep], rows[keep], "top", past_ends=(speck, np.array([7])))
    assert far["body_height_mm"] == plain["body_height_mm"]


def test_compiled_extents_with_faint_ends_equal_the_numpy_ones():
    from measurement import _kernels
    from measurement.body import ENDS_STEP_MM, _extent_with

    rng = np.random.default_rng(3)
    for seed in range(6):
        pts, stripe = _groups(seed)
        for k in np.unique(stripe):
            x = pts[stripe == k]
            if len(x) < 12:
                continue
            extra = x[rng.integers(0, len(x), 30)] * rng.uniform(0.9, 1.4) + rng.normal(size=(30, 3))
            walk = np.sort(rng.integers(0, 4, 30))
            walks, first = np.unique(walk, return_index=True)
            start = first[np.searchsorted(walks, walk)]
            want, want_ends, want_n = _extent_with(x, extra, start, 0.01)
            ends = np.zeros((2, 3))
            got, n = _kernels.group_extent_with(x, extra, start, 0.01, ENDS_STEP_MM, ends)
            assert abs(got - want) <= 1e-9 * max(abs(want), 1.0) and n == want_n
            assert np.allclose(ends, want_ends, rtol=1e-12, atol=1e-9)


def test_the_length_reads_wide_peaks_only_of_stripes_the_cloud_makes_no_group_of():
    """A stripe over a thin part (a tail's tip) is all wide, dim peaks the cloud leaves out: with only 6 of
    its 60 rows in the cloud it makes no group, and the length runs from the next stripe in. Its wide peaks
    make it a group for the length; wide peaks of a stripe that already is one change nothing (more rows
    there would move the 10-row rule), nor do they change the extents or the groups."""
    pts, stripe, rows = _barrel()
    first = stripe == 0
    kept = ~first | (rows < 6)  # stripe 0 keeps 6 rows in the cloud
    plain = measure(pts[kept], stripe[kept], rows[kept], "side")
    assert plain["body_length"]["stripes"] == [1, 19]
    wide_at = np.flatnonzero(first & (rows >= 6))
    wide = (pts[wide_at], stripe[wide_at], rows[wide_at])
    m = measure(pts[kept], stripe[kept], rows[kept], "side", wide=wide)
    assert m["body_length"]["stripes"] == [0, 19] and m["length_wide_groups"] == [0]
    assert m["body_length_mm"] == pytest.approx(400.0, abs=0.5) and plain["body_length_mm"] < 390.0
    assert m["body_height_mm"] == plain["body_height_mm"] and m["stripes_detected"] == plain["stripes_detected"]
    # wide peaks of a stripe the cloud makes a group of are not read: stripe 1 keeps its upper half, stripe
    # 19 its lower one, so the two share no row and the length is another pair's; stripe 1's wide peaks in
    # the lower half would have made them share 30
    cut = ~first & ~((stripe == 1) & (rows >= 30)) & ~((stripe == 19) & (rows < 30))
    apart = measure(pts[cut], stripe[cut], rows[cut], "side")
    assert apart["body_length"]["stripes"] != [1, 19]
    lower = np.flatnonzero((stripe == 1) & (rows >= 30))
    again = measure(pts[cut], stripe[cut], rows[cut], "side", wide=(pts[lower], stripe[lower], rows[lower]))
    assert again["body_length"] == apart["body_length"] and "length_wide_groups" not in again


def test_the_length_reads_faint_ends_only_of_stripes_neither_the_cloud_nor_wide_peaks_make_a_group_of():
    """A tail's tip seen from above can hold its outermost stripe in a handful of rows, its other rows too dim
    even for a wide peak: the faint ends walked from those rows (with their image rows) make it a group for
    the length, as wide peaks do. Faint ends of a stripe the cloud or its wide peaks already make a group of
    change nothing: walked past a stripe's true end they run on in the blur's halo (the 40-stripe fur top
    view of seed 12: 32 rows for the truth's 20, the length -0.5 -> -1.3 %)."""
    pts, stripe, rows = _barrel()
    first = stripe == 0
    kept = ~first | (rows < 6)
    plain = measure(pts[kept], stripe[kept], rows[kept], "top")
    assert plain["body_length"]["stripes"] == [1, 19]
    faint_at = np.flatnonzero(first & (rows >= 6))
    walk = np.zeros(len(faint_at), np.int64)
    ends = (pts[faint_at], stripe[faint_at], walk, rows[faint_at])
    m = measure(pts[kept], stripe[kept], rows[kept], "top", ends=ends)
    assert m["body_length"]["stripes"] == [0, 19] and m["length_faint_groups"] == [0]
    assert m["body_length_mm"] == pytest.approx(400.0, abs=0.5)
    assert m["stripes_detected"] == plain["stripes_detected"]
    # without their rows (as before) they are not read for the length
    assert measure(pts[kept], stripe[kept], rows[kept], "top", ends=ends[:3])["body_length"] == plain["body_length"]
    # a stripe the wide peaks make a group of takes no faint ends: a halo's rows would move its mean
    half = faint_at[: len(faint_at) // 2]
    wide = (pts[half], stripe[half], rows[half])
    halo = pts[faint_at] + np.array([0.0, 0.0, 40.0])  # far off: read, it would move the length
    w = measure(pts[kept], stripe[kept], rows[kept], "top", wide=wide)
    both = measure(pts[kept], stripe[kept], rows[kept], "top", wide=wide,
                   ends=(halo, stripe[faint_at], walk, rows[faint_at]))
    assert both["body_length"] == w["body_length"] and "length_faint_groups" not in both


def test_points_beside_the_animal_join_it_and_those_apart_or_on_the_floor_do_not():
    from measurement.body import beside

    animal = np.column_stack([np.linspace(0, 300, 200), np.zeros(200), np.full(200, 1200.0)])
    floor = np.array([[0.0, 1.0, 0.0, -150.0]])  # y = -150
    points = np.array([[310.0, 5.0, 1200.0],     # just past the animal's end: joins
                       [400.0, 0.0, 1200.0],     # 100 mm away: apart
                       [150.0, -149.0, 1200.0],  # on the floor
                       [np.nan, 0.0, 1200.0]])
    assert beside(animal, points, floor, 3.0, 25.0).tolist() == [True, False, False, False]
