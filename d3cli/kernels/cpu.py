"""The CPU backend: every step's CPU driver under one name (``get_backend("cpu")``).

A facade: the drivers live with their step (``cost/``, ``aggregation/``, ``sgm/``,
``decisive/``, ``perspective/``), the functions both backends provide and their contract
in :mod:`d3cli.kernels.backend`.  The per-pixel functions are compiled with
``numba.njit`` in :mod:`d3cli.kernels.cpu_common` and driven by parallel (``prange``)
loops over rows or over frontier pixels.  Every driver is deterministic and independent
of the thread count.  A few private helpers are named here too, for the tests that
check them.
"""

from __future__ import annotations

import numpy as np

from . import cache as _cache  # noqa: F401  (chooses the numba cache folder first)
from .aggregation.cpu import (  # noqa: F401
    GREY_STEPS, RBF_TASKS_PER_THREAD, _grey_scale, _rbf_passes, bilateral_filter, rbf_filter, rbf_weights)
from .aggregation.cpu_rows import _covered_bands, _rbf_interior, _rbf_normalise_row, _rbf_pixel  # noqa: F401
from .aggregation.cpu_vector import RBF_MAX_LANES  # noqa: F401
from .cost.band import band_indexes  # noqa: F401
from .cost.cpu import (  # noqa: F401
    GRID_BITS, NCC_BLOCK_ROWS, NCC_EXACT_TASKS, NCC_NARROW, _grid_bits, cosine_cost_volume, integral_image,
    invalidate_out_of_view, ncc_cost_volume)
from .cpu_common import _row_layout, ops  # noqa: F401
from .decisive.cpu_diffusion import FRONTIER_CHUNK, PREFETCH_BLOCK, SERIAL_FRONTIER, diffuse  # noqa: F401
from .decisive.cpu_inheritance import _inherit_row_prc, inherit  # noqa: F401
from .decisive.cpu_maps import SUBPIXEL_PREFETCH, count_decided, merge_sparse, min_cost, subpixel  # noqa: F401
from .decisive.cpu_seeds import SEED_PREFETCH, _right_wta_row, decisive_seeds  # noqa: F401
from .intrinsics import _store_fence, _store_nt  # noqa: F401
from .perspective.cpu import pt_restore, pt_warp  # noqa: F401
from .sgm.cpu import SGM_MIN_SEGMENT, SGM_PREFETCH_PIXELS, SGM_SEGMENTS, sgm_smooth  # noqa: F401


def to_device(array):
    """C-contiguous array for the kernels (the CPU's memory is the device's)."""
    return np.ascontiguousarray(array)


def to_host(array):
    """NumPy array of a backend array (identity on the CPU)."""
    return np.asarray(array)


def counts_to_host(values):
    """Plain ints of counts (the CPU's counts are ints already)."""
    return [int(v) for v in values]
