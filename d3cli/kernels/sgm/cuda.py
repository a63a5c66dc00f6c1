"""CUDA driver of the semi-global smoothing: one block of 32 threads per image line, the
line's disparities across the threads.  The contract: :mod:`d3cli.kernels.backend`."""

from __future__ import annotations

import numba
import numpy as np
from numba import cuda

from ..cuda_launch import device_zeros, pack_volume, unpack_volume

#: Threads per line: a warp, the band's disparities spread over them (as libSGM does).
LANES = 32
#: Size of the block's shared minimum buffer (LANES may be set lower, never higher).
MAX_LANES = 32


# ----------------------------------------------------------------------------- semi-global smoothing
# One path step of a pixel is the recurrence of ``Backend.sgm_smooth`` (kernels/backend.py),
# cell by cell, with the band spread over the block's threads instead of a loop: the previous pixel's least path cost is
# a block-wide minimum (exact in any order), each cell's new cost the same float32
# expression in the same order, so the result equals the CPU's bit for bit (the tests
# compare them).  The line's two path buffers are in ``scratch`` (L(d) at base + d + 1, as
# the CPU's); a cell outside the previous pixel's band reads as inf by a bounds test
# rather than from inf-filled sentinels (on the CPU they keep the loop branch-free), which
# spares a reset of the buffer and a barrier per pixel.
@cuda.jit(device=True)
def _previous(scratch, a, d, plo, phi):
    """L(q, d) of the previous pixel, inf outside its band ``[plo, phi)``."""
    if plo <= d and d < phi:
        return scratch[a + d + 1]
    return numba.float32(np.inf)


@cuda.jit(device=True)
def _sgm_path(cost, index, line, along_rows, backward, p1, p2, scratch, size, acc, mode, partial):
    lane = cuda.threadIdx.x
    lanes = cuda.blockDim.x
    n = index.shape[1] if along_rows else index.shape[0]
    a = 2 * size * line
    b = a + size
    plo = 0
    phi = 0
    quarter = numba.float32(0.25)
    for i in range(n):
        j = n - 1 - i if backward else i
        v = line if along_rows else j
        u = j if along_rows else line
        off = index[v, u, 0]
        lo = index[v, u, 1]
        hi = index[v, u, 2]
        m = numba.float32(np.inf)
        for k in range(plo + lane, phi, lanes):
            x = scratch[a + k + 1]
            m = x if x < m else m
        partial[lane] = m
        cuda.syncthreads()
        pm = numba.float32(np.inf)
        for k in range(lanes):
            x = partial[k]
            pm = x if x < pm else pm
        for d in range(lo + lane, hi, lanes):
            el = cost[off + d]
            if pm != np.inf:
                x = _previous(scratch, a, d, plo, phi)  # L(q, d)
                jump = pm + p2
                best = x if x < jump else jump
                y = _previous(scratch, a, d - 1, plo, phi) + p1  # L(q, d - 1) + P1
                best = y if y < best else best
                y = _previous(scratch, a, d + 1, plo, phi) + p1  # L(q, d + 1) + P1
                best = y if y < best else best
                el = el + (best - pm)
            scratch[b + d + 1] = el
            if mode == 0:
                acc[off + d] = el
            elif mode == 1:
                acc[off + d] += el
            else:
                acc[off + d] = (acc[off + d] + el) * quarter
        cuda.syncthreads()  # the pixel's costs are written, the previous ones and partial read
        plo = lo
        phi = hi
        a, b = b, a


@cuda.jit(cache=True)
def _sgm_line_kernel(cost, index, along_rows, backward, p1, p2, scratch, size, acc, mode):
    """One path of one row (``along_rows``) or column per block, forward or ``backward``."""
    line = cuda.blockIdx.x
    partial = cuda.shared.array(MAX_LANES, numba.float32)
    _sgm_path(cost, index, line, along_rows, backward, p1, p2, scratch, size, acc, mode, partial)


def sgm_smooth(cost, p1, p2):
    """Mean of four semi-global path costs of a volume (as the CPU backend's): a block per
    row or column, one launch per path, in the CPU's order of the sums (left, down, right,
    up: the CPU walks two paths per sweep, left and down, then right and up).

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.sgm_smooth`.
    """
    flat, index, n_disp, dense = unpack_volume(cost)
    h, w = int(index.shape[0]), int(index.shape[1])
    acc = device_zeros(flat.shape[0], np.float32)  # cells outside every visible band stay 0
    p1, p2 = np.float32(p1), np.float32(p2)
    size = n_disp + 2
    scratch = cuda.device_array(2 * size * max(h, w), np.float32)  # read only where written
    lanes = min(int(LANES), MAX_LANES)
    # (along rows, backward, mode): the first path stores, the last one scales
    for along_rows, backward, mode in ((True, False, 0), (False, False, 1), (True, True, 1), (False, True, 2)):
        lines = h if along_rows else w
        _sgm_line_kernel[lines, lanes](flat, index, along_rows, backward, p1, p2, scratch, size, acc, mode)
    return pack_volume(acc, index, n_disp, dense)
