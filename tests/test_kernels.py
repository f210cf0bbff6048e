"""The compiled kernels against the NumPy forms they replaced, to the bit."""

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from measurement import _kernels


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
    got = np.array([_kernels._depth(rays, i, planes, i) for i in range(len(rays))])
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
