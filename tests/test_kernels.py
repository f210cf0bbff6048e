"""The compiled kernels against the NumPy forms they replaced, to the bit (or, where a kernel says so, to a rounding)."""

import cv2
import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from measurement import _kernels
from measurement._kernels.rays import _depth
from measurement.matching import gapped_rows_numpy


def _nearest_key(key, target):
    hi = np.clip(np.searchsorted(key, target), 1, len(key) - 1)
    d_lo, d_hi = np.abs(key[hi - 1] - target), np.abs(key[hi] - target)
    upper = d_hi < d_lo
    return np.where(upper, hi, hi - 1), np.where(upper, d_hi, d_lo)


def _link_reference(key, link_px):
    src, dst = [], []
    for gap in (1, 2):
        best, d = _nearest_key(key, key + gap * 1e5)
        ok = d <= link_px * gap
        a, b = np.nonzero(ok)[0], best[ok]
        mutual = _nearest_key(key, key[b] - gap * 1e5)[0] == a
        src.append(a[mutual])
        dst.append(b[mutual])
    s, d = np.concatenate(src), np.concatenate(dst)
    graph = csr_matrix((np.ones(len(s)), (s, d)), shape=(len(key), len(key)))
    return connected_components(graph, directed=False)[1]


def test_link_components_numbers_components_as_scipy_does():
    rng = np.random.default_rng(3)
    rows = np.sort(rng.integers(0, 300, 4000))
    u = rng.uniform(0, 400, len(rows)).round(1)
    order = np.lexsort((u, rows))
    key = rows[order] * 1e5 + u[order]
    assert np.array_equal(_kernels.link_components(key, 2.5), _link_reference(key, 2.5))


def test_depth_sums_three_products_as_einsum_does():
    rng = np.random.default_rng(4)
    rays = rng.normal(size=(5000, 3))
    rays[:, 2] = 1.0
    planes = rng.normal(size=(5000, 4)) * [1, 1, 1, 1000]
    denom = np.einsum("ij,ij->i", rays, planes[:, :3])
    expected = rays[:, 2] * (planes[:, 3] / denom)
    got = np.array([_depth(rays, i, planes, i) for i in range(len(rays))])
    assert np.array_equal(got, expected)


def _majority_reference(voter, vote, n, min_share):
    cast = np.nonzero(vote >= 0)[0]
    if len(cast) == 0:
        return {}
    support = np.bincount(voter)
    pair, first, cnt = np.unique(voter[cast] * (n + 1) + vote[cast], return_index=True, return_counts=True)
    segs, labs = pair // (n + 1), pair % (n + 1)
    order = np.lexsort((first, -cnt, segs))
    best = order[np.r_[True, segs[order][1:] != segs[order][:-1]]]
    best = best[(cnt[best] >= 3) & (cnt[best] >= min_share * support[segs[best]])]
    seg_first = np.full(len(support), len(cast))
    np.minimum.at(seg_first, segs, first)
    best = best[np.argsort(seg_first[segs[best]])]
    return dict(zip(segs[best].tolist(), labs[best].tolist(), strict=True))


def test_majority_keeps_the_earliest_cast_of_a_tie_and_the_first_voted_order():
    rng = np.random.default_rng(5)
    for _ in range(20):
        voter = rng.integers(0, 40, 600)
        vote = rng.integers(-1, 4, 600)
        segs, labs = _kernels.majority(voter, vote, 4, 0.4)
        got = dict(zip(segs.tolist(), labs.tolist(), strict=True))
        expected = _majority_reference(voter, vote, 4, 0.4)
        assert got == expected and list(got) == list(expected)


def test_intersect_matches_the_einsum_formula_to_the_bit():
    from measurement.triangulation import intersect

    def numpy_form(rays, planes):
        denom = np.einsum("ij,ij->i", rays, planes[:, :3])
        with np.errstate(divide="ignore", invalid="ignore"):
            s = planes[:, 3] / denom
        s[np.abs(denom) < 1e-9] = np.nan
        return rays * s[:, None]

    rng = np.random.default_rng(6)
    rays = rng.normal(size=(4000, 3))
    rays[:, 2] = 1.0
    planes = rng.normal(size=(4000, 4)) * [1, 1, 1, 1000]
    planes[:5, :3] = 0.0  # parallel: NaN
    assert np.array_equal(intersect(rays, planes), numpy_form(rays, planes), equal_nan=True)
    # np.einsum sums a column-major array's rows another way: that layout keeps the NumPy code
    fortran = np.asfortranarray(rays)
    assert np.array_equal(intersect(fortran, planes), numpy_form(fortran, planes), equal_nan=True)


def test_gapped_rows_label_the_rows_the_numpy_form_labels():
    rng = np.random.default_rng(7)
    n, m, rows = 40, 37, 300
    steps = np.ones((rows, m - 1))
    for row in steps:  # three missing stripes each, sometimes a fourth
        row[rng.choice(m - 1, 3 + (rng.random() < 0.3), replace=False)] = 2
    u = np.cumsum(np.concatenate([rng.uniform(0, 50, (rows, 1)), steps * 20 + rng.normal(0, 2.5, steps.shape)],
                                 axis=1), axis=1).ravel()
    order = np.arange(len(u))
    got, expected = np.full(len(u), -1), np.full(len(u), -1)
    _kernels.gapped_rows(u, order, m, n, 7, 0.2, got)
    gapped_rows_numpy(u, order, m, n, expected, 7, 0.2)
    assert (expected >= 0).any() and (expected < 0).any()
    assert np.array_equal(got, expected)


def _crowded_reference(row, col, h, w, size):
    mask = np.zeros((h, w), np.uint8)
    mask[row, col] = 1
    counts = cv2.boxFilter(mask, cv2.CV_8U, (size, size), normalize=False, borderType=cv2.BORDER_CONSTANT)
    return counts[row, col] >= 0.5 * size


def test_crowded_counts_as_the_full_frame_box_filter_does():
    rng = np.random.default_rng(5)
    for size in (3, 4, 8, 13, 25):
        for _ in range(40):
            h, w = (int(n) for n in rng.integers(1, 50, 2))
            m = int(rng.integers(1, 300))
            # repeated pixels, the frame's edges and rows far from uniform
            row = np.minimum(rng.integers(0, h, m), rng.integers(0, h, m))
            col = rng.integers(0, w, m)
            assert np.array_equal(_kernels.crowded(row, col, h, size), _crowded_reference(row, col, h, w, size))


def test_inlier_counts_score_planes_as_the_distance_matrix_does():
    rng = np.random.default_rng(5)
    sample = rng.normal(0, 100, (2000, 3)) + [0, 0, 1200]
    n = rng.normal(size=(300, 3))
    n /= np.linalg.norm(n, axis=1)[:, None]
    d = n @ sample[rng.integers(0, 2000, 300)].T[:, 0]
    counts = _kernels.inlier_counts(sample, n, d, 4.0)
    reference = (np.abs(sample @ n.T - d) < 4.0).sum(axis=0)
    assert counts.sum() > 300  # each plane passes through a point of the sample at least
    assert np.abs(counts - reference).max() <= 1  # a point within a rounding of 4 mm may count either way
    from measurement.planes import _inlier_counts

    assert np.array_equal(_inlier_counts(sample, n, d, 4.0), counts)  # half of them on the second core


def test_segment_row_order_sorts_as_lexsort_does():
    rng = np.random.default_rng(6)
    v = rng.integers(3, 900, 20000).astype(np.int32)
    seg = rng.integers(0, 400, 20000)
    assert np.array_equal(_kernels.segment_row_order(seg, v), np.lexsort((v, seg)))
    assert len(_kernels.segment_row_order(seg[:0], v[:0])) == 0


def test_voters_from_grouped_pairs_are_the_voting_pairs_of_a_full_pass():
    from measurement._kernels.growth import _voters

    rng = np.random.default_rng(7)
    n_seg, n_pairs = 300, 5000
    cols = np.zeros((7, n_pairs), np.int64)
    cols[3] = rng.integers(0, n_seg, n_pairs)
    cols[4] = rng.integers(0, n_seg, n_pairs)
    table = np.where(rng.random(n_seg) < 0.4, rng.integers(0, 40, n_seg), -1)
    newly = np.flatnonzero((table >= 0) & (rng.random(n_seg) < 0.3))
    flags = np.zeros(n_seg, bool)
    flags[newly] = True
    full = _kernels.voting_pairs(cols[3], cols[4], table, _kernels.flag_beside(cols[3], cols[4], flags), False)
    got = _voters(cols, table, newly, *_kernels.pair_groups(cols, n_seg))
    assert len(full) > 50
    assert np.array_equal(got, full)


def test_gap_votes_pick_the_labels_the_numpy_gap_test_picks():
    from measurement.triangulation import intersect

    rng = np.random.default_rng(8)
    n, m, n_seg = 40, 3000, 200
    ang = np.deg2rad(np.linspace(-12, 12, n))
    planes = np.column_stack([np.cos(ang), np.zeros(n), np.sin(ang), 250 * np.cos(ang)])
    rays = np.column_stack([rng.uniform(-0.3, 0.3, m), rng.uniform(-0.2, 0.2, m), np.ones(m)])
    seg = rng.integers(0, n_seg, m)
    table = rng.integers(0, n, n_seg)
    pairs = 2000
    cols = np.zeros((7, pairs), np.int64)
    cols[0], cols[1] = rng.integers(0, m, pairs), rng.integers(0, m, pairs)
    cols[2] = rng.choice([-1, 1], pairs)
    cols[3], cols[4] = seg[cols[0]], seg[cols[1]]
    at = np.arange(pairs)
    gaps, tol = (1, 2, 3), 60.0
    got = _kernels.gap_votes(rays, planes, table, cols, at, np.array(gaps, np.int64), tol, n)
    # matching._votes' NumPy form
    idx, nbr, sign, kn = cols[0], cols[1], cols[2], table[cols[4]]
    pn = intersect(rays.take(nbr, axis=0), planes.take(kn, axis=0))
    ks = [kn + sign * gap for gap in gaps]
    on_k = np.clip(np.concatenate(ks), 0, n - 1)
    p_gap = intersect(np.tile(rays.take(idx, axis=0), (len(gaps), 1)), planes.take(on_k, axis=0)).reshape(len(gaps), -1, 3)
    best_k, best_d = np.full(pairs, -1), np.full(pairs, np.inf)
    for g, gap in enumerate(gaps):
        k = ks[g]
        d = np.linalg.norm(p_gap[g] - pn, axis=1) / gap
        better = (k >= 0) & (k < n) & (d < best_d) & (d < tol)
        best_k[better], best_d[better] = k[better], d[better]
    assert (best_k >= 0).sum() > 30
    assert np.array_equal(got, best_k)


def test_first_of_each_is_np_unique_with_first_positions():
    rng = np.random.default_rng(10)
    values = rng.integers(0, 500, 8000)
    ids, pos = _kernels.first_of_each(values, 600)
    ref_ids, ref_pos = np.unique(values, return_index=True)
    assert np.array_equal(ids, ref_ids) and np.array_equal(pos, ref_pos)


def test_stable_group_order_is_a_stable_argsort():
    rng = np.random.default_rng(11)
    keys = rng.integers(0, 250, 30000)
    assert np.array_equal(_kernels.stable_group_order(keys, 260), np.argsort(keys, kind="stable"))


def test_denoise_counted_on_both_cores_keeps_what_one_count_keeps():
    from measurement.detection import Centres
    from measurement.segments import denoise

    rng = np.random.default_rng(8)
    h, w, m = 700, 900, 40_000
    v = np.sort(rng.integers(0, h, m))
    u = np.empty(m)
    for row in np.unique(v):  # each row's centres left to right: some on stripes, some scattered
        at = np.flatnonzero(v == row)
        u[at] = np.sort(np.where(rng.random(len(at)) < 0.7, rng.integers(0, 30, len(at)) * 30.0,
                                 rng.uniform(0, w - 1, len(at))))
    c = Centres(u, v.astype(np.int32), np.full(m, 20, np.float32), np.full(m, 5, np.float32))
    ui = np.clip(np.rint(u).astype(np.int64), 0, w - 1)
    keep = denoise(c, (h, w))
    assert np.array_equal(keep, _kernels.crowded(v.astype(np.int64), ui, h, 5))
    assert keep.any() and not keep.all()


def test_segment_rows_sorts_as_lexsort_does_with_rows_in_order_or_not():
    from measurement.segments import segment_rows

    rng = np.random.default_rng(9)
    seg = rng.integers(0, 300, 5000)
    for v in (np.sort(rng.integers(0, 900, 5000)), rng.integers(0, 900, 5000)):  # by row (detection), shuffled
        assert np.array_equal(segment_rows(seg, v), np.lexsort((v, seg)))


def test_row_order_sorts_as_lexsort_does_listed_by_row_or_not():
    from measurement.detection import Centres
    from measurement.segments import row_order

    rng = np.random.default_rng(10)
    v = rng.integers(0, 300, 4000).astype(np.int32)
    u = rng.integers(0, 2000, 4000) + rng.choice([0.0, 0.25, 0.5], 4000)  # repeated columns in a row too
    for order in (np.lexsort((u, v)), rng.permutation(4000)):  # as detection lists them, and shuffled
        c = Centres(u[order], v[order], np.zeros(4000, np.float32), np.zeros(4000, np.float32))
        assert np.array_equal(row_order(c), np.lexsort((c.u, c.v)))


def test_union_sorted_merges_as_the_sort_of_both_does():
    from measurement.offsets import in_sorted, union_sorted

    rng = np.random.default_rng(11)
    for na, nb in ((0, 5), (5, 0), (3000, 400), (400, 3000), (1, 1)):
        a = np.unique(rng.integers(0, 5000, na)).astype(np.int64)
        b = np.unique(np.concatenate([rng.integers(0, 5000, nb), a[: len(a) // 3]])).astype(np.int64)
        reference = np.sort(np.concatenate([a, b[~in_sorted(b, a)]]), kind="stable")
        assert np.array_equal(union_sorted(a, b), reference) and np.array_equal(reference, np.union1d(a, b))


def test_walk_stops_clear_what_the_numpy_steps_clear():
    from measurement.ends import walk_stops_numpy

    rng = np.random.default_rng(5)
    for _ in range(30):
        # walks listed step by step: each step a random ascending subset of the surviving walks
        n_w, walk = int(rng.integers(1, 12)), []
        alive = np.arange(n_w)
        while len(alive):
            alive = np.sort(rng.choice(alive, int(rng.integers(0, len(alive) + 1)), replace=False))
            walk.extend(alive.tolist())
        walk = np.array(walk, np.int64)
        near = rng.random(len(walk)) < 0.1
        other = np.where(rng.random(len(walk)) < 0.6, rng.integers(0, 3, len(walk)), -1).astype(np.int64)
        keep = rng.random(len(walk)) < 0.95
        want = walk_stops_numpy(walk, near, other, 2, keep.copy()) if len(walk) else keep
        assert np.array_equal(_kernels.walk_stops(walk, near, other, 2, keep.copy()), want)
