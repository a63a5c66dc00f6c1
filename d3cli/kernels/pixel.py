"""Per-pixel math shared by the steps of D3Stereo: the constants and helpers every step's
per-pixel module uses, written once and compiled for every backend.

This module holds the constants (:data:`UNDECIDED`, :data:`INF`, :data:`UINT`) and the
helpers several steps share (:func:`build_shared`); it imports no step.  Every step's
per-pixel module (``cost/pixel.py``, ``aggregation/pixel.py``, ``decisive/pixel_*.py``,
``subpixel/pixel.py``, ``perspective/pixel.py``) imports it; :mod:`d3cli.kernels.ops`
composes them all into one namespace of functions compiled with ``jit``: ``numba.njit``
for the CPU (``kernels/cpu_common.py``) and ``numba.cuda.jit(device=True)`` for CUDA
(``kernels/cuda_launch.py``).  The same Python source is compiled twice, so the two
backends cannot drift apart.  (Calling an ``@njit`` function from a CUDA kernel fails
in the CUDA simulator, hence the factory rather than shared dispatchers.)

Rules for everything in here: arguments are arrays, indices and scalars; results are
scalars; no allocation, no exceptions, no Python objects.  Scratch memory and loops over
the image belong to the drivers.

Conventions (docs/design.md, 'Cost volumes')
---------------------------------
* A cost volume is a pair ``(cost, index)``: ``cost`` a flat float32 array, ``index``
  an int32 (H, W, 3) array ``[off, lo, hi]`` per pixel; the pixel (u, v) holds the
  disparities ``lo <= d < hi`` (its *band*) at ``cost[off + d]``.  The full-range volume
  is the band ``[0, D)`` everywhere with ``off = (v W + u) D``: exactly the (H, W, D)
  array, disparity innermost (:mod:`d3cli.kernels.volume`).  Fine pyramid levels store
  only a band around what the coarser level decided (:mod:`d3cli.kernels.cost.band`).
  Cost is ``(1 - NCC) / 2`` in [0, 1], lower is better.  Cells whose right pixel
  ``u - d`` is outside the image, or whose window is flat, hold 1.0 and never win.
* Disparity maps are int32 with ``-1`` for undecided pixels (never 0, a legal disparity).
* :func:`cost_or_inf` returns ``inf`` for a cell that does not exist (pixel outside the
  image or disparity outside the pixel's band).  A comparison ``c < cost_or_inf(...)`` against a
  missing cell is therefore always true: missing neighbours never veto a decision.
* The right-view cost is the left volume re-indexed (never a second volume):
  ``C_R(x, v, d) = C_L(x + d, v, d)`` (:func:`right_cost_or_inf`); a cell outside the
  band of the left pixel x + d does not exist.
* Ties in an arg-min go to the smaller disparity, so every backend agrees exactly.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

UNDECIDED = -1
INF = math.inf
UINT = np.uint64  # subscripts already checked to be >= 0


# Longer than 80 lines by design: a factory whose length is the per-pixel functions it
# compiles (each short); one closure scope is what lets the same source compile for the
# CPU and for CUDA (calling an @njit function from a CUDA kernel fails in the simulator).
def build_shared(jit):
    """Compile the per-pixel helpers shared by several steps with ``jit``.

    Parameters
    ----------
    jit : callable
        A decorator such as ``numba.njit(cache=True)`` or ``numba.cuda.jit(device=True)``.

    Returns
    -------
    types.SimpleNamespace
        ``cost_or_inf, right_cost_or_inf, least, least_two, first_at, band_min``.
    """

    @jit
    def cost_or_inf(cost, index, v, u, d):
        """Cost of cell (u, v, d), or inf where that cell does not exist (pixel outside the
        image, disparity outside the pixel's band)."""
        if v < 0 or v >= index.shape[0] or u < 0 or u >= index.shape[1]:
            return INF
        # unsigned subscripts (known >= 0 here): no negative-index wraparound code
        vu = UINT(v)
        uu = UINT(u)
        if d < index[vu, uu, 1] or d >= index[vu, uu, 2]:
            return INF
        return cost[UINT(index[vu, uu, 0] + d)]


    @jit
    def right_cost_or_inf(cost, index, v, x, d):
        """Right-view cost ``C_R(x, v, d) = C_L(x + d, v, d)``, inf where it does not exist."""
        return cost_or_inf(cost, index, v, x + d, d)


    @jit
    def least(cost, base, n):
        """Least of the ``n`` cells ``cost[base:base + n]`` (inf when ``n`` <= 0).

        Four interleaved lanes, merged at the end: their min chains are independent, so
        the CPU overlaps them (one chain waits a compare and a select per cell).  ``min``
        returns one of its arguments: the value is the one an in-order scan finds.
        """
        a0 = a1 = a2 = a3 = np.float32(INF)
        k = 0
        while k + 4 <= n:
            a0 = min(a0, cost[base + UINT(k)])
            a1 = min(a1, cost[base + UINT(k + 1)])
            a2 = min(a2, cost[base + UINT(k + 2)])
            a3 = min(a3, cost[base + UINT(k + 3)])
            k += 4
        while k < n:
            a0 = min(a0, cost[base + UINT(k)])
            k += 1
        return min(min(a0, a1), min(a2, a3))


    @jit
    def least_two(cost, base, n):
        """Least and second least of the ``n`` > 0 cells ``cost[base:base + n]``, the
        second inf when ``n`` = 1 (a least held twice is the second least too).

        Four interleaved lanes as in :func:`least`, each keeping its least ``a`` and second
        least ``b``; two lanes merge into the lesser least and, as second, the lesser of
        their greater least and their seconds.  ``min`` and ``max`` return one of their
        arguments, so the values are exactly those of an in-order scan.
        """
        a0 = a1 = a2 = a3 = np.float32(INF)
        b0 = b1 = b2 = b3 = np.float32(INF)
        k = 0
        while k + 4 <= n:
            c = cost[base + UINT(k)]
            b0 = min(b0, max(c, a0))
            a0 = min(a0, c)
            c = cost[base + UINT(k + 1)]
            b1 = min(b1, max(c, a1))
            a1 = min(a1, c)
            c = cost[base + UINT(k + 2)]
            b2 = min(b2, max(c, a2))
            a2 = min(a2, c)
            c = cost[base + UINT(k + 3)]
            b3 = min(b3, max(c, a3))
            a3 = min(a3, c)
            k += 4
        while k < n:
            c = cost[base + UINT(k)]
            b0 = min(b0, max(c, a0))
            a0 = min(a0, c)
            k += 1
        b0 = min(max(a0, a1), min(b0, b1))
        a0 = min(a0, a1)
        b2 = min(max(a2, a3), min(b2, b3))
        a2 = min(a2, a3)
        return min(a0, a2), min(max(a0, a2), min(b0, b2))


    @jit
    def first_at(cost, base, c):
        """Offset of the first of the cells ``cost[base:]`` that equals ``c`` (one must)."""
        k = 0
        while cost[base + UINT(k)] != c:
            k += 1
        return k


    @jit
    def band_min(cost, index, v, u):
        """Least cost of pixel (u, v) over its band, which is not empty."""
        lo = index[v, u, 1]
        return least(cost, UINT(index[v, u, 0] + lo), index[v, u, 2] - lo)

    return SimpleNamespace(
        cost_or_inf=cost_or_inf,
        right_cost_or_inf=right_cost_or_inf,
        least=least,
        least_two=least_two,
        first_at=first_at,
        band_min=band_min,
    )
