"""CUDA driver of the decisive seeds (pipeline step 4: PKRN plus left-right check), and
the merge of fresh seeds into the inherited map where inheritance left holes.  The
contract: :mod:`d3cli.kernels.backend`."""

from __future__ import annotations

import numpy as np
from numba import cuda

from ..cuda_launch import as_f64, on_device, ops, per_pixel, unpack_volume
from ..pixel import UNDECIDED


_seed_at = ops.seed_at


# ----------------------------------------------------------------------------- seeds (step 4)
@cuda.jit(cache=True)
def _seeds_kernel(cost, index, n_disp, pkrn_min, epsilon, lr_tolerance, exclusion, skip, has_skip, out):
    u, v = cuda.grid(2)
    if v < index.shape[0] and u < index.shape[1]:
        if has_skip and skip[v, u] >= 0:
            out[v, u] = UNDECIDED
        else:
            out[v, u] = _seed_at(cost, index, n_disp, v, u, pkrn_min, epsilon, lr_tolerance, exclusion)


def decisive_seeds(cost, pkrn_min, epsilon, lr_tolerance, exclusion, skip=None):
    """Sparse seed map (docs/design.md, step 4); int32 (H, W), -1 undecided; ``skip`` as on the CPU."""
    flat, index, n_disp, _ = unpack_volume(cost)
    has_skip = skip is not None
    d_skip = on_device(skip) if has_skip else cuda.device_array((1, 1), np.int32)  # never read
    return per_pixel(
        _seeds_kernel, index.shape, np.int32, flat, index, n_disp, as_f64(pkrn_min), as_f64(epsilon),
        int(lr_tolerance), int(exclusion), d_skip, has_skip,
    )


# ----------------------------------------------------------------------------- merging seeds into a map
@cuda.jit(cache=True)
def _merge_kernel(primary, fallback, out):
    u, v = cuda.grid(2)
    if v < primary.shape[0] and u < primary.shape[1]:
        if primary[v, u] >= 0:
            out[v, u] = primary[v, u]
        else:
            out[v, u] = fallback[v, u]


def merge_sparse(primary, fallback):
    """``primary`` where decided (>= 0), else ``fallback``; int32 (H, W), a new device map."""
    d_primary = on_device(primary)
    return per_pixel(_merge_kernel, d_primary.shape, np.int32, d_primary, on_device(fallback))


# ----------------------------------------------------------------------------- the decided pixels
@cuda.jit(cache=True)
def _decided_kernel(disp, out):
    u, v = cuda.grid(2)
    if v < disp.shape[0] and u < disp.shape[1]:
        out[v, u] = disp[v, u] >= 0


def decided_mask(disparity):
    """``disparity >= 0``: bool (H, W), a new device map (a quarter of the int32 map's bytes
    to download)."""
    d_disp = on_device(disparity)
    return per_pixel(_decided_kernel, d_disp.shape, np.bool_, d_disp)
