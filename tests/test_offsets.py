"""The absolute stripe index of an isolated piece, on an exact synthetic scene: a flat plate in front of a
wall, lit by the reference rig's stripes, with its shadow and the camera's occlusion worked out exactly."""

import numpy as np
import pytest

from measurement.offsets import occlusion_offset
from measurement.simulate.rig import default_rig

N = 40
WALL_Z, PLATE_Z, HALF_H = 1400.0, 1100.0, 80.0


def _on_stripe(planes: np.ndarray, k: int, z: float, y: np.ndarray) -> np.ndarray:
    n, d = planes[k, :3], planes[k, 3]
    x = (d - n[2] * z - n[1] * y) / n[0]
    return np.column_stack([x, y, np.full_like(y, z)])


def _scene(x_left: float, x_right: float):
    """Rays (M, 3), background labels (M,) (-1 on the plate), the plate's point indices and true labels."""
    rig = default_rig((1536, 1024), N)
    planes, centre = rig.projector.planes_cam(), rig.projector.centre_cam

    def on_plate(p):
        return (p[:, 0] >= x_left) & (p[:, 0] <= x_right) & (np.abs(p[:, 1]) <= HALF_H)

    pts, lab, plate = [], [], []
    for k in range(N):
        p = _on_stripe(planes, k, PLATE_Z, np.arange(-HALF_H, HALF_H, 2.0))
        p = p[on_plate(p)]
        pts.append(p), lab.append(np.full(len(p), k)), plate.append(np.ones(len(p), bool))
        w = _on_stripe(planes, k, WALL_Z, np.arange(-300.0, 300.0, 2.0))
        t = (PLATE_Z - centre[2]) / (w[:, 2] - centre[2])
        shadow = on_plate(centre + t[:, None] * (w - centre))
        hidden = on_plate(w * (PLATE_Z / WALL_Z))
        w = w[~shadow & ~hidden]
        pts.append(w), lab.append(np.full(len(w), k)), plate.append(np.zeros(len(w), bool))
    pts, lab, plate = np.vstack(pts), np.concatenate(lab), np.concatenate(plate)
    return planes, pts / pts[:, 2:3], np.where(plate, -1, lab), np.nonzero(plate)[0], lab


@pytest.mark.parametrize("x_left, x_right", [(-60.0, 60.0), (-150.0, -20.0)])
def test_offset_of_a_plate_from_its_shadow(x_left, x_right):
    planes, rays, cl, idx, true = _scene(x_left, x_right)
    k_min = int(true[idx].min())
    r = np.zeros(len(rays), np.int64)
    r[idx] = true[idx] - k_min
    assert occlusion_offset(rays, planes, cl, r, idx, N, projector_right=True) == k_min


def test_a_piece_lit_to_the_last_stripe_is_not_pushed_past_it():
    """Stray centres at the plate's left edge carry one index too few (a partial stripe at an outline);
    at the true offset they land on lit wall, so the conflict curve alone cannot settle the plate; the
    pattern's edge can: one stripe higher would put its rightmost stripe past the projector's last."""
    planes, rays, cl, idx, true = _scene(-60.0, 2000.0)
    assert true[idx].max() == N - 1
    k_min = int(true[idx].min())
    left = idx[true[idx] == k_min]
    rays = np.vstack([rays, rays[left]])
    cl = np.concatenate([cl, np.full(len(left), -1)])
    r = np.zeros(len(rays), np.int64)
    r[idx] = true[idx] - k_min
    r[len(true):] = -1
    idx = np.concatenate([idx, np.arange(len(true), len(rays))])
    # without the pattern's edge the stray column's conflicts leave the plate unplaced or one stripe high
    assert occlusion_offset(rays, planes, cl, r, idx, N, projector_right=True, pattern_edge=1.0) != k_min
    assert occlusion_offset(rays, planes, cl, r, idx, N, projector_right=True) == k_min


def test_a_piece_hemmed_in_on_both_sides_is_read_at_the_bottom_of_its_curve():
    """A tail beside an already placed body: conflicts rise both ways, so the minimum is the answer
    even with a residue on it; a one-sided curve (conflict-free toward unseen cells) is not a V."""
    from measurement.offsets import sharp_minimum

    v_shape = {12: 0.31, 13: 0.13, 14: 0.003, 15: 0.10, 16: 0.20}
    no_edge = {o: (0.0, 0.0) for o in range(10, 20)}
    assert sharp_minimum(v_shape, no_edge) == 14
    one_sided = {12: 0.31, 13: 0.06, 14: 0.0, 15: 0.0, 16: 0.0}
    assert sharp_minimum(one_sided, no_edge) is None
    # past the last stripe counts as a wall: the piece lit up to the pattern's edge is a V too
    edge = {**no_edge, 15: (0.0, 0.3), 16: (0.0, 0.6)}
    assert sharp_minimum({12: 0.31, 13: 0.13, 14: 0.01}, edge) == 14


def test_a_piece_with_play_between_its_conflicts_and_the_pattern_edge_is_refused():
    """Conflicts rise below offset 20; above it nothing conflicts until the piece would leave the
    pattern. One stripe of play: the offset nearest the conflicts. Four: it could sit anywhere."""
    from measurement.offsets import choose_offset

    ramp = {o: 0.04 * (20 - o) for o in range(8, 20)}

    def curve(last_inside):
        conflicts = {**ramp, **{o: 0.0 for o in range(20, last_inside + 4)}}
        beyond = {o: (0.0, 0.0 if o <= last_inside else 0.05 * (o - last_inside)) for o in conflicts}
        return conflicts, beyond

    assert choose_offset(*curve(21)) == 20
    assert choose_offset(*curve(24)) is None
    # the floor bounds the run short of the edge: the piece sinks behind it from offset 22 on, so only one
    # stripe of play is left (a cow seen from the side at 3072 px was refused without this)
    assert choose_offset(*curve(24), behind=lambda off: 0.05 if off >= 22 else 0.0) == 20
    # a bound that lies beyond the edge changes nothing
    assert choose_offset(*curve(24), behind=lambda off: 0.05 if off >= 26 else 0.0) is None


def test_a_steady_shallow_ramp_places_the_piece_at_its_minimum_when_asked():
    """A sitting rabbit seen from the side (1536 px) hides most of its shadow's lit edge: its conflicts
    fall steadily by under 0.005 a stripe to zero at the true offset, 27. The usual reading refuses such a
    curve; the shallow one takes its minimum, not the offset half a step up the ramp (26)."""
    from measurement.offsets import choose_offset, steady_ramp

    conflicts = {19: 0.0107, 20: 0.0087, 21: 0.0069, 22: 0.0054, 23: 0.0048, 24: 0.0038, 25: 0.0022,
                 26: 0.0008, 27: 0.0, 28: 0.0007, 29: 0.0025, 30: 0.0048, 31: 0.0074}
    beyond = {o: (0.0, 0.0) for o in conflicts}
    assert choose_offset(conflicts, beyond) is None
    assert choose_offset(conflicts, beyond, shallow=True) == 27
    # a bump on the way down, or a curve that barely falls, is no ramp
    bumpy = {**conflicts, 24: 0.0060}
    assert not steady_ramp(np.array([bumpy[o] for o in sorted(bumpy)]), 8)
    assert choose_offset(bumpy, beyond, shallow=True) is None
    flat = {o: 0.0005 + 0.0001 * (27 - o) * (o < 27) for o in conflicts}
    assert choose_offset(flat, beyond, shallow=True) is None



def test_a_steady_shallow_ramp_that_runs_into_the_patterns_edge_keeps_its_end_stripes_residue():
    """A spot cow seen from above fills a 50-stripe pattern to its last stripe (1536 px): its conflicts
    fall steadily to 0.0012 at the true offset, 26, and every offset past it puts over 2 % of the piece
    beyond the last stripe. The edge bounds the piece there as the ramp does on the other side, so the
    floor may keep a fifth of the fall (the animal's end stripes), not the tenth a free run must reach;
    the same curve with room past 26 is refused as before."""
    from measurement.offsets import choose_offset

    conflicts = {16: 0.0108, 17: 0.0106, 18: 0.0108, 19: 0.0108, 20: 0.0108, 21: 0.0098, 22: 0.0089,
                 23: 0.0072, 24: 0.0054, 25: 0.0023, 26: 0.0012, 27: 0.0007, 28: 0.0, 29: 0.0, 30: 0.0005}
    past = {o: (0.0, max(0.0, 0.0235 * (o - 26))) for o in conflicts}
    assert choose_offset(conflicts, past, shallow=True, from_above=True) == 26
    assert choose_offset(conflicts, past, from_above=True) is None  # not without the shallow reading
    room = {o: (0.0, 0.0) for o in conflicts}
    assert choose_offset({**conflicts, 27: 0.0012, 28: 0.0012, 29: 0.0012, 30: 0.0012}, room, shallow=True,
                         from_above=True) is None

def test_a_small_piece_that_conflicts_wherever_it_goes_is_not_placed():
    """A V whose bottom still puts a tenth of the piece on lit cells is a piece whose relative indices
    are wrong (a mislinked stub at the pattern's edge): ``max_floor`` refuses it."""
    from measurement.offsets import sharp_minimum

    no_edge = {o: (0.0, 0.0) for o in range(25, 36)}
    v_with_residue = {27: 0.47, 28: 0.16, 29: 0.09, 30: 0.09, 31: 0.28, 32: 0.41}
    assert sharp_minimum(v_with_residue, no_edge) == 29
    assert sharp_minimum(v_with_residue, no_edge, max_floor=0.05) is None
    assert sharp_minimum({27: 0.47, 28: 0.16, 29: 0.01, 30: 0.3}, no_edge, max_floor=0.05) == 29


def test_the_ramp_reading_never_stops_where_the_animal_would_sink_through_the_floor():
    """A residue on the right offset (20) makes the ramp reading take the next one (21); there the piece
    sits one depth step deeper and its feet go through the floor, which nothing physical allows."""
    from measurement.offsets import choose_offset

    conflicts = {**{o: 0.04 * (20 - o) + 0.03 for o in range(8, 20)}, 20: 0.03, 21: 0.0, 22: 0.0, 23: 0.03, 24: 0.1}
    beyond = {o: (0.0, 0.0) for o in conflicts}
    assert choose_offset(conflicts, beyond) == 21
    assert choose_offset(conflicts, beyond, behind=lambda o: 0.0 if o <= 20 else 0.004 * (o - 20)) == 20


def test_a_plate_pushed_deeper_sinks_behind_the_wall():
    """The exact plate-and-wall scene: at its true offset and nearer the camera nothing of the plate lies
    behind the wall; five stripes deeper (the wall is 300 mm behind it) all of it does."""
    from measurement.offsets import behind_background

    planes, rays, cl, idx, true = _scene(-60.0, 60.0)
    k_min = int(true[idx].min())
    r = np.zeros(len(rays), np.int64)
    r[idx] = true[idx] - k_min
    wall = np.array([[0.0, 0.0, 1.0, WALL_Z]])
    share = {o: behind_background(rays, planes, r, idx, N, wall, o) for o in range(k_min - 6, k_min + 8)}
    assert all(share[o] == 0.0 for o in share if o <= k_min)
    assert share[k_min + 5] == 1.0


def test_only_the_seen_part_of_a_nearer_parallel_plane_bounds_the_piece():
    """A platform's front (a plane parallel to the wall, 150 mm nearer than the plate, seen only in a band
    below it) does not push the plate forward: the plate lies behind that plane but not behind the part of
    it that was seen. The wall, seen on both sides of the plate, still bounds it."""
    from measurement.background import Footprints
    from measurement.offsets import behind_background

    planes, rays, cl, idx, true = _scene(-60.0, 60.0)
    k_min = int(true[idx].min())
    r = np.zeros(len(rays), np.int64)
    r[idx] = true[idx] - k_min
    front_z = PLATE_Z - 150.0  # the platform's front, nearer than the plate (whose true depth is 1100)
    band = []  # its stripes, seen in a band of 60 mm below the plate only
    for k in range(N):
        band.append(_on_stripe(planes, k, front_z, np.arange(HALF_H + 40.0, HALF_H + 100.0, 2.0)))
    band = np.vstack(band)
    rays_all = np.vstack([rays, band / band[:, 2:3]])
    labels = np.concatenate([cl, np.repeat(np.arange(N), len(band) // N)])
    r_all = np.concatenate([r, np.zeros(len(band), np.int64)])
    bg = np.array([[0.0, 0.0, 1.0, WALL_Z], [0.0, 0.0, 1.0, front_z]])
    fp = Footprints(rays_all, planes, labels, bg)
    cover = fp.covers(rays_all[idx])
    assert cover[:, 0].all() and not cover[:, 1].any()  # the wall seen around the plate, the front below it
    unbounded = behind_background(rays_all, planes, r_all, idx, N, bg, k_min)
    bounded = behind_background(rays_all, planes, r_all, idx, N, bg, k_min, footprint=fp)
    assert unbounded == 1.0 and bounded == 0.0
    assert behind_background(rays_all, planes, r_all, idx, N, bg, k_min + 5, footprint=fp) == 1.0  # the wall


def test_a_bump_on_the_flat_side_does_not_hold_the_reading_away_from_the_ramp():
    """A noisy sensor's curve (a side view with 3x the read noise): the ramp ends at 27, and a bump at 29
    over the tolerance lies between it and the minimum at 32. The first tolerated offset coming up the
    ramp is the answer (reading down from the minimum stopped at 30, three stripes deep)."""
    from measurement.offsets import choose_offset

    vals = [0.113, 0.114, 0.101, 0.089, 0.083, 0.083, 0.079, 0.07, 0.066, 0.064, 0.043, 0.028, 0.009, 0.005,
            0.013, 0.01, 0.01, 0.002, 0.043, 0.079, 0.108, 0.127, 0.139, 0.154, 0.168, 0.17]
    conflicts = {15 + i: v for i, v in enumerate(vals)}
    beyond = {o: (0.0, 0.0) for o in conflicts}
    assert choose_offset(conflicts, beyond, projector_right=True) == 27
    mirrored = {40 - o: v for o, v in conflicts.items()}
    assert choose_offset(mirrored, {o: (0.0, 0.0) for o in mirrored}, projector_right=False) == 13


def test_a_minimum_that_pushes_the_piece_past_the_pattern_is_not_the_reading():
    """Below offset 20 a share of the piece falls before the first stripe and its cells there are not
    counted, so the curve reads nothing at offsets 13-19 and no ramp lies below that minimum. Among the
    offsets the pattern allows the curve has its ramp (conflicts falling to 27), and that is read; one
    stripe deeper the piece sinks behind the floor (a side view without a wall at 3072 px)."""
    from measurement.offsets import choose_offset

    conflicts = {o: 0.0 for o in range(13, 20)}
    conflicts.update({20: 0.06, 21: 0.055, 22: 0.05, 23: 0.045, 24: 0.04, 25: 0.03, 26: 0.015, 27: 0.0,
                      28: 0.0, 29: 0.0, 30: 0.0})
    beyond = {o: ((20 - o) * 0.03 if o < 20 else 0.0, 0.0) for o in conflicts}
    assert choose_offset(conflicts, beyond, behind=lambda off: 0.01 if off >= 28 else 0.0) == 27



def test_lit_cells_screened_ray_by_ray_are_the_cells_of_the_exact_formula():
    from measurement.offsets import _unique_cells, elevation_bins, lit_cells
    from measurement.triangulation import intersect

    planes = default_rig((1536, 1024), 40).projector.planes_cam()
    rng = np.random.default_rng(12)
    rays = np.column_stack([rng.uniform(-0.4, 0.4, 20000), rng.uniform(-0.3, 0.3, 20000), np.ones(20000)])
    labels = rng.integers(0, 40, 20000)
    which = np.flatnonzero(rng.random(20000) < 0.7)
    exact = elevation_bins(intersect(rays[which], planes[labels[which]]), planes, 0.002)
    assert np.array_equal(lit_cells(rays, planes, labels, which), _unique_cells(labels[which], exact, 40))


def test_elevation_bins_and_conflict_cells_shared_by_both_cores_are_those_of_one():
    from measurement import _kernels, offsets
    from measurement.triangulation import intersect

    planes = default_rig((1536, 1024), 40).projector.planes_cam()
    rng = np.random.default_rng(13)
    m = 9000  # five chunks of rays: two screened on the second core
    rays = np.column_stack([rng.uniform(-0.4, 0.4, m), rng.uniform(-0.3, 0.3, m), np.ones(m)])
    bins = offsets._bins_on_planes(rays, planes, 0.002)
    for k in (0, 17, 39):
        assert np.array_equal(bins[:, k], offsets.elevation_bins(intersect(rays, planes[np.full(m, k)]), planes,
                                                                  0.002))
    rel = rng.integers(-5, 6, m)
    sub = rng.permutation(m)[:6000]
    deep = np.unique(rng.integers(0, 40, 5000) * 1_000_000 + rng.choice(bins.ravel(), 5000))
    offs = np.arange(5, 35)
    both = offsets._distinct_cells_both_cores(rel[sub], bins, sub, offs, 40, deep)
    one = _kernels.distinct_cells(rel[sub], bins, sub, offs, 40, deep, 20_000_000)
    assert len(rel[sub]) * len(offs) >= offsets._SPLIT_CELLS and both[2] and one[2]
    assert np.array_equal(both[0], one[0]) and np.array_equal(both[1], one[1]) and one[1].any()


def test_from_above_a_v_shaped_curve_is_read_at_its_bottom():
    """A top view's first piece (the shared cow's at 3072 px): a steady ramp of about 0.04 a stripe whose
    last step onto the true offset 10 is a third of that (the edge column's floor partly hidden), then
    the pattern's edge. Read up the ramp, the weak step is tolerated and the piece lands one stripe low;
    from above the curve's V is read at its bottom. Seen from the side the reading stays the ramp's."""
    from measurement.offsets import choose_offset

    conflicts = {o: 0.04 * (10 - o) for o in range(0, 9)}
    conflicts.update({9: 0.012, 10: 0.0, 11: 0.0, 12: 0.0})
    beyond = {o: (0.0, {11: 0.05, 12: 0.1}.get(o, 0.0)) for o in conflicts}
    assert choose_offset(conflicts, beyond) == 9
    assert choose_offset(conflicts, beyond, from_above=True) == 10
    # a curve with no second wall is read as before (here: refused, the piece could sit anywhere past 9)
    flat = {**conflicts, 11: 0.0, 12: 0.0, 13: 0.0}
    open_beyond = {o: (0.0, 0.0) for o in flat}
    assert choose_offset(flat, open_beyond, from_above=True) is None and choose_offset(flat, open_beyond) is None


def test_the_shadows_edge_settles_a_reading_that_stray_conflicts_left_one_stripe_high():
    """At the plate's right offset the projector's ray just past its lit-side edge lands on lit wall beside
    the shadow; one stripe higher, the next stripe out is one the plate intercepts. When stray centres leave
    the conflict curve as high at the right offset as one stripe above it (a head grown onto a body one
    stripe off), the ramp reading takes the higher one; the shadow's edge brings it back, and stops at a
    real ramp step."""
    from measurement.offsets import _edge_settled, edge_adjacency, lit_cells

    planes, rays, cl, idx, true = _scene(-60.0, 60.0)
    k_min = int(true[idx].min())
    r = np.zeros(len(rays), np.int64)
    r[idx] = true[idx] - k_min
    lit = lit_cells(rays, planes, cl, np.flatnonzero(cl >= 0))
    at = {o: edge_adjacency(rays, planes, r, idx, N, lit, o) for o in (k_min - 1, k_min, k_min + 1)}
    assert at[k_min] > 0.9 and at[k_min + 1] < 0.1
    flat = {k_min - 2: 0.2, k_min - 1: 0.1, k_min: 0.004, k_min + 1: 0.004, k_min + 2: 0.0, k_min + 3: 0.0}
    assert _edge_settled(rays, planes, r, idx, N, lit, flat, k_min + 1, True, 0.002) == k_min
    assert _edge_settled(rays, planes, r, idx, N, lit, flat, k_min, True, 0.002) == k_min  # the ramp stops it
    rising = {**flat, k_min: 0.01}  # the right offset conflicts more: no evidence to move on
    assert _edge_settled(rays, planes, r, idx, N, lit, rising, k_min + 1, True, 0.002) == k_min + 1
