"""The per-row bodies of the occlusion tests, written once for the CPU and for CUDA.

:func:`build` defines them with a given ``jit`` inside one closure (the project's pattern,
:func:`d3cli.kernels.ops.build_ops`): ``numba.njit`` for the CPU tasks of
:mod:`d3cli.kernels.finishing.occlusion`, ``numba.cuda.jit(device=True)`` for the kernels of
:mod:`d3cli.kernels.finishing.cuda` (one thread per row).  Each body reads and writes one
row ``y`` and its own row buffers, so the rows are independent.

May import: numpy.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

_F32_ONE = np.float32(1.0)
_F32_INF = np.float32(np.inf)
_F64_NEG_INF = -np.inf
# NumPy's float -> int64 cast of a value outside the int64 range (and of NaN) gives
# INT64_MIN on x86, which the reference's clip then maps to column 0
_INT64_LIMIT = 9.223372036854775807e18
# np.rint (half to even) of |x| < 2^51: adding and subtracting 1.5 * 2^52 rounds to an
# integer in the current (nearest-even) mode; measured 25 % faster than np.rint on the CPU
_ROUNDER = 6755399441055744.0


def build(jit):
    """The occlusion tests' row bodies compiled with ``jit``.

    Returns
    -------
    types.SimpleNamespace
        ``right_column(u, d, w)``, ``nearest_claims(disparity, valid, y, row_best,
        row_target)``, ``first_valid_from(disparity, valid, y, start)``,
        ``uniqueness_row(disparity, valid, tolerance, y, row_best, row_target, out)``,
        ``out_of_view_row(disparity, valid, start, y, out)`` and ``drop_occluded_row(disparity,
        valid, tolerance, start, y, row_best, row_target, out, occluded)`` (returns the
        row's number of occluded pixels).  ``row_best`` (float64) and ``row_target`` (int64)
        are the caller's row buffers of at least W cells.
    """

    @jit
    def right_column(u, d, w):
        """Column ``round(u - d)`` clipped to [0, w-1], as NumPy computes it (float64, half
        to even): 0 where ``u - d`` is NaN, infinite or beyond the int64 range (NumPy's cast
        gives INT64_MIN there, which the clip maps to 0).  Selects only, so that a loop over
        a row vectorises."""
        x = np.float64(u) - d
        inside = (x > -0.5) & (x < w - 0.5)  # rounds to 0 .. w-1 (False for NaN)
        beyond = (x >= w - 0.5) & (abs(x) < _INT64_LIMIT)  # rounds to w - 1 or above
        r = np.int64(((x if inside else 0.0) + _ROUNDER) - _ROUNDER)
        return r if inside else (w - 1 if beyond else 0)

    @jit
    def nearest_claims(disparity, valid, y, row_best, row_target):
        """The uniqueness test's scatter for row y: ``row_target[u]`` the right column of
        every pixel u, ``row_best[x]`` the largest valid disparity that claims right column
        x (-inf where none does; a NaN disparity wins its column).  Returns the number of
        valid pixels of the row."""
        w = disparity.shape[1]
        for u in range(w):  # no branch: vectorised (the scatter below is not)
            row_target[u] = right_column(u, np.float64(disparity[y, u]), w)
        for x in range(w):
            row_best[x] = _F64_NEG_INF
        n_valid = 0
        for u in range(w):
            if valid[y, u]:
                n_valid += 1
                d = np.float64(disparity[y, u])
                xr = row_target[u]
                if d > row_best[xr] or d != d:
                    row_best[xr] = d
        return n_valid

    @jit
    def first_valid_from(disparity, valid, y, start):
        """The left-border test's ``b`` of row y: the first valid disparity at or right of
        column ``start`` (float32), -inf when the row has none."""
        for u in range(start, disparity.shape[1]):
            if valid[y, u]:
                return disparity[y, u]
        return -_F32_INF

    @jit
    def uniqueness_row(disparity, valid, tolerance, y, row_best, row_target, out):
        """The uniqueness test of row y into ``out[y]``."""
        nearest_claims(disparity, valid, y, row_best, row_target)
        for u in range(disparity.shape[1]):
            out[y, u] = valid[y, u] and np.float64(disparity[y, u]) < row_best[row_target[u]] - tolerance

    @jit
    def out_of_view_row(disparity, valid, start, y, out):
        """The left-border test of row y into ``out[y]``."""
        b = first_valid_from(disparity, valid, y, start)
        b_minus_1 = b - _F32_ONE
        for u in range(disparity.shape[1]):
            out[y, u] = valid[y, u] and u < b and disparity[y, u] < b_minus_1

    @jit
    def drop_occluded_row(disparity, valid, tolerance, start, y, row_best, row_target, out, occluded):
        """Both tests of row y, their holes (``valid[y]`` in place) and the masked row
        ``out[y]`` (may be ``disparity``: the tests of the row finish before its first
        write, and each pixel is read before it is written)."""
        w = disparity.shape[1]
        # both tests read the row's validity before any of it is dropped
        n_valid = nearest_claims(disparity, valid, y, row_best, row_target)
        b = first_valid_from(disparity, valid, y, start)
        b_minus_1 = b - _F32_ONE
        n = 0
        # the loop chosen by the row's share of holes: selects or branches, whichever is
        # faster for that share on the CPU (measured on the pipeline's inputs of every data
        # set); both give the same values
        if 8 * (w - n_valid) > w:
            # many holes: selects (a branch on validity is mispredicted); every pixel has a
            # right column, so reading row_best there is safe
            for u in range(w):
                d32 = disparity[y, u]
                keep = valid[y, u]
                claimed = np.float64(d32) < row_best[row_target[u]] - tolerance
                occ = keep & (claimed | ((u < b) & (d32 < b_minus_1)))
                occluded[y, u] = occ
                keep = keep & (not occ)
                valid[y, u] = keep
                out[y, u] = d32 if keep else _F32_INF
                n += occ
        else:
            # few holes: branches (predicted; the vectorised loop above gathers row_best,
            # slower here)
            for u in range(w):
                d32 = disparity[y, u]
                keep = valid[y, u]
                occ = keep and (np.float64(d32) < row_best[row_target[u]] - tolerance
                                or (u < b and d32 < b_minus_1))
                occluded[y, u] = occ
                keep = keep and not occ
                valid[y, u] = keep
                out[y, u] = d32 if keep else _F32_INF
                n += occ
        return n

    return SimpleNamespace(right_column=right_column, nearest_claims=nearest_claims,
                           first_valid_from=first_valid_from, uniqueness_row=uniqueness_row,
                           out_of_view_row=out_of_view_row, drop_occluded_row=drop_occluded_row)
