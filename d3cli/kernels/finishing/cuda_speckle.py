"""CUDA driver of the speckle filter: the regions of ``cv2.filterSpeckles`` by a union-find
on the device (Playne and Hawick 2018), in four launches whatever the map, with no read
back to the host.

1. a thread per pixel: the 1/16 px fixed point of the usable pixels (valid and finite;
   -1 elsewhere: in no region, as ``cv2.filterSpeckles``'s new value), each usable pixel
   its own root, the sizes zeroed;
2. a thread per pixel: the pixel joined to its left and upper neighbour where the two
   belong to one region (``pixel_speckle.joins``): the two roots found and the larger
   linked to the smaller with an atomic min, again from the roots where another thread
   linked one first;
3. a thread per pixel: its root found and written (the forest is final), the root's size
   counted with an atomic add;
4. a thread per pixel: a usable pixel of a region of at most ``max_size`` pixels becomes a
   hole, the map masked, the holes counted into a slot of a device pool
   (:mod:`d3cli.kernels.device_counts`).

The regions are the connected components of one graph, whatever order the links are made
in, so the speckles are ``cv2.filterSpeckles``'s and the CPU's
(:func:`d3cli.kernels.finishing.speckle.drop_speckles`).  The contract:
:meth:`d3cli.kernels.backend.Backend.drop_speckles`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import cuda

from ..cuda_launch import grid_1d, grid_2d, is_device, on_device
from ..device_counts import DeviceCount, next_slot
from .pixel_speckle import build as build_pixels
from .pixel_speckle import fixed_step

_F32_INF = np.float32(np.inf)

_pixels = build_pixels(cuda.jit(device=True))
_fixed_16 = _pixels.fixed_16
_joins = _pixels.joins
_find = _pixels.find


@cuda.jit(device=True)
def _union(labels, a, b):
    """Join the trees of pixels ``a`` and ``b``: the larger root linked to the smaller with
    an atomic min; when the larger one was no longer a root (another thread linked it
    meanwhile), the min left its link or shortened it, and the union goes on from the
    value it found."""
    while True:
        a = _find(labels, a)
        b = _find(labels, b)
        if a == b:
            return
        if a < b:
            old = cuda.atomic.min(labels, b, a)
            if old == b:
                return
            b = old
        else:
            old = cuda.atomic.min(labels, a, b)
            if old == a:
                return
            a = old


@cuda.jit(cache=True)
def _speckle_init_kernel(disp, valid, fixed, labels, sizes):
    u, y = cuda.grid(2)
    h, w = disp.shape
    if y < h and u < w:
        i = y * w + u
        d = disp[y, u]
        ok = valid[y, u] and math.isfinite(d)
        fixed[y, u] = np.int32(_fixed_16(d)) if ok else np.int32(-1)
        labels[i] = i if ok else -1
        sizes[i] = 0


@cuda.jit(cache=True)
def _speckle_merge_kernel(fixed, max_diff, labels):
    u, y = cuda.grid(2)
    h, w = fixed.shape
    if y < h and u < w:
        f = fixed[y, u]
        i = y * w + u
        if u > 0 and _joins(f, fixed[y, u - 1], max_diff):
            _union(labels, i, i - 1)
        if y > 0 and _joins(f, fixed[y - 1, u], max_diff):
            _union(labels, i, i - w)


@cuda.jit(cache=True)
def _speckle_size_kernel(labels, sizes):
    i = cuda.grid(1)
    if i < labels.shape[0] and labels[i] >= 0:
        r = _find(labels, i)
        labels[i] = r  # the forest is final: another thread's find may pass through i either way
        cuda.atomic.add(sizes, r, 1)


@cuda.jit(cache=True)
def _drop_speckles_kernel(disp, valid, labels, sizes, max_size, out, counts, slot):
    u, y = cuda.grid(2)
    h, w = disp.shape
    if y < h and u < w:
        r = labels[y * w + u]  # >= 0 exactly on the usable pixels
        speck = r >= 0 and sizes[r] <= max_size
        keep = valid[y, u] and not speck
        valid[y, u] = keep
        d = disp[y, u]
        out[y, u] = d if keep else _F32_INF
        if speck:
            cuda.atomic.add(counts, slot, 1)


def drop_speckles(disparity, valid, max_size, max_diff, out):
    """The speckles made holes and the map masked on the device
    (:func:`d3cli.kernels.finishing.speckle.drop_speckles`): ``valid`` updated in place (a
    host map through an upload and a download), ``out`` (a device map; may be
    ``disparity``) masked.

    Returns
    -------
    DeviceCount
        Speckle pixels, left on the device.
    """
    d_disp = on_device(disparity)
    d_valid = on_device(valid)
    h, w = d_disp.shape
    n = h * w
    fixed = cuda.device_array((h, w), np.int32)
    labels = cuda.device_array(max(n, 1), np.int32)
    sizes = cuda.device_array(max(n, 1), np.int32)
    pool, slot = next_slot()
    blocks, threads = grid_2d(w, h)
    _speckle_init_kernel[blocks, threads](d_disp, d_valid, fixed, labels, sizes)
    _speckle_merge_kernel[blocks, threads](fixed, np.int32(fixed_step(max_diff)), labels)
    blocks_1d, threads_1d = grid_1d(n)
    _speckle_size_kernel[blocks_1d, threads_1d](labels[:n], sizes)
    _drop_speckles_kernel[blocks, threads](d_disp, d_valid, labels, sizes, np.int64(max_size), out, pool.array,
                                           slot)
    if not is_device(valid):  # a host map: updated in place as the contract says
        d_valid.copy_to_host(valid)
    return DeviceCount(pool, slot)
