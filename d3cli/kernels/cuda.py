"""The CUDA backend: every step's CUDA driver under one name (``get_backend("cuda")``).

A facade: the drivers live with their step (``cost/``, ``aggregation/``, ``sgm/``,
``decisive/``, ``subpixel/``, ``perspective/``), the functions both backends provide and their contract
in :mod:`d3cli.kernels.backend`.  The per-pixel functions are compiled with
``numba.cuda.jit(device=True)`` in :mod:`d3cli.kernels.cuda_launch` and driven by one
thread per pixel or per (pixel, disparity) cell.

Every public function accepts device arrays or host arrays (uploaded on the way in).
Results stay on the device, so the pipeline uploads the pair once (a uint8 grey image in
its own bytes: :func:`pyramid` converts and halves it on the device) and downloads the
result once; :func:`to_host` brings any array back.  The band indexes of the finer levels
are built on the device from the coarser map (:func:`band_indexes`), the full-range index
too (:func:`dense_index`).  Counts (decided pixels, diffusion sweeps, band cells) stay on
the device until :func:`counts_to_host` reads them all at once, or
:func:`outputs_to_host` packs them with the finished map and its validity into one
download.

Exactness: the drivers evaluate the same expressions in the same order as the CPU
drivers (float64 window sums, float32 filter accumulation, Jacobi diffusion over the
same frontier set), so integer maps are equal and costs agree to rounding (the GPU
may contract a multiply-add into one FMA and its ``exp`` is not libm's).  Under the
CUDA simulator (``NUMBA_ENABLE_CUDASIM=1``) the kernels run as Python and the tests
compare them with the CPU drivers.  Grid sizes: :mod:`d3cli.kernels.cuda_launch`
(``BLOCK_2D``, ``BLOCK_1D``, read at each launch).
"""

from __future__ import annotations

from numba import cuda  # noqa: F401  (the tests watch its transfers)

from .aggregation.cuda import bilateral_filter, rbf_filter, rbf_weights
from .cost.band_cuda import band_indexes
from .cost.cuda import NCC_SCRATCH_BYTES, cosine_cost_volume, dense_index, invalidate_out_of_view, ncc_cost_volume
from .cuda_launch import BLOCK_1D, BLOCK_2D, to_device, to_host
from .decisive.cuda_diffusion import diffuse, min_cost
from .decisive.cuda_inheritance import inherit
from .decisive.cuda_seeds import decided_mask, decisive_seeds, merge_sparse
from .device_counts import count_decided, counts_to_host
from .device_outputs import outputs_to_host, small_ints_to_host
from .finishing.cuda import drop_occluded, fill_rows, median_of_holes
from .finishing.cuda_fill_inside import fill_inside
from .finishing.cuda_smoothing import smooth_map
from .finishing.cuda_speckle import drop_speckles
from .perspective.cuda import count_range_ends, pt_restore, pt_validity, pt_warp
from .pyramid.cuda import pyramid
from .sgm.cuda import sgm_smooth
from .subpixel.cuda import subpixel

__all__ = [
    "BLOCK_1D",
    "BLOCK_2D",
    "NCC_SCRATCH_BYTES",
    "band_indexes",
    "bilateral_filter",
    "cosine_cost_volume",
    "count_decided",
    "count_range_ends",
    "counts_to_host",
    "decided_mask",
    "decisive_seeds",
    "dense_index",
    "diffuse",
    "drop_occluded",
    "drop_speckles",
    "fill_inside",
    "fill_rows",
    "inherit",
    "invalidate_out_of_view",
    "median_of_holes",
    "merge_sparse",
    "min_cost",
    "ncc_cost_volume",
    "outputs_to_host",
    "pt_restore",
    "pt_validity",
    "pt_warp",
    "pyramid",
    "rbf_filter",
    "rbf_weights",
    "sgm_smooth",
    "small_ints_to_host",
    "smooth_map",
    "subpixel",
    "to_device",
    "to_host",
]
