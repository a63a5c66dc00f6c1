"""Census matching cost blended into an NCC volume (addition to DESIGN step 2, issue 16).

The census transform (Zabih and Woodfill 1994) of a pixel is a bit string, one bit per
pixel of a w x w window around it (the centre left out): 1 where that neighbour is darker
than the centre.  The census cost of a match is the Hamming distance of the two strings,
divided by the number of bits (in [0, 1]).  It depends only on the order of grey levels,
so it is robust to the gain/offset differences between the two cameras and, unlike NCC,
does not stretch the noise of a nearly flat window to full contrast.

:func:`census_codes` computes the strings (uint64: windows up to 7 x 9 = 62 bits) and
:func:`blend_census` mixes the census cost into a banded cost volume in place:
``C = (1 - lam) C_ncc + lam C_census``.  Both are host (numba CPU) kernels; the CUDA
backend uses :func:`blend_census_cuda` with the same per-cell formula.  Cells whose right
pixel ``u - d`` lies outside the image keep their cost (1.0).

Layout of the volume: see :mod:`d3cli.kernels.volume` (``cost[off + d]`` for
``lo <= d < hi``).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

#: Largest census window area minus the centre that fits in a uint64 code.
MAX_BITS = 63


def census_bits(window: int) -> int:
    """Number of bits of a ``window`` x ``window`` census code (the centre is left out)."""
    return int(window) * int(window) - 1


@njit(parallel=True, cache=True)
def census_codes(image, window):
    """Census codes of a grey image.

    Parameters
    ----------
    image : ndarray, float32, (H, W)
    window : int
        Odd window size; ``window**2 - 1 <= 63``.

    Returns
    -------
    ndarray, uint64, (H, W)
        Bit ``k`` (neighbours in row-major order, centre skipped) is 1 where that
        neighbour is darker than the centre.  Neighbours outside the image are replaced
        by the nearest border pixel (replicate padding), so border codes stay comparable
        between the two views.
    """
    h, w = image.shape
    r = window // 2
    out = np.zeros((h, w), np.uint64)
    one = np.uint64(1)
    for v in prange(h):
        for u in range(w):
            centre = image[v, u]
            code = np.uint64(0)
            k = np.uint64(0)
            for dv in range(-r, r + 1):
                y = min(max(v + dv, 0), h - 1)
                for du in range(-r, r + 1):
                    if dv == 0 and du == 0:
                        continue
                    x = min(max(u + du, 0), w - 1)
                    if image[y, x] < centre:
                        code |= one << k
                    k += one
            out[v, u] = code
    return out


@njit(cache=True, inline="always")
def _popcount(x):
    """Number of set bits of a uint64 (SWAR; numba has no portable popcount)."""
    x = x - ((x >> np.uint64(1)) & np.uint64(0x5555555555555555))
    x = (x & np.uint64(0x3333333333333333)) + ((x >> np.uint64(2)) & np.uint64(0x3333333333333333))
    x = (x + (x >> np.uint64(4))) & np.uint64(0x0F0F0F0F0F0F0F0F)
    return (x * np.uint64(0x0101010101010101)) >> np.uint64(56)


@njit(parallel=True, cache=True)
def blend_census(cost, index, codes_l, codes_r, weight, n_bits):
    """``cost[off + d] = (1 - weight) cost + weight popcount(cl ^ cr) / n_bits`` in place.

    Parameters
    ----------
    cost : ndarray, float32, (n_cells,)
        The flat banded NCC volume (modified in place).
    index : ndarray, int32, (H, W, 3)
        ``[off, lo, hi]`` per pixel.
    codes_l, codes_r : ndarray, uint64, (H, W)
        Census codes of the left and right image (:func:`census_codes`).
    weight : float
        lambda in [0, 1].
    n_bits : int
        Bits per code (:func:`census_bits`).

    Notes
    -----
    Cells with ``u - d < 0`` are left as they are (1.0: no match there).  The blend is
    computed in float32 like the NCC cost itself.
    """
    h, w = codes_l.shape
    keep = np.float32(1.0 - weight)
    scale = np.float32(weight / n_bits)
    for v in prange(h):
        for u in range(w):
            off = index[v, u, 0]
            lo = index[v, u, 1]
            hi = min(index[v, u, 2], u + 1)
            cl = codes_l[v, u]
            for d in range(lo, hi):
                ham = np.float32(_popcount(cl ^ codes_r[v, u - d]))
                cost[off + d] = keep * cost[off + d] + scale * ham
    return cost


def blend_census_cuda(cost, index, codes_l, codes_r, weight, n_bits):
    """CUDA version of :func:`blend_census` on device arrays (``cost``, ``index``).

    The codes are computed on the host (:func:`census_codes`, O(H W w^2), small beside
    the volume) and uploaded here.
    """
    from numba import cuda

    kernel = _cuda_kernel()
    h, w = codes_l.shape
    dl = cuda.to_device(np.ascontiguousarray(codes_l))
    dr = cuda.to_device(np.ascontiguousarray(codes_r))
    threads = (16, 16)
    blocks = ((w + 15) // 16, (h + 15) // 16)
    kernel[blocks, threads](cost, index, dl, dr, np.float32(1.0 - weight), np.float32(weight / n_bits))
    return cost


_CUDA_KERNEL = None


def _cuda_kernel():
    """The CUDA blend kernel, compiled on first use (numba.cuda is optional)."""
    global _CUDA_KERNEL
    if _CUDA_KERNEL is None:
        from numba import cuda

        @cuda.jit
        def kernel(cost, index, codes_l, codes_r, keep, scale):
            u, v = cuda.grid(2)
            h, w = codes_l.shape
            if v >= h or u >= w:
                return
            off = index[v, u, 0]
            lo = index[v, u, 1]
            hi = min(index[v, u, 2], u + 1)
            cl = codes_l[v, u]
            for d in range(lo, hi):
                ham = cuda.popc(cl ^ codes_r[v, u - d])
                cost[off + d] = keep * cost[off + d] + scale * np.float32(ham)

        _CUDA_KERNEL = kernel
    return _CUDA_KERNEL
