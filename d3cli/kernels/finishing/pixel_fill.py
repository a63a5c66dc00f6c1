"""The per-row bodies of the row-wise hole filling, written once for the CPU and for CUDA.

:func:`build` defines them with a given ``jit`` inside one closure (as
:mod:`d3cli.kernels.finishing.pixel_occlusion`): ``numba.njit`` for the CPU tasks of
:mod:`d3cli.kernels.finishing.fill`, ``numba.cuda.jit(device=True)`` for the kernels of
:mod:`d3cli.kernels.finishing.cuda` (one thread per row, or per pixel for the median).

May import: numpy.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

_F32_INF = np.float32(np.inf)


def build(jit):
    """The hole filling's row bodies compiled with ``jit``.

    Returns
    -------
    types.SimpleNamespace
        ``np_minimum(a, b)``, ``usable_row(disp, valid, use, y)`` (returns the row's usable
        pixels), ``fill_row(disp, valid, filled, y)`` (returns whether the row has a valid
        pixel), ``nearest_row(row_has, y)`` and ``copy_nearest_row(filled, row_has, y)``,
        ``median5_at(filled, y, u, buf)`` (``buf``: the caller's 25 float32 cells).
    """

    @jit
    def np_minimum(a, b):
        """``np.minimum`` of two non-NaN values (the second when they compare equal)."""
        return a if a < b else b

    @jit
    def usable_row(disp, valid, use, y):
        """``use[y] = valid[y] & isfinite(disp[y])``; the number of such pixels."""
        m = 0
        for u in range(disp.shape[1]):
            ok = valid[y, u] & math.isfinite(disp[y, u])  # &: no branch
            use[y, u] = ok
            m += ok
        return m

    @jit
    def fill_row(disp, valid, filled, y):
        """Row y of the row-wise fill: each hole the smaller of the nearest valid values
        left and right (inf where the row has none).  One pass: the holes of a run between
        two valid pixels (or a row end, inf) all take the same value, written when the run
        ends.  Returns whether the row has a valid pixel."""
        w = disp.shape[1]
        left = _F32_INF
        start = 0  # the first hole of the current run
        has = False
        for u in range(w):
            x = disp[y, u]
            filled[y, u] = x
            if valid[y, u]:
                if start < u:
                    fill = np_minimum(left, x)
                    for j in range(start, u):
                        filled[y, j] = fill
                left = x
                has = True
                start = u + 1
        fill = np_minimum(left, _F32_INF)
        for j in range(start, w):
            filled[y, j] = fill
        return has

    @jit
    def nearest_row(row_has, y):
        """The row an empty row y copies: the nearest row that has a valid pixel, the upper
        on a tie; the last row when none has (a copy of itself for that row)."""
        h = row_has.shape[0]
        up = -1
        for k in range(y - 1, -1, -1):
            if row_has[k]:
                up = k
                break
        below = -1
        for k in range(y + 1, h):
            if row_has[k]:
                below = k
                break
        if below < 0 or (up >= 0 and y - up <= below - y):
            return up if up >= 0 else h - 1
        return below

    @jit
    def copy_nearest_row(filled, row_has, y):
        """Row y, when it has no valid pixel, becomes a copy of :func:`nearest_row`'s (a row
        that is never written itself, so the rows may run in any order)."""
        if row_has[y]:
            return
        src = nearest_row(row_has, y)
        for u in range(filled.shape[1]):
            filled[y, u] = filled[src, u]

    @jit
    def median5_at(filled, y, u, buf):
        """The median of the 5x5 window around (y, u), borders replicated
        (``cv2.medianBlur(filled, 5)`` of a map without NaN): an insertion sort of the 25
        values into ``buf``, the 13th."""
        h, w = filled.shape
        n = 0
        for dy in range(-2, 3):
            yy = min(max(y + dy, 0), h - 1)
            for dx in range(-2, 3):
                x = filled[yy, min(max(u + dx, 0), w - 1)]
                i = n
                while i > 0 and buf[i - 1] > x:
                    buf[i] = buf[i - 1]
                    i -= 1
                buf[i] = x
                n += 1
        return buf[12]

    return SimpleNamespace(np_minimum=np_minimum, usable_row=usable_row, fill_row=fill_row,
                           nearest_row=nearest_row, copy_nearest_row=copy_nearest_row, median5_at=median5_at)
