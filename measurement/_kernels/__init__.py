"""Compiled loops (numba) for the hot spots of stripe matching, each the exact loop form of a NumPy
function it replaces: the same floating-point operations in the same order (np.einsum sums three
products as (x + z) + y), or a screened formula that leaves to the exact NumPy one every case rounding
could decide, so the labels come out to the bit.

numba compiles a kernel on its first call (about twenty seconds for all of them) and caches the machine code
in ``__pycache__`` beside this file, else in ``NUMBA_CACHE_DIR`` or the user's cache directory; where
none is writable the kernels are compiled in memory on each start."""

from __future__ import annotations

from .background import group_counts, near_any_plane
from .body import group_extents, plane_distances, voxel_cells
from .cloud import cloud_points, rays_and_cells
from .detection import difference_counts, first_peaks, refine_peaks, sample_levels
from .growth import (
    depth_votes,
    flag_beside,
    flag_touching,
    gapped_rows,
    grow_by_depth,
    majority,
    neighbour_pairs,
    segment_steps,
    voting_pairs,
)
from .offsets import distinct_cells, screened_bins
from .rays import depth_screen, intersect, neighbour_distances, rays_at
from .segments import change_cuts, crowded, link_components, smooth_runs

__all__ = [
    "change_cuts",
    "crowded",
    "depth_screen",
    "depth_votes",
    "distinct_cells",
    "flag_beside",
    "flag_touching",
    "gapped_rows",
    "group_counts",
    "grow_by_depth",
    "intersect",
    "link_components",
    "majority",
    "near_any_plane",
    "neighbour_distances",
    "neighbour_pairs",
    "rays_at",
    "screened_bins",
    "segment_steps",
    "smooth_runs",
    "voting_pairs",
    "first_peaks",
    "refine_peaks",
    "group_extents",
    "rays_and_cells",
    "cloud_points",
    "voxel_cells",
    "difference_counts",
    "plane_distances",
    "sample_levels",
]
