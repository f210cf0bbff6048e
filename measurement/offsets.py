"""The absolute stripe index of an isolated piece of the animal, seen from the projector.

Within a piece, depth continuity fixes the indices relative to each other; the offset comes from the
projector's point of view: a background point lit by stripe k at projector elevation e proves nothing
stood in front of it, so a wrong offset slides the piece onto lit background cells.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from . import _kernels
from .planes import pencil_axis
from .threads import second_core
from .triangulation import intersect, kernel_layout

if TYPE_CHECKING:
    from .background import Footprints

_log = logging.getLogger(__name__)


def projector_centre(planes: np.ndarray) -> np.ndarray:
    """A point on the axis that all light planes share, at the camera's height (y = 0): the projector
    centre of a level rig. The planes alone cannot fix it along the axis; a few centimetres off only
    tilts rays by the ratio of that error to the working distance."""
    return _projector_frame(planes)[0].copy()


def projector_right(planes: np.ndarray) -> bool:
    """Whether the projector sits right of the camera (positive x), from the planes' shared axis."""
    return bool(_projector_frame(planes)[0][0] > 0)


def _projector_frame(planes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The projector centre (3,) mm and the planes' shared axis (3,) (read-only), computed once per
    set of light planes (N, 4): a scan asks for them dozens of times."""
    planes = np.ascontiguousarray(planes)
    return _frame_of(planes.tobytes(), planes.dtype.str, planes.shape)


@lru_cache(maxsize=8)
def _frame_of(data: bytes, dtype: str, shape: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    p0, a = pencil_axis(np.frombuffer(data, dtype).reshape(shape))
    centre = p0 - a * (p0[1] / a[1]) if abs(a[1]) > 1e-6 else p0
    centre.flags.writeable = False
    a.flags.writeable = False
    return centre, a


def elevation_bins(points: np.ndarray, planes: np.ndarray, bins: float) -> np.ndarray:
    """The projector elevation of each point (K, 3) mm, in bins of ``bins``: floor(elevation / bins) (K,)
    int64. The elevation is the tan of the angle between the projector's ray to the point and the plane
    perpendicular to the planes' shared axis (the projector's row coordinate). ``points`` is used as
    scratch (overwritten)."""
    centre, a = _projector_frame(planes)
    points -= centre
    e = _elevation(points, a)
    np.divide(e, bins, out=e)
    return np.floor(e, out=e).astype(np.int64)


class BinTable:
    """``elevation_bins`` of centres on every light plane, each centre's computed when first asked for and
    kept: a scan weighs the first piece's centres again with the whole animal."""

    def __init__(self, rays: np.ndarray, planes: np.ndarray, bins: float = 0.002) -> None:
        self.rays, self.planes, self.bins = rays, planes, bins
        # the rows computed so far, in that order, are the first _rows of _data: room for every centre,
        # its pages faulted in only as rows are written (growing one array by concatenation copied it
        # all on each call)
        self._data = np.empty((len(rays), len(planes)), np.int64)
        self._rows = 0
        self._slot = np.full(len(rays), -1, np.int64)  # each centre's row in _data, -1 before

    def rows(self, idx: np.ndarray) -> np.ndarray:
        """(K, N) bins of the distinct centres ``idx`` (K,) on every plane."""
        data, slot = self.table(idx)
        return data.take(slot, axis=0)

    def table(self, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The rows computed so far (R, N) and the row (K,) of each of the distinct centres ``idx`` (K,)
        among them: a compact table (one (M, N) array indexed by centre would fault in most of its pages)."""
        new = idx[self._slot[idx] < 0]
        if len(new):
            r = self._rows
            self._slot[new] = np.arange(r, r + len(new))
            _bins_on_planes(self.rays.take(new, axis=0), self.planes, self.bins, out=self._data[r:r + len(new)])
            self._rows = r + len(new)
        return self._data[:self._rows], self._slot[idx]


def _bins_on_planes(rays: np.ndarray, planes: np.ndarray, bins: float, chunk: int = 2048,
                    out: np.ndarray | None = None) -> np.ndarray:
    """``elevation_bins`` (S, N) of the point of each ray (S, 3) on every light plane (N, 4), as
    ``elevation_bins(intersect(...))`` gives them ray by ray; ``chunk`` rays at a time, in cache.

    Without (S, N, 3) points: with s the ray's scale on the plane, the point's offset from the projector
    centre c is s r - c, the elevation's numerator s (r . a) - c . a and its squared distance from the
    axis |s r - c|^2 minus that squared (``_kernels.screened_bins``). This rounds differently; where that
    could matter (within 1e-5 of a bin's edge, a ray nearly parallel to its plane, a point near the axis)
    the exact formula decides, in the order and batches it always did. On well-conditioned points (ray .
    normal at least 1e-3 of the sum of its terms' sizes, the distance from the axis at least 1e-2 of
    |s r - c| + |c|) the two differ by under 1e-6 (64 ulp times condition numbers up to 1e3 and 300); on
    1.9 M points of the bench views by at most 1.1e-16.
    ``out`` : a C-contiguous (S, N) int64 array to write the bins into (returned), instead of a new one."""
    out = np.empty((len(rays), len(planes)), np.int64) if out is None else out
    centre, a = _projector_frame(planes)
    starts = range(0, len(rays), chunk)

    def screen(at: int) -> np.ndarray:
        return _kernels.screened_bins(np.ascontiguousarray(rays[at:at + chunk]), planes, centre, a, bins, 1e-5,
                                      out[at:at + chunk])

    # the chunks are screened on both cores when there are several (each writes its own rows of out), the
    # later half on the second; the unsure bins are then formed exactly, chunk by chunk as before
    split = len(starts) // 2 if len(starts) > 3 else len(starts)
    later = second_core().submit(lambda: [screen(at) for at in starts[split:]]) if split < len(starts) else None
    unsure_all = [screen(at) for at in starts[:split]] + (later.result() if later is not None else [])
    for at, unsure in zip(starts, unsure_all, strict=True):
        k, i = np.divmod(unsure, min(chunk, len(rays) - at))
        if len(i):
            r = np.ascontiguousarray(rays[at:at + chunk])
            out[at + i, k] = _exact_bins(r.take(i, axis=0), planes.take(k, axis=0), planes, bins)
    return out


def _exact_bins(rays: np.ndarray, on: np.ndarray, planes: np.ndarray, bins: float) -> np.ndarray:
    """``elevation_bins`` (K,) of rays (K, 3) on their planes ``on`` (K, 4), each as in a larger call (a
    single ray would take another BLAS path in ``_elevation``)."""
    if len(rays) == 1:
        return _exact_bins(np.repeat(rays, 2, axis=0), np.repeat(on, 2, axis=0), planes, bins)[:1]
    return elevation_bins(intersect(rays, on, out=rays), planes, bins)


def _elevation(q: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Elevation (K,) of points q (K, 3) relative to the projector centre about the unit axis a (3,)."""
    along = q @ a
    # the distance from the axis summed column by column: the rounding of np.linalg.norm(axis=1) over
    # three columns, without its (K, 3) temporaries
    d = np.empty_like(along)
    across2 = np.empty_like(along)
    for j in range(3):
        np.multiply(along, a[j], out=d)
        np.subtract(q[:, j], d, out=d)
        if j == 0:
            np.multiply(d, d, out=across2)
        else:
            across2 += np.multiply(d, d, out=d)
    np.sqrt(across2, out=across2)
    return np.divide(along, np.maximum(across2, 1e-9, out=across2), out=along)


def in_sorted(x: np.ndarray, sorted_values: np.ndarray) -> np.ndarray:
    """``np.isin(x, sorted_values)`` for a sorted array, without sorting it again."""
    if len(sorted_values) == 0:
        return np.zeros(len(x), bool)
    pos = np.minimum(np.searchsorted(sorted_values, x), len(sorted_values) - 1)
    return sorted_values[pos] == x


def union_sorted(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.union1d(a, b)`` for sorted arrays of distinct values: one compiled merge (the NumPy form, a stable
    sort of a and the values of b not in a, is the reference in tests/test_kernels.py)."""
    if a.dtype == b.dtype and a.dtype.kind in "iu":
        return _kernels.merge_distinct(a, b)
    return np.sort(np.concatenate([a, b[~in_sorted(b, a)]]), kind="stable")


def _thinned(idx: np.ndarray, most: int = 20000) -> np.ndarray:
    """``idx`` (K,), every j-th entry when there are more than ``most`` (a piece's shape survives it)."""
    return idx if len(idx) <= most else idx[:: len(idx) // most + 1]


def occlusion_offset(rays, planes, cl, r, idx, n, projector_right: bool = True, bins: float = 0.002,
                      residue: float = 0.5, pattern_edge: float = 0.02, beside_placed: bool = False,
                      lit: np.ndarray | None = None, background: np.ndarray | None = None,
                      table: BinTable | None = None, shallow: bool = False, report: dict | None = None,
                      footprint: Footprints | None = None, from_above: bool = False) -> int | None:
    """Absolute offset of a cluster with relative labels ``r[idx]``, from the projector's point of view.

    A background point lit by stripe k at projector elevation e proves that nothing stood in front of it
    on that projector ray: the object must not occupy cell (k, e). Cells well inside a lit run (lit two
    bins either side too) count, so the shadow's own edges do not. Offsets that slide the object onto lit
    background conflict; those sliding it toward background the camera cannot see (behind the object)
    do not, so the right offset is the conflict-free one nearest the conflicts: the lowest with the
    projector right of the camera, the highest with it on the left. "Conflict-free" is measured against
    the ramp of the curve: stray centres at the outline leave a residue on the right offset, and a
    residue under ``residue`` of one ramp step is tolerated. The result never puts more than
    ``pattern_edge`` of the piece beyond the first or last stripe.

    With ``beside_placed`` (``cl`` also holds the cells of pieces already placed, which no other piece
    may share) a curve that rises on both sides of its minimum is read at the minimum. Not for the
    first piece seen from the side: there the conflict residue of stray centres at the outline often
    sits on the right offset and makes the next one up the minimum. Seen from above (``from_above``)
    the first piece's V is read at its bottom too: there the ramp's last step onto the true offset is
    often under half a step (the edge column's floor is partly hidden), while the other wall of the V
    is the pattern's edge or the floor (``choose_offset``).

    With the ``background`` planes (P, 4) the other physical bound joins in for the first piece: no part
    of the animal lies behind the floor or the wall (``behind_background``). Sliding a piece one stripe
    away from its conflicts moves it deeper, and its feet then sink through the floor; the ramp reading
    never stops at such an offset. ``footprint`` : where each plane was seen (``background.Footprints``).
    """
    curve = conflict_curve(rays, planes, cl, r, idx, n, bins, lit, table)
    if curve is None:
        return None
    # only for the first piece: a later one (a far leg, a tail) carries more stray centres with a wrong
    # relative index, which can sink through the floor at the right offset (the sparse-fan render)
    behind = None
    if background is not None and not beside_placed:
        def behind(off: int) -> float:
            return behind_background(rays, planes, r, idx, n, background, off, footprint=footprint)
    reading: dict = {} if report is None else report
    off = choose_offset(*curve, projector_right, pattern_edge, beside_placed, residue, behind=behind,
                        shallow=shallow, report=reading, from_above=from_above)
    if off is not None and reading.get("ramp") and not beside_placed and lit is not None:
        off = _edge_settled(rays, planes, r, idx, n, lit, curve[0], off, projector_right, bins)
    return off


EDGE_DROP = 0.15  # a step toward the conflicts gains this share of edge bins beside lit background, or is not taken


def edge_adjacency(rays, planes, r, idx, n: int, lit: np.ndarray, off: int, projector_right: bool = True,
                   bins: float = 0.002, reach: int = 2) -> float:
    """The share of a piece's projector elevation bins (relative labels ``r[idx]`` at offset ``off``) whose
    edge stripe on the lit side (the lowest with the projector right of the camera) has its next stripe out
    lit on the background (``lit``, sorted cell keys, ``lit_cells``) within ``reach`` bins; NaN if none can.

    The projector's ray just past the animal's outline misses it and lands on the floor or wall beside the
    shadow, where the camera sees it lit: at the right offset most edge bins have it. One stripe away from
    the conflicts the piece's edge stripe is really that ray's neighbour inside the shadow, and the next one
    out is one the animal intercepts: the share falls (on the five seeds' and the shared meshes' views
    0.50-0.96 at the right offset, mostly 0.16-0.70 one further; one view keeps 0.96)."""
    sub = _thinned(idx)
    k = r[sub] + off
    ok = (k >= 0) & (k < n)
    ii, k = sub[ok], k[ok]
    if not len(ii):
        return float("nan")
    e = elevation_bins(intersect(rays.take(ii, axis=0), planes.take(k, axis=0)), planes, bins)
    order = np.lexsort((k if projector_right else -k, e))
    e_s, k_s = e[order], k[order]
    first = np.r_[True, e_s[1:] != e_s[:-1]]  # per bin, its edge stripe
    nb = k_s[first] - 1 if projector_right else k_s[first] + 1
    ee = e_s[first]
    valid = (nb >= 0) & (nb < n)
    if not valid.any():
        return float("nan")
    ee, nb = ee[valid], nb[valid]
    hit = np.zeros(len(ee), bool)
    for d in range(-reach, reach + 1):
        hit |= in_sorted(nb * 1_000_000 + ee + d, lit)
    return float(hit.mean())


def _edge_settled(rays, planes, r, idx, n: int, lit: np.ndarray, conflicts: dict[int, float], off: int,
                  projector_right: bool, bins: float) -> int:
    """The ramp reading ``off`` moved toward the conflicts while a step there adds no conflicts and gains
    ``EDGE_DROP`` of the edge bins beside lit background (``edge_adjacency``): the reading's residue
    tolerance is blind where stray centres conflict as much at the right offset as one stripe away from it
    (large cow-like shapes seen from the side, overflowing the pattern, a head grown onto the body a stripe
    off: 0.9 and 0.9 per mille, 7.6 and 7.9), but the shadow's edge is not. It stops at the first real ramp
    step."""
    toward = -1 if projector_right else 1
    a = None  # (read only where a step is free: on most views the first one toward the conflicts is not)
    while off + toward in conflicts and conflicts[off + toward] <= conflicts[off]:
        if a is None:
            a = edge_adjacency(rays, planes, r, idx, n, lit, off, projector_right, bins)
        b = edge_adjacency(rays, planes, r, idx, n, lit, off + toward, projector_right, bins)
        if not b - a >= EDGE_DROP:  # (NaN: no evidence, no move)
            break
        off, a = off + toward, b
    return off


def behind_background(rays, planes, r, idx, n, background: np.ndarray, off: int, margin_mm: float = 8.0,
                      footprint: Footprints | None = None) -> float:
    """The share of the piece (relative labels ``r[idx]``) that offset ``off`` puts more than
    ``margin_mm`` behind a background plane (P, 4), on the side away from the camera; with ``footprint``
    (``background.Footprints``) only behind the part of a plane that was seen."""
    sub = _thinned(idx)
    k = r[sub] + off
    inside = (k >= 0) & (k < n)
    if not inside.any():
        return 0.0
    p = intersect(rays.take(sub[inside], axis=0), planes.take(k[inside], axis=0))
    camera_side = np.where(background[:, 3] <= 0, 1.0, -1.0)  # the sign of n.x - d at the camera (x = 0)
    depth = (p @ background[:, :3].T - background[:, 3]) * camera_side  # (K, P), > 0 on the camera's side
    behind = depth < -margin_mm
    if footprint is not None and behind.any():
        behind &= footprint.covers(rays.take(sub[inside], axis=0))
    return float(behind.any(axis=1).mean())


def lit_cells(rays, planes, labels, which, bins: float = 0.002) -> np.ndarray:
    """Sorted keys (stripe * 1e6 + elevation bin) of the projector cells lit at the centres ``which``
    (indices) with stripe ``labels[which]``."""
    if len(which) == 0:
        return np.zeros(0, np.int64)
    k = labels[which]
    ray = rays.take(which, axis=0)
    if kernel_layout(ray, planes):  # screened ray by ray, the exact formula where it could differ
        centre, a = _projector_frame(planes)
        e = np.empty(len(which), np.int64)
        unsure = _kernels.screened_bins_at(ray, planes, k, centre, a, bins, 1e-5, e)
        if len(unsure):
            e[unsure] = _exact_bins(ray.take(unsure, axis=0), planes.take(k[unsure], axis=0), planes, bins)
    else:
        e = elevation_bins(intersect(ray, planes.take(k, axis=0), out=ray), planes, bins)
    return _unique_cells(k, e, len(planes))


def _unique_cells(stripe: np.ndarray, e: np.ndarray, n: int) -> np.ndarray:
    """``np.unique(stripe * 1_000_000 + e)`` for stripes (K,) and elevation bins (K,): by a bitmap of the
    (stripe, bin) cells when the stripes lie in [0, n) and the bins within +-4e5 (keys ordered alike)."""
    lo, hi = (int(e.min()), int(e.max())) if len(e) else (0, 0)
    bins = hi - lo + 1
    if not (lo > -400_000 and hi < 400_000 and n * bins <= 20_000_000 and len(e)
            and stripe.min() >= 0 and stripe.max() < n):
        return np.unique(stripe * 1_000_000 + e)
    mark = np.zeros(n * bins, bool)
    mark[stripe * bins + (e - lo)] = True
    k, b = np.divmod(np.flatnonzero(mark), bins)
    return k * 1_000_000 + (b + lo)


def conflict_curve(rays, planes, cl, r, idx, n, bins: float = 0.002, lit: np.ndarray | None = None,
                   table: BinTable | None = None) -> tuple[dict[int, float], dict[int, tuple[float, float]]] | None:
    """Per offset: the share of the piece's cells that land on deep-lit cells, and the shares of the
    piece pushed before the first and past the last stripe; None without enough lit background.
    ``lit`` : the cells lit at every labelled centre of ``cl`` (``lit_cells``), if already known;
    ``table`` : a ``BinTable`` of these rays and planes at these ``bins``, to share with other curves."""
    bg = np.nonzero(cl >= 0)[0]
    if len(bg) < 100:
        return None
    if lit is None:
        lit = lit_cells(rays, planes, cl, bg, bins)
    # cells lit two bins either side too: in sorted distinct keys, five in a row span four
    deep = lit[2:-2][lit[4:] - lit[:-4] == 4]
    rr = r[idx]
    sub = _thinned(idx)
    offs = np.arange(-int(rr.max()), n - int(rr.min()))
    # share of the piece that an offset pushes before the first (< 0) or past the last (>= n) stripe
    rs = np.sort(r[sub])
    lo, hi = np.searchsorted(rs, -offs), len(rs) - np.searchsorted(rs, n - offs)
    before, past = lo / len(rs), hi / len(rs)
    beyond = {int(o): (float(b), float(a)) for o, b, a in zip(offs, before, past, strict=True)}
    weighed = (len(rs) - lo - hi) / len(rs) >= 0.8
    rows = np.flatnonzero(weighed)
    table = table if table is not None else BinTable(rays, planes, bins)
    cells, hits, counted = _distinct_cells_both_cores(r[sub], *table.table(sub), offs[rows], n, deep)
    if not counted:  # bins too widely spread for a bitmap
        cells, hits = _offset_cells(r[sub], table.rows(sub), offs[rows], n, deep)
    conflicts = {int(offs[j]): float(hits[w] / cells[w]) for w, j in enumerate(rows)}
    if not conflicts:
        return None
    if _log.isEnabledFor(logging.DEBUG):
        _log.debug("occlusion conflicts %s", sorted(conflicts.items()))
    return conflicts, beyond


EDGE_FLOOR = 0.2  # a steady shallow ramp's floor, as a share of its fall, where the pattern's edge bounds it
_SPLIT_CELLS = 100_000  # centre-offset pairs above which a conflict curve's offsets are shared by both cores


def _distinct_cells_both_cores(rel: np.ndarray, rows: np.ndarray, sub: np.ndarray, offsets: np.ndarray, n: int,
                               deep: np.ndarray, most: int = 20_000_000) -> tuple[np.ndarray, np.ndarray, bool]:
    """``_kernels.distinct_cells`` (each offset's cells are counted on their own), the later half of the
    offsets on the second core when the curve is large; counted only if both halves were."""
    if len(rel) * len(offsets) < _SPLIT_CELLS or len(offsets) < 4:
        return _kernels.distinct_cells(rel, rows, sub, offsets, n, deep, most)
    half = len(offsets) // 2
    later = second_core().submit(_kernels.distinct_cells, rel, rows, sub, offsets[half:], n, deep, most)
    cells, hits, counted = _kernels.distinct_cells(rel, rows, sub, offsets[:half], n, deep, most)
    cells2, hits2, counted2 = later.result()
    return np.concatenate([cells, cells2]), np.concatenate([hits, hits2]), counted and counted2


def _offset_cells(rel: np.ndarray, rows: np.ndarray, offsets: np.ndarray, n: int, deep: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Per offset (W,): the distinct cells of centres with relative stripes ``rel`` (S,) and elevation
    bins ``rows`` (S, N) on every plane, and how many are in the sorted keys ``deep``."""
    k = rel[None, :] + offsets[:, None]  # (W, S) the stripe of each centre at each offset
    inside = (k >= 0) & (k < n)
    flat = np.flatnonzero(inside)
    at = np.repeat(np.arange(len(offsets)), np.count_nonzero(inside, axis=1))  # flat // S without a division
    k = k.ravel().take(flat)
    # the bin of centre i = flat - at S on plane k sits at i N + k of rows
    pos = flat - at * len(rel)
    pos *= rows.shape[1]
    pos += k
    return _distinct_cells(at, k, rows.ravel().take(pos), len(offsets), n, deep)


def _distinct_cells(group: np.ndarray, stripe: np.ndarray, e: np.ndarray, groups: int, n: int,
                    deep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per group (groups,): the number of distinct cells (stripe * 1e6 + elevation bin) among the
    entries (K,) of that group, and how many of them are in the sorted keys ``deep``."""
    lo, hi = (int(e.min()), int(e.max())) if len(e) else (0, 0)
    bins = hi - lo + 1
    if lo > -400_000 and hi < 400_000 and groups * n * bins <= 20_000_000:  # a bitmap, no sort
        mark = np.zeros((groups, n * bins), bool)
        cell = stripe * bins  # the flat position in the bitmap: cheaper than a 2-D index
        cell += e
        cell += group * (n * bins) - lo
        mark.ravel()[cell] = True
        dk = (deep + 500_000) // 1_000_000  # keys of bins within +-5e5 split back into stripe and bin
        de = deep - dk * 1_000_000 - lo
        use = (dk >= 0) & (dk < n) & (de >= 0) & (de < bins)
        in_deep = np.zeros(n * bins, bool)
        in_deep[dk[use] * bins + de[use]] = True
        return np.count_nonzero(mark, axis=1), np.count_nonzero(mark & in_deep, axis=1)
    both = np.unique(np.column_stack([group, stripe * 1_000_000 + e]), axis=0)
    hits = np.bincount(both[:, 0], weights=in_sorted(both[:, 1], deep), minlength=groups)
    return np.bincount(both[:, 0], minlength=groups), hits.astype(np.int64)


def choose_offset(conflicts: dict[int, float], beyond: dict[int, tuple[float, float]], projector_right: bool = True,
                  pattern_edge: float = 0.02, beside_placed: bool = False, residue: float = 0.5,
                  ramp_steps: int = 12, behind: Callable[[int], float] | None = None,
                  max_behind: float = 0.001, shallow: bool = False, report: dict | None = None,
                  from_above: bool = False) -> int | None:
    """The offset read off a conflict curve (see ``occlusion_offset``); ``behind`` : offset -> the share
    of the piece it puts behind the floor or wall, of which at most ``max_behind`` is tolerated (on the
    simulator's renders the right offset puts none there, one stripe deeper 0.2-2.4 %).

    With ``shallow``, a ramp too shallow to read the usual way (steps under 0.005 of the piece's cells: a
    blob seen from above or a sitting rabbit hides most of its shadow's lit edge) still places the piece
    when it is steady (``steady_ramp``): then at about its minimum (a tenth of a step of residue
    tolerated, not half), since a residue of half such a step is already the whole next column's
    conflicts. Where the next offset past that minimum would put more than ``pattern_edge`` of the piece
    beyond the pattern, the edge bounds the piece as the ramp does, and the floor may keep ``EDGE_FLOOR``
    of the ramp's fall (the residue of the animal's end stripes; a spot cow seen from above, filling a
    50-stripe pattern to its last stripe at 1536 px: 0.0012 after a fall of 0.0086, unplaced before).
    ``report`` (if given) gets "shallow": whether it was.

    With ``beside_placed`` or ``from_above`` a V-shaped curve (``sharp_minimum``) is read at its bottom. From
    above, on 326 rendered views (2026-11-22): 10 top views placed right that were one stripe off
    (among them the shared cow's and fox's and five of the rig variants' at 3072 px), 2 the other way (a
    camera 200 mm nearer, and a noisy 1536 px render of the turned animal); no side view can change."""
    if beside_placed or from_above:
        sharp = sharp_minimum(conflicts, beyond)
        if sharp is not None:
            return sharp
    offs = sorted(conflicts)
    vals = np.array([conflicts[o] for o in offs])
    if not projector_right:  # mirror, so the conflicts always rise toward lower offsets
        offs, vals = offs[::-1], vals[::-1]
    if len(vals) < 5:
        return None
    # the ramp: each stripe the piece slides onto the lit side adds about one column of conflicting cells.
    # Its step (the mean of the three steepest of the twelve steps below the minimum) sets the scale: a
    # residue under half a step is stray centres at the outline, not the piece's edge column
    i = int(np.argmin(vals))
    step = _ramp_step(vals, i, ramp_steps)
    possible = np.ones(len(vals), bool)
    if step <= 0.005:
        # the minimum can sit where a share of the piece would lie past the pattern (those cells are not
        # counted): read the curve among the offsets the pattern allows (a side view without a wall at
        # 3072 px, whose body's minimum lay where 15 % of it fell before the first stripe)
        possible = np.array([max(beyond[o]) <= pattern_edge for o in offs])
        if possible.any():
            i = int(np.argmin(np.where(possible, vals, np.inf)))
            step = _ramp_step(vals, i, ramp_steps)
    if step <= 0.005:  # no ramp: nothing bounds the piece on the lit side, unless a steady shallow one does
        # a ramp that runs into the pattern's edge is bounded there on both sides: its floor may keep the
        # residue of the animal's end stripes (EDGE_FLOOR of the fall, not a tenth)
        at_pattern_edge = i + 1 < len(vals) and not possible[i + 1]
        if not (shallow and possible[i] and steady_ramp(vals, i, floor=EDGE_FLOOR if at_pattern_edge else 0.1)):
            return None
        residue = 0.1
        if report is not None:
            report["shallow"] = True
    floor = float(vals[i])
    if report is not None:
        report["ramp"] = True  # (read off the ramp, not at a V's bottom)
    # the first tolerated offset coming up the ramp: with a noisy sensor the flat side is bumpy, and a
    # bump over the tolerance between the ramp's foot and the minimum must not hold the reading there
    tolerated = (vals - floor < residue * step) & possible
    i = int(np.argmax(tolerated))
    if i == 0:
        return None
    best = offs[i]
    # the same run followed the other way: when it ends only because the piece would leave the pattern,
    # both ends are walls and the piece could sit anywhere between them (seen on an animal lit to the
    # pattern's edge from above): two or more stripes of play is refused rather than guessed. The floor
    # and wall bound the run too: where the piece would sink behind them, the run ends short of the edge
    side = 1 if projector_right else 0
    j = i
    flat = vals - floor < 0.25 * residue * step
    while (j + 1 < len(vals) and flat[j + 1] and beyond[offs[j + 1]][side] <= pattern_edge
           and (behind is None or behind(offs[j + 1]) <= max_behind)):
        j += 1
    nxt = offs[j] + (1 if projector_right else -1)
    at_edge = j + 1 >= len(vals) or (flat[j + 1] and beyond[nxt][side] > pattern_edge)
    if at_edge and j - i >= 2:
        return None
    # the pattern has n stripes and no more: an offset that puts a real share of the piece past the last
    # (or before the first) stripe is impossible, however conflict-free it looks (an animal that fills the
    # pattern to its edge is common from above)
    while beyond[best][1] > pattern_edge and best - 1 in conflicts:
        best -= 1
    while beyond[best][0] > pattern_edge and best + 1 in conflicts:
        best += 1
    # nothing of the animal lies behind the floor or wall: step back toward the conflicts until it does not
    toward = -1 if projector_right else 1
    while behind is not None and best + toward in conflicts and behind(best) > max_behind:
        best += toward
    return int(best)


def steady_ramp(vals: np.ndarray, i: int, run: int = 5, rise: float = 0.004, floor: float = 0.1) -> bool:
    """Whether the curve ``vals`` (conflicts rising toward lower indices) comes down to its minimum at
    ``i`` without a bump over the last ``run`` steps, falling by at least ``rise`` on them to a floor
    under ``floor`` of that fall."""
    if i < run:
        return False
    part = vals[i - run:i + 1]
    fall = float(part[0] - part[-1])
    return bool((np.diff(part) <= 0).all() and fall >= rise and part[-1] <= floor * fall)


def _ramp_step(vals: np.ndarray, i: int, ramp_steps: int) -> float:
    """The mean of the three steepest of the ``ramp_steps`` steps of the curve ``vals`` below its
    minimum at ``i`` (0 without any)."""
    steps = np.sort(-np.diff(vals[max(0, i - ramp_steps):i + 1]))[-3:]
    return float(steps.mean()) if len(steps) else 0.0


def sharp_minimum(conflicts: dict[int, float], beyond: dict[int, tuple[float, float]],
                  max_floor: float = 1.0) -> int | None:
    """The offset at the bottom of a V: conflicts (plus the share pushed past the pattern) rise on both
    sides within two stripes. A piece whose every neighbouring cell is lit or taken by an already placed
    piece (a tail beside the body, a leg in front of the wall) shows this shape, and its bottom is the
    answer; a one-sided curve (a flat conflict-free run toward cells the camera cannot see) is left to
    ``choose_offset``'s ramp reading. A bottom above ``max_floor`` is no answer: the piece conflicts
    wherever it goes, so its relative indices do not describe one surface."""

    def cost(o: int) -> float:
        return conflicts.get(o, 1.0) + sum(beyond.get(o, (1.0, 0.0)))

    best = min(conflicts, key=cost)
    floor = cost(best)
    if floor > max_floor:
        return None
    need = max(2 * floor, floor + 0.02)
    rises_low = max(cost(best - 1), cost(best - 2)) >= need
    rises_high = max(cost(best + 1), cost(best + 2)) >= need
    return best if rises_low and rises_high else None
