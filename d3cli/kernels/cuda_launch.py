"""What every CUDA driver shares: the per-pixel functions compiled with
``numba.cuda.jit(device=True)`` (:data:`ops`), grid sizes, host/device transfers and
the volume unpack/pack.

Drivers accept device or host arrays (uploaded on the way in) and leave results on the
device; :func:`to_host` brings any array back.
"""

from __future__ import annotations

import numpy as np
from numba import cuda

from . import compile_cache as _compile_cache  # noqa: F401  (drops stale cached kernels before any is loaded)
from .ops import build_ops
from .volume import Volume, dense_index


#: Threads per block (x, y) of the image-shaped grids; x runs along columns (or
#: column x disparity cells), y along rows.  Tests make it small to get several partly
#: filled blocks on odd sizes.
BLOCK_2D = (16, 16)


#: Threads per block of the one-dimensional grids (rows, columns, pixel lists).
BLOCK_1D = 256


ops = build_ops(cuda.jit(device=True))


# ----------------------------------------------------------------------------- launch helpers
def grid_1d(n):
    """(blocks, threads) covering ``n`` items with :data:`BLOCK_1D` threads per block."""
    threads = int(BLOCK_1D)
    return (max(1, -(-int(n) // threads)),), (threads,)


def grid_2d(nx, ny):
    """(blocks, threads) covering an ``nx`` (fast, x) by ``ny`` (rows, y) grid."""
    bx, by = (int(b) for b in BLOCK_2D)
    return (max(1, -(-int(nx) // bx)), max(1, -(-int(ny) // by))), (bx, by)


def per_pixel(kernel, shape, dtype, *args):
    """Launch ``kernel(*args, out)`` with one thread per pixel of an (H, W) map.

    ``out`` is a new (H, W) device array of ``dtype`` (the kernel's last argument), and
    is returned.
    """
    h, w = int(shape[0]), int(shape[1])
    out = cuda.device_array((h, w), dtype)
    blocks, threads = grid_2d(w, h)
    kernel[blocks, threads](*args, out)
    return out


def as_f64(x):
    """A float scalar argument as float64 (the CPU drivers' type, also under the simulator)."""
    return np.float64(x)


def is_device(array) -> bool:
    """True for a CUDA device array (real or simulated), False for host arrays."""
    return not isinstance(array, np.ndarray) and hasattr(array, "copy_to_host")


def on_device(array):
    """``array`` on the device (uploaded when it is a host array)."""
    if is_device(array):
        return array
    return cuda.to_device(np.ascontiguousarray(array))


def device_copy(d_array):
    """A device copy of a device array."""
    out = cuda.device_array(d_array.shape, d_array.dtype)
    out.copy_to_device(d_array)
    return out


@cuda.jit(cache=True)
def fill_zero(flat):
    i = cuda.grid(1)
    if i < flat.shape[0]:
        flat[i] = 0


def device_zeros(n, dtype):
    """A zeroed 1-D device array, filled on the device (no host transfer)."""
    out = cuda.device_array(int(n), dtype)
    blocks, threads = grid_1d(n)
    fill_zero[blocks, threads](out)
    return out


def unpack_volume(cost):
    """``(flat device cost, device index, n_disp, dense shape or None)`` of a Volume or an
    (H, W, D) array (host or device), as ``cpu.unpack_volume``."""
    if isinstance(cost, Volume):
        return on_device(cost.cost), on_device(cost.index), int(cost.n_disp), None
    d_cost = on_device(cost)
    h, w, n_disp = d_cost.shape
    return d_cost.reshape(h * w * n_disp), cuda.to_device(dense_index(h, w, n_disp)), n_disp, (h, w, n_disp)


def pack_volume(flat, index, n_disp, dense_shape):
    """The result in the caller's kind: a Volume of device arrays, or an (H, W, D) device array."""
    if dense_shape is not None:
        return flat.reshape(*dense_shape)
    return Volume(flat, index, n_disp)


# ----------------------------------------------------------------------------- array handling
def to_device(array):
    """The array on the device: host arrays are uploaded (C-contiguous), device arrays kept."""
    return on_device(array)


def to_host(array):
    """NumPy array of a device array (one download); host arrays pass through."""
    if is_device(array):
        return array.copy_to_host()
    return np.asarray(array)
