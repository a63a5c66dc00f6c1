"""The CPU backend: every step's CPU driver under one name (``get_backend("cpu")``).

A facade: the drivers live with their step (``pyramid/``, ``cost/``, ``aggregation/``,
``sgm/``, ``decisive/``, ``subpixel/``, ``perspective/``), the functions both backends
provide and their contract in :mod:`d3cli.kernels.backend`.  The per-pixel functions are compiled with
``numba.njit`` in :mod:`d3cli.kernels.cpu_common` and driven by parallel (``prange``)
loops over rows or over frontier pixels.  Every driver is deterministic and independent
of the thread count.  This module names exactly the functions of the contract; tests of a
driver's helpers import them from the driver's own module.
"""

from __future__ import annotations

import numpy as np

from . import compile_cache as _compile_cache  # noqa: F401  (chooses the numba cache folder first)
from .aggregation.cpu import bilateral_filter, rbf_filter, rbf_weights
from .cost.band import band_indexes
from .cost.cpu import cosine_cost_volume, invalidate_out_of_view, ncc_cost_volume
from .decisive.cpu_diffusion import diffuse, min_cost
from .decisive.cpu_inheritance import inherit
from .decisive.cpu_seeds import decided_mask, decisive_seeds, merge_sparse
from .finishing.fill import fill_inside_holes as fill_inside
from .finishing.fill import fill_rows, median_of_holes
from .finishing.occlusion import count_range_ends, drop_occluded, pt_validity
from .finishing.smooth import smooth_map
from .finishing.speckle import drop_speckles
from .perspective.cpu import pt_restore, pt_warp
from .pyramid.cpu import pyramid
from .sgm.cpu import sgm_smooth
from .subpixel.cpu import subpixel
from .volume import dense_index

__all__ = [
    "band_indexes", "bilateral_filter", "cosine_cost_volume", "count_decided", "count_range_ends", "counts_to_host",
    "decided_mask", "decisive_seeds", "dense_index", "diffuse", "drop_occluded", "drop_speckles", "fill_inside",
    "fill_rows", "inherit", "invalidate_out_of_view", "median_of_holes", "merge_sparse", "min_cost",
    "ncc_cost_volume", "outputs_to_host", "pt_restore", "pt_validity", "pt_warp", "pyramid", "rbf_filter",
    "rbf_weights", "sgm_smooth", "small_ints_to_host", "smooth_map", "subpixel", "to_device", "to_host",
]


def to_device(array):
    """C-contiguous array for the kernels (the CPU's memory is the device's)."""
    return np.ascontiguousarray(array)


def to_host(array):
    """NumPy array of a backend array (identity on the CPU)."""
    return np.asarray(array)


def counts_to_host(values):
    """Plain ints of counts (the CPU's counts are ints already)."""
    return [int(v) for v in values]


def outputs_to_host(disparity, valid, counts=()):
    """The finished map, its validity (the arrays themselves) and plain ints of counts."""
    return np.asarray(disparity), np.asarray(valid), counts_to_host(counts)


def small_ints_to_host(disparity, max_value):
    """The integer map itself (the CPU's memory is the host's)."""
    return np.asarray(disparity)


def count_decided(disparity) -> int:
    """Number of decided pixels (>= 0) of an integer disparity map."""
    return int(np.count_nonzero(np.asarray(disparity) >= 0))
