"""The host-side kernels under one name: what :mod:`d3cli.method` and
:mod:`d3cli.baselines` use besides the backend object.

The pipeline computes on a backend (:mod:`d3cli.kernels.backend`, the contract; ``cpu.py``
or ``cuda.py``, picked by :func:`d3cli.kernels.get_backend`).  A few steps run on the host
for every backend, and are reached through this facade only:

- the layout of a banded cost volume (:class:`Volume`, :func:`dense_index`,
  :data:`MAX_CELLS`) and the band indexes of a finer level on the host (:func:`band_indexes`;
  the pipeline builds them through the backend, ``backend.band_indexes``, where its maps are);
- the pyramid's halving of a host image (:func:`halve_area`; the pipeline's pyramid:
  ``backend.pyramid``);
- the finishing (occlusion tests, speckles, hole filling, smoothing: ``finishing/``; the
  occlusion tests, the speckles, the filling and the smoothing also on the backend,
  ``backend.drop_occluded``, ``backend.drop_speckles``, ``backend.fill_rows``,
  ``backend.fill_inside``, ``backend.median_of_holes``, ``backend.smooth_map``),
  with the road model's rules over a map (:func:`shift_plane_f32`, :func:`restored_validity`,
  :func:`right_image_mask`; the rules themselves: :mod:`d3cli.kernels.road_model`);
- the road fit's solvers (:func:`solve_weighted`, :func:`ransac_inlier_counts`,
  :func:`irls`);
- the perspective warp and restore of a host image (:func:`pt_warp`, :func:`pt_restore`:
  the CPU drivers, for PT-SGM and for the colour image the features are extracted from).

May import: the kernels' step packages and shared modules.
"""

from __future__ import annotations

from .cost.band import band_indexes
from .finishing import (box_smooth_disparity, clamp_negative, combine_shares, copy_nearest_rows, drop_marked,
                        drop_occluded, fill_inside, fill_rows_smaller_side, fixed_point_16, fixed_point_16_finite,
                        gaussian_smooth, keep_valid, nearest_along_columns, out_of_view_mask, range_kernel_smooth,
                        range_levels, residual_and_range, restored_validity, right_image_mask, shift_plane_f32,
                        smooth_groups, smooth_map, uniqueness_occluded, unsmoothed, usable)
from .perspective.cpu import pt_restore, pt_warp
from .perspective.road_fit import irls, ransac_inlier_counts, solve_weighted
from .pyramid import halve_area
from .volume import MAX_CELLS, Volume, dense_index

__all__ = [
    "MAX_CELLS", "Volume", "band_indexes", "box_smooth_disparity", "clamp_negative", "combine_shares",
    "copy_nearest_rows", "dense_index", "drop_marked", "drop_occluded", "fill_inside", "fill_rows_smaller_side",
    "fixed_point_16", "fixed_point_16_finite", "gaussian_smooth", "halve_area", "irls", "keep_valid", "nearest_along_columns",
    "out_of_view_mask", "pt_restore", "pt_warp", "range_kernel_smooth", "range_levels", "ransac_inlier_counts", "residual_and_range",
    "restored_validity", "right_image_mask", "shift_plane_f32", "smooth_groups", "smooth_map", "solve_weighted",
    "uniqueness_occluded", "unsmoothed", "usable",
]
