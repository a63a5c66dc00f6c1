"""The tests' references: slow, obviously-correct NumPy/Python formulations the kernels
and the pipeline are held to, in one place.

- ``steps.py``: per-pixel references of the pipeline's steps (pyramid, NCC, RBF and the
  bilateral filter, seeds, diffusion, inheritance, sub-pixel, the perspective warp);
- ``finishing.py``: the NumPy/OpenCV formulation of the finishing (occlusion tests,
  speckles, hole filling, smoothing) with the byte-comparison helpers its tests share;
- ``inheritance.py``: the literal per-pixel form of inheritance (eq. 6-8), compiled with
  the kernels' ``jit`` against their namespace of per-pixel functions;
- ``band.py``: the band rule of the finer levels' cost volumes;
- ``features.py``: the cosine cost of deep features; ``sgm.py``: the semi-global paths;
- ``road.py``: the road report's confidence evidence (spikiness by a full median filter).

``from tests import reference as ref`` gives every reference by name (``ref.ref_ncc_cost_volume``).
"""

from __future__ import annotations

from .band import ref_band_indexes
from .finishing import (SHAPES, assert_same_bytes, assert_same_smoothing, numpy_exp_is_simd, random_map,
                        ref_box_smoothing_glue, ref_drop_occluded, ref_drop_speckles, ref_fill_holes,
                        ref_nearest_along_rows, ref_occluded_by_uniqueness, ref_out_of_view, ref_restored_validity,
                        ref_right_image, ref_shift_plane, ref_smooth_disparity)
from .inheritance import build_literal
from .steps import (INF, UNDECIDED, argmin_smallest, cell, kernel_weight, ref_accepts, ref_bilateral_filter,
                    ref_candidates, ref_decisive_seeds, ref_diffuse, ref_diffuse_pixel, ref_downsample, ref_inherit,
                    ref_inherit_pixel, ref_min_cost, ref_ncc_cost, ref_ncc_cost_volume, ref_patch_least_outside,
                    ref_pixel_decisive, ref_pt_restore, ref_pt_warp, ref_rbf_filter, ref_rbf_weights, ref_seed,
                    ref_subpixel, right_cell, view_cost)
