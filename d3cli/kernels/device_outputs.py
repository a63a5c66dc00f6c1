"""The results of a pair brought back from the device in one copy each.

Every device-to-host copy waits for the device.  The finished pair has three results on
the device: the float32 disparity map, its bool validity and the pools of counts
(:mod:`d3cli.kernels.device_counts`: the levels', the road model's, the occluded
pixels').  :func:`outputs_to_host` packs them into views of one device byte buffer (one
launch for the map, the validity and the first pool, one more per further pool) and
downloads the buffer once; the host arrays are views of the downloaded bytes (no host
copy).  :func:`small_ints_to_host` downloads an integer map in the narrowest integer dtype
that holds its values (the road fit's coarse map: a quarter of the int32 bytes).
"""

from __future__ import annotations

import numpy as np
from numba import cuda

from .cuda_launch import grid_1d, grid_2d, is_device, to_host
from .device_counts import DeviceCount, counts_to_host


@cuda.jit(cache=True)
def _pack_kernel(disparity, valid, pool, n_slots, out_disparity, out_valid, out_pool):
    # one thread per pixel, the first threads also copy the pool's slots (a map can have
    # fewer pixels than a pool has slots: the grid covers the larger of the two)
    i = cuda.grid(1)
    h, w = disparity.shape
    if i < h * w:
        v = i // w
        u = i - v * w
        out_disparity[v, u] = disparity[v, u]
        out_valid[v, u] = valid[v, u]
    if i < n_slots:
        out_pool[i] = pool[i]


@cuda.jit(cache=True)
def _copy_slots_kernel(pool, out_pool):
    i = cuda.grid(1)
    if i < pool.shape[0]:
        out_pool[i] = pool[i]


def _unread_pools(counts) -> list:
    """The pools of ``counts`` not read yet, each once, in order of appearance."""
    pools = []
    for value in counts:
        if isinstance(value, DeviceCount) and value.pool.values is None and value.pool not in pools:
            pools.append(value.pool)
    return pools


def _layout(n_pixels: int, pools: list) -> tuple[int, list[int], int]:
    """Byte offsets of the packed buffer: the validity's, each pool's, and the total size.

    The float32 map starts the buffer, the bool validity follows it, the int64 pools start
    on 8-byte boundaries (so the host views are aligned)."""
    valid_at = 4 * n_pixels
    at = -(-(valid_at + n_pixels) // 8) * 8
    pool_at = []
    for pool in pools:
        pool_at.append(at)
        at += 8 * int(pool.array.shape[0])
    return valid_at, pool_at, at


def outputs_to_host(disparity, valid, counts=()):
    """The finished map, its validity and counts on the host, in one device-to-host copy.

    Parameters
    ----------
    disparity : device ndarray, float32, (H, W)
    valid : device ndarray, bool, (H, W)
    counts : sequence of int or :class:`~d3cli.kernels.device_counts.DeviceCount`
        Their pools not read yet are packed with the maps and marked read: a later
        :func:`~d3cli.kernels.device_counts.counts_to_host` of any count of those pools
        makes no copy.

    Returns
    -------
    disparity : ndarray, float32, (H, W)
    valid : ndarray, bool, (H, W)
        Views of one downloaded byte buffer (writable).
    values : list of int
        ``counts`` as ints.
    """
    if not (is_device(disparity) and is_device(valid)):
        return to_host(disparity), to_host(valid), counts_to_host(counts)
    h, w = disparity.shape
    n = h * w
    pools = _unread_pools(counts)
    valid_at, pool_at, size = _layout(n, pools)
    buffer = cuda.device_array(max(size, 1), np.uint8)
    d_disp = buffer[0:4 * n].view(np.float32).reshape(h, w)
    d_valid = buffer[valid_at:valid_at + n].view(np.bool_).reshape(h, w)
    d_pools = [buffer[at:at + 8 * int(p.array.shape[0])].view(np.int64) for p, at in zip(pools, pool_at)]
    # without a pool to read, the map and validity alone (a 1-slot stand-in, not copied)
    first = pools[0].array if pools else cuda.device_array(1, np.int64)
    first_out = d_pools[0] if pools else first
    n_slots = int(pools[0].array.shape[0]) if pools else 0
    blocks, threads = grid_1d(max(n, n_slots))
    _pack_kernel[blocks, threads](disparity, valid, first, n_slots, d_disp, d_valid, first_out)
    for pool, out in zip(pools[1:], d_pools[1:]):
        blocks, threads = grid_1d(pool.array.shape[0])
        _copy_slots_kernel[blocks, threads](pool.array, out)
    host = buffer.copy_to_host()
    for pool, at in zip(pools, pool_at):
        pool.values = host[at:at + 8 * int(pool.array.shape[0])].view(np.int64)
    out_disp = host[0:4 * n].view(np.float32).reshape(h, w)
    out_valid = host[valid_at:valid_at + n].view(np.bool_).reshape(h, w)
    return out_disp, out_valid, counts_to_host(counts)


@cuda.jit(cache=True)
def _narrow_kernel(disparity, out):
    u, v = cuda.grid(2)
    if v < disparity.shape[0] and u < disparity.shape[1]:
        out[v, u] = disparity[v, u]


def small_ints_to_host(disparity, max_value: int) -> np.ndarray:
    """An integer map with values in ``[-1, max_value]`` on the host, downloaded as int8
    (``max_value`` up to 127) or int16 (up to 32767); int32 otherwise.  The values are the
    map's (a host map is returned as it is)."""
    if not is_device(disparity):
        return np.asarray(disparity)
    dtype = np.int8 if max_value <= 127 else np.int16 if max_value <= 32767 else None
    if dtype is None:
        return to_host(disparity)
    h, w = disparity.shape
    out = cuda.device_array((h, w), dtype)
    blocks, threads = grid_2d(w, h)
    _narrow_kernel[blocks, threads](disparity, out)
    return out.copy_to_host()
