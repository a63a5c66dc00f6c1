"""CUDA drivers of the decisive steps except the diffusion: seeds, least costs,
inheritance, sub-pixel, merging and counting maps.  The contract:
:mod:`d3cli.kernels.backend`."""

from __future__ import annotations

import numba
import numpy as np
from numba import cuda

from ..cuda_launch import _dev, _f64, _grid_2d, _is_device, _per_pixel, _unpack, ops
from ..device_counts import DeviceCount, next_slot
from ..pixel import UNDECIDED


_seed_at = ops.seed_at


_band_min = ops.band_min


_inherit_patch_into = ops.inherit_patch_into


_subpixel_at = ops.subpixel_at


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
    flat, index, n_disp, _ = _unpack(cost)
    has_skip = skip is not None
    d_skip = _dev(skip) if has_skip else cuda.device_array((1, 1), np.int32)  # never read
    return _per_pixel(
        _seeds_kernel, index.shape, np.int32, flat, index, n_disp, _f64(pkrn_min), _f64(epsilon),
        int(lr_tolerance), int(exclusion), d_skip, has_skip,
    )


@cuda.jit(cache=True)
def _min_cost_kernel(cost, index, out):
    u, v = cuda.grid(2)
    if v < index.shape[0] and u < index.shape[1]:
        # pixel.band_min: the least cost the CPU's diffusion finds for itself
        out[v, u] = _band_min(cost, index, v, u) if index[v, u, 2] > index[v, u, 1] else numba.float32(1.0)


def min_cost(cost):
    """Least cost of every pixel over its band; float32 (H, W) device array (1 if empty)."""
    flat, index, _, _ = _unpack(cost)
    return _least_costs(flat, index)


def _least_costs(flat, index):
    """:func:`min_cost` of an unpacked volume (device arrays)."""
    return _per_pixel(_min_cost_kernel, index.shape, np.float32, flat, index)


# ----------------------------------------------------------------------------- inheritance (step 7)
@cuda.jit(cache=True)
def _inherit_kernel(cost, index, coarse, prc, dfm_pkrn_min, epsilon, candidates, out):
    """One thread per 2x2 patch: the patch tests once for its four fine pixels."""
    pu, pv = cuda.grid(2)
    if 2 * pv < index.shape[0] and 2 * pu < index.shape[1]:
        _inherit_patch_into(out, cost, index, coarse, pv, pu, prc, dfm_pkrn_min, epsilon, candidates)


def inherit(cost, coarse, prc, dfm_pkrn_min, epsilon, candidates=0):
    """Inter-scale decisive inheritance (paper Algorithm 2, eq. 6-8).

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.inherit`.
    """
    flat, index, _, _ = _unpack(cost)
    h, w = int(index.shape[0]), int(index.shape[1])
    out = cuda.device_array((h, w), np.int32)
    blocks, threads = _grid_2d((w + 1) // 2, (h + 1) // 2)
    _inherit_kernel[blocks, threads](flat, index, _dev(coarse), bool(prc), _f64(dfm_pkrn_min), _f64(epsilon),
                                     np.int32(candidates), out)
    return out


# ----------------------------------------------------------------------------- sub-pixel (step 8)
@cuda.jit(cache=True)
def _subpixel_kernel(cost, index, disp, equiangular, out):
    u, v = cuda.grid(2)
    if v < disp.shape[0] and u < disp.shape[1]:
        out[v, u] = _subpixel_at(cost, index, disp, v, u, equiangular)


def subpixel(cost, disp, equiangular=False):
    """Sub-pixel refinement (docs/design.md, step 8): the parabola, or with ``equiangular``
    the equiangular line fit (``pixel.subpixel_at``); float32 (H, W), inf where undecided."""
    d_disp = _dev(disp)
    flat, index, _, _ = _unpack(cost)
    return _per_pixel(_subpixel_kernel, d_disp.shape, np.float32, flat, index, d_disp, bool(equiangular))


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
    d_primary = _dev(primary)
    return _per_pixel(_merge_kernel, d_primary.shape, np.int32, d_primary, _dev(fallback))


@cuda.jit(cache=True)
def _count_kernel(disp, counts, slot):
    u, v = cuda.grid(2)
    if v < disp.shape[0] and u < disp.shape[1] and disp[v, u] >= 0:
        cuda.atomic.add(counts, slot, 1)


def count_decided(disparity):
    """Number of decided pixels (>= 0) of an integer disparity map, left on the device.

    Returns a :class:`~d3cli.kernels.device_counts.DeviceCount` (``int()`` of it, or
    :func:`counts_to_host` of many, downloads); a host map is counted on the host.
    """
    if not _is_device(disparity):
        return int(np.count_nonzero(np.asarray(disparity) >= 0))
    h, w = disparity.shape
    pool, slot = next_slot()
    blocks, threads = _grid_2d(w, h)
    _count_kernel[blocks, threads](disparity, pool.array, slot)
    return DeviceCount(pool, slot)

