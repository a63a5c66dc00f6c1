"""The column and row bodies of the filling inside surfaces, written once for the CPU and
for CUDA.

:func:`build` defines them with a given ``jit`` inside one closure (as
:mod:`d3cli.kernels.finishing.pixel_fill`): ``numba.njit`` for the CPU tasks of
:mod:`d3cli.kernels.finishing.fill` (a task a block of columns or of rows),
``numba.cuda.jit(device=True)`` for the kernels of
:mod:`d3cli.kernels.finishing.cuda_fill_inside` (a thread per column, a thread per row).

May import: numpy.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

_F32_TWO = np.float32(2.0)
_F32_INF = np.float32(np.inf)


def build(jit):
    """The filling inside surfaces compiled with ``jit``.

    Returns
    -------
    types.SimpleNamespace
        ``nearest_columns(disp, valid, up, down, u0, u1, last)`` (columns ``u0 <= u < u1``;
        ``last``: the caller's ``u1 - u0`` float32 cells), ``inside_value(l_v, r_v, up_v,
        down_v, occluded)`` and ``fill_inside_row(disp, valid, occluded, up, down, out,
        left, right, y)`` (``left``, ``right``: the caller's ``W`` float32 cells).
    """

    @jit
    def nearest_columns(disp, valid, up, down, u0, u1, last):
        """Columns ``u0 <= u < u1`` of the nearest usable value (valid and finite) at or
        above (``up``) and at or below (``down``) each pixel, inf where there is none; the
        rows streamed top down, then bottom up."""
        h = disp.shape[0]
        n = u1 - u0
        for i in range(n):
            last[i] = _F32_INF
        for y in range(h):  # top down: the nearest usable value at or above
            d_row = disp[y, u0:u1]
            v_row = valid[y, u0:u1]
            o_row = up[y, u0:u1]
            for i in range(n):  # selects: vectorised across the columns on the CPU
                x = d_row[i]  # both loaded before the select: a load in its arm is a branch
                prev = last[i]
                value = x if (v_row[i] & math.isfinite(x)) else prev
                last[i] = value
                o_row[i] = value
        for i in range(n):
            last[i] = _F32_INF
        for y in range(h - 1, -1, -1):  # bottom up: at or below
            d_row = disp[y, u0:u1]
            v_row = valid[y, u0:u1]
            o_row = down[y, u0:u1]
            for i in range(n):
                x = d_row[i]
                prev = last[i]
                value = x if (v_row[i] & math.isfinite(x)) else prev
                last[i] = value
                o_row[i] = value

    @jit
    def np_minimum(a, b):
        """``np.minimum`` of two non-NaN values (the second when they compare equal)."""
        return a if a < b else b

    @jit
    def order(a, b):
        """``(a, b)`` in increasing order, swapped only when ``a > b`` (equal values keep
        their order: a network of such adjacent exchanges sorts stably, as an insertion
        sort)."""
        swap = a > b
        return (b if swap else a), (a if swap else b)

    @jit
    def inside_value(l_v, r_v, up_v, down_v, occluded):
        """The fill of one hole from its four nearest values: the smaller row neighbour
        where the hole is occluded or has no nearest value, else the median of the finite
        ones (the float32 mean of the middle two of an even count)."""
        side = np_minimum(l_v, r_v)
        # The nearest values are finite or +inf (none): sorting all four with +inf last
        # gives the finite ones in the order of the reference's insertion sort of the
        # finite values alone (left, right, up, down; stable on ties).  Selects only: the
        # pattern of holes is random, and branches mispredicted.
        a0, a1 = order(l_v, r_v)
        a1, a2 = order(a1, up_v)
        a0, a1 = order(a0, a1)
        a2, a3 = order(a2, down_v)
        a1, a2 = order(a1, a2)
        a0, a1 = order(a0, a1)
        # int() of each: NumPy's sum of two bools (CUDA's simulator) is their or
        n = int(l_v != _F32_INF) + int(r_v != _F32_INF) + int(up_v != _F32_INF) + int(down_v != _F32_INF)
        median = a0 if n == 1 else ((a0 + a1) / _F32_TWO if n == 2 else (a1 if n == 3 else (a1 + a2) / _F32_TWO))
        return side if (occluded or n == 0) else median

    @jit
    def fill_inside_row(disp, valid, occluded, up, down, out, left, right, y):
        """Row y of the filling inside surfaces: ``disp`` where valid, else
        :func:`inside_value` of the nearest valid values left and right in the row (found
        here, into ``left`` and ``right``) and ``up``, ``down``."""
        w = disp.shape[1]
        d_row = disp[y]
        v_row = valid[y]
        # the nearest valid value at or left of u and at or right of j = w - 1 - u: two
        # independent chains of selects in one loop (faster than two scans)
        a = _F32_INF
        b = _F32_INF
        for u in range(w):
            j = w - 1 - u
            x = d_row[u]  # loaded before the select: a load in its arm compiles to a branch
            z = d_row[j]
            a = x if v_row[u] else a
            b = z if v_row[j] else b
            left[u] = a
            right[j] = b
        for u in range(w):  # no carried value: this loop vectorises on the CPU
            fill = inside_value(left[u], right[u], up[y, u], down[y, u], occluded[y, u])
            out[y, u] = d_row[u] if v_row[u] else fill

    return SimpleNamespace(nearest_columns=nearest_columns, np_minimum=np_minimum, order=order,
                           inside_value=inside_value, fill_inside_row=fill_inside_row)
