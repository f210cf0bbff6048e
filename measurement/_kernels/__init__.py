"""Compiled loops (numba) for the hot spots of a scan (detection, matching, triangulation, measurement),
each the exact loop form of a NumPy function it replaces: the same floating-point operations in the same
order (np.einsum sums three products as (x + z) + y), or a screened formula that leaves to the exact NumPy
one every case rounding could decide, so the labels come out to the bit. One exception says so in its
docstring: RANSAC's inlier count (``inlier_counts``) sums its dot products in its own order.

numba compiles a kernel on its first call (about forty seconds for all of them on a 2-core machine; a job
worker does it when it starts, ``measurement.warmup``) and caches the machine code in ``__pycache__``
beside this file, else in ``NUMBA_CACHE_DIR`` or the user's cache directory; where none is writable the
kernels are compiled in memory on each start."""

from __future__ import annotations

from .background import first_of_each, group_counts, group_medians, inlier_counts, near_any_plane
from .body import group_extent_with, group_extents, plane_distances, voxel_cells
from .cloud import cloud_points, rays_and_cells
from .detection import difference_counts, first_peaks, refine_peaks, sample_levels, shaded_centroids
from .growth import (
    depth_votes,
    flag_beside,
    flag_touching,
    gap_votes,
    gapped_rows,
    grow_by_depth,
    grow_by_slope,
    grow_piece,
    majority,
    neighbour_pairs,
    pair_groups,
    segment_steps,
    voting_pairs,
)
from .offsets import distinct_cells, merge_distinct, screened_bins, screened_bins_at
from .rays import depth_screen, intersect, neighbour_distances, rays_at
from .segments import (
    chain_runs,
    change_cuts,
    crowded,
    group_members,
    link_components,
    row_order_breaks,
    run_scatter,
    segment_row_order,
    smooth_runs,
    stable_group_order,
    walk_ends,
    walk_stops,
)

__all__ = [
    "chain_runs",
    "change_cuts",
    "cloud_points",
    "crowded",
    "depth_screen",
    "depth_votes",
    "difference_counts",
    "distinct_cells",
    "first_peaks",
    "first_of_each",
    "flag_beside",
    "flag_touching",
    "gap_votes",
    "gapped_rows",
    "group_counts",
    "group_extent_with",
    "group_extents",
    "group_medians",
    "group_members",
    "grow_by_depth",
    "grow_by_slope",
    "grow_piece",
    "inlier_counts",
    "intersect",
    "link_components",
    "majority",
    "merge_distinct",
    "near_any_plane",
    "neighbour_distances",
    "neighbour_pairs",
    "pair_groups",
    "plane_distances",
    "rays_and_cells",
    "rays_at",
    "refine_peaks",
    "row_order_breaks",
    "run_scatter",
    "sample_levels",
    "screened_bins",
    "screened_bins_at",
    "segment_row_order",
    "segment_steps",
    "shaded_centroids",
    "smooth_runs",
    "stable_group_order",
    "voting_pairs",
    "voxel_cells",
    "walk_ends",
    "walk_stops",
]
