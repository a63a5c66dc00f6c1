"""CUDA driver of the semi-global smoothing: one thread per line.  The contract:
:mod:`d3cli.kernels.backend`."""

from __future__ import annotations

import numpy as np
from numba import cuda

from ..cuda_launch import _grid_1d, _pack, _unpack, _zeros, ops


_sgm_step = ops.sgm_step


# ----------------------------------------------------------------------------- semi-global smoothing
@cuda.jit(device=True)
def _all_inf(buffer, start, stop):
    for k in range(start, stop):
        buffer[k] = np.inf


@cuda.jit(device=True)
def _sgm_line(cost, index, line, along_rows, p1, p2, scratch, size, acc, forward_mode, backward_mode):
    """Both paths along one row (``along_rows``) or column of the image, forward then
    backward, with the line's two path buffers in ``scratch`` (``pixel.sgm_step``'s layout,
    inf outside the band); ``*_mode`` as the step's ``mode``."""
    n = index.shape[1] if along_rows else index.shape[0]
    start = 2 * size * line
    a, b = start, start + size
    _all_inf(scratch, start, start + 2 * size)
    plo, phi = 0, 0
    for i in range(n):
        v, u = (line, i) if along_rows else (i, line)
        _sgm_step(cost, index, v, u, (scratch, a), plo, phi, (scratch, b), p1, p2, acc, forward_mode)
        plo, phi = index[v, u, 1], index[v, u, 2]
        a, b = b, a
    _all_inf(scratch, start, start + 2 * size)
    plo, phi = 0, 0
    for i in range(n):
        v, u = (line, n - 1 - i) if along_rows else (n - 1 - i, line)
        _sgm_step(cost, index, v, u, (scratch, a), plo, phi, (scratch, b), p1, p2, acc, backward_mode)
        plo, phi = index[v, u, 1], index[v, u, 2]
        a, b = b, a


@cuda.jit(cache=True)
def _sgm_rows_kernel(cost, index, p1, p2, scratch, size, acc):
    v = cuda.grid(1)
    if v < index.shape[0]:
        _sgm_line(cost, index, v, True, p1, p2, scratch, size, acc, 0, 1)  # the first path stores


@cuda.jit(cache=True)
def _sgm_columns_kernel(cost, index, p1, p2, scratch, size, acc):
    u = cuda.grid(1)
    if u < index.shape[1]:
        _sgm_line(cost, index, u, False, p1, p2, scratch, size, acc, 1, 2)  # the last one scales


def sgm_smooth(cost, p1, p2):
    """Mean of four semi-global path costs of a volume (as the CPU backend's): one thread
    per row for the row paths, one per column for the column paths.

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.sgm_smooth`.
    """
    flat, index, n_disp, dense = _unpack(cost)
    h, w = int(index.shape[0]), int(index.shape[1])
    acc = _zeros(flat.shape[0], np.float32)  # cells outside every visible band stay 0
    p1, p2 = np.float32(p1), np.float32(p2)
    size = n_disp + 2
    scratch = cuda.device_array(2 * size * max(h, w), np.float32)  # inf-filled by the kernels
    blocks, threads = _grid_1d(h)
    _sgm_rows_kernel[blocks, threads](flat, index, p1, p2, scratch, size, acc)
    blocks, threads = _grid_1d(w)
    _sgm_columns_kernel[blocks, threads](flat, index, p1, p2, scratch, size, acc)
    return _pack(acc, index, n_disp, dense)
