"""CPU driver of the disparity inheritance to the next finer level (paper
Algorithm 2, eq. 6-8).  The contract: :mod:`d3cli.kernels.backend`."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .. import compile_cache as _compile_cache  # noqa: F401  (chooses the numba cache folder first)
from ..cpu_common import ops, unpack_volume
from ..pixel import UNDECIDED


_inherit_patch_into = ops.inherit_patch_into


# ----------------------------------------------------------------------------- inheritance (step 7)
def inherit(cost, coarse, prc, dfm_pkrn_min, epsilon, candidates=0):
    """Inter-scale decisive inheritance (paper Algorithm 2, eq. 6-8).

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.inherit`.
    """
    flat, index, _, _ = unpack_volume(cost)
    return _inherit(flat, index, coarse, bool(prc), float(dfm_pkrn_min), float(epsilon), int(candidates))


@njit(parallel=True, cache=True, error_model="numpy")
def _inherit(cost, index, coarse, prc, dfm_pkrn_min, epsilon, candidates):
    h, w, _ = index.shape
    out = np.empty((h, w), np.int32)
    for prange_pv in prange((h + 1) // 2):
        # int64 as every other caller passes (a prange index is uint64): one compiled
        # variant of each row kernel instead of two, a shorter first compile
        pv = np.int64(prange_pv)
        # The test variant as constants in each branch: the compiler specialises the
        # inlined tests (measured faster than one generic call).
        if prc and candidates == 0:
            inherit_row_prc(cost, index, coarse, pv, out, 0)
        elif prc:
            inherit_row_prc(cost, index, coarse, pv, out, 1)
        elif candidates == 0:
            _inherit_row(cost, index, coarse, pv, out, False, dfm_pkrn_min, epsilon, 0)
        else:
            _inherit_row(cost, index, coarse, pv, out, False, dfm_pkrn_min, epsilon, 1)
    return out


@njit(cache=True, error_model="numpy")
def _inherit_row(cost, index, coarse, pv, out, prc, dfm_pkrn_min, epsilon, candidates):
    """The fine rows 2 pv, 2 pv + 1 of :func:`_inherit` (one patch row)."""
    for pu in range((out.shape[1] + 1) // 2):
        _inherit_patch_into(out, cost, index, coarse, pv, pu, prc, dfm_pkrn_min, epsilon, candidates)


_window5 = ops.window5


_right_window5 = ops.right_window5


_window_summary = ops.window_summary


_patch_reliable4 = ops.patch_reliable4


_pixel_decisive5 = ops.pixel_decisive5


@njit(cache=True, error_model="numpy", inline="always")
def _right_decision(s, d, least_out):
    """:func:`pixel.pixel_decisive5` with ``prc`` of a right-view window from its
    :func:`pixel.window_summary` ``s`` alone (the PRC test needs no more of the window)."""
    if s[0] < 0 or s[1] >= 1.0:
        return UNDECIDED
    if s[3] and s[1] < least_out:
        return d - 2 + s[0]
    return UNDECIDED


@njit(cache=True, error_model="numpy", inline="always")
def _pick4(j, a, b, c, e):
    """The j-th (0..3) of four ints, as selects (j is data: no branch to mispredict)."""
    lo = a if j == 0 else b
    hi = c if j == 2 else e
    return lo if j < 2 else hi


@njit(cache=True, error_model="numpy", inline="always")
def _inherit_pixel_prc(left, left_s, u, d, x0, least_out_l, rd0, rd1, rd2, rd3, candidates):
    """:func:`pixel.inherit_pixel5` with ``prc``: the matched right pixel x = u - dl is
    one of x0 - 1 .. x0 + 2, whose right-view decisions are ``rd0 .. rd3``."""
    dl = _pixel_decisive5(left, left_s, u, d, False, True, least_out_l, 1.0, 0.0, candidates)
    dr = _pick4(u - dl - x0 + 1, rd0, rd1, rd2, rd3)
    return dl if dl >= 0 and dr == dl else UNDECIDED


@njit(cache=True, error_model="numpy")
def inherit_row_prc(cost, index, coarse, pv, out, candidates):
    """:func:`_inherit_row` with ``prc`` (the configured test): the same decisions, with the
    right-view windows of a patch row shared along it.

    A left pixel of the patch at u0 matches a right pixel x0 - 1 .. x0 + 2 (x0 = u0 - d):
    the patch's own two and, for about a quarter of the decided pixels, one beside them,
    which :func:`pixel.inherit_quad` reads on demand (a branch on data).  Here each
    patch summarises the right windows x0 + 1 and x0 + 2 of both rows and takes x0 - 1
    and x0 from the patch before it, whose x0 + 1 and x0 + 2 they are when its coarse
    disparity is the same (84-99 % of the decided patches); otherwise it reads all four.
    The pixel then picks its right pixel's decision by a select.
    """
    h = out.shape[0]
    w = out.shape[1]
    y0 = 2 * pv
    y1 = y0 + 1
    n_pu = (w + 1) // 2
    if pv >= coarse.shape[0]:
        for pu in range(n_pu):
            _write_patch(out, y0, 2 * pu, UNDECIDED, UNDECIDED, UNDECIDED, UNDECIDED)
        return
    prev_d = -1  # d of the patch before whose x0 + 1, x0 + 2 summaries are held (-1: none)
    q02 = q03 = q12 = q13 = (0, 0.0, 0.0, False)  # those summaries (row b: q_b2, q_b3)
    for pu in range(n_pu):
        u0 = 2 * pu
        dc = coarse[pv, pu] if pu < coarse.shape[1] else UNDECIDED
        if dc < 0:
            _write_patch(out, y0, u0, UNDECIDED, UNDECIDED, UNDECIDED, UNDECIDED)
            prev_d = -1
            continue
        d = 2 * dc
        x0 = u0 - d
        l00 = _window5(cost, index, y0, u0, d)
        l01 = _window5(cost, index, y0, u0 + 1, d)
        l10 = _window5(cost, index, y1, u0, d)
        l11 = _window5(cost, index, y1, u0 + 1, d)
        sl00 = _window_summary(l00, u0, d, False, candidates)
        sl01 = _window_summary(l01, u0 + 1, d, False, candidates)
        sl10 = _window_summary(l10, u0, d, False, candidates)
        sl11 = _window_summary(l11, u0 + 1, d, False, candidates)
        least_out_l = _patch_reliable4(sl00, sl01, sl10, sl11)
        if least_out_l < 0.0:
            _write_patch(out, y0, u0, UNDECIDED, UNDECIDED, UNDECIDED, UNDECIDED)
            prev_d = -1
            continue
        if prev_d == d:
            s00, s01, s10, s11 = q02, q03, q12, q13
        else:
            s00 = _window_summary(_right_window5(cost, index, y0, x0 - 1, d), x0 - 1, d, True, candidates)
            s01 = _window_summary(_right_window5(cost, index, y0, x0, d), x0, d, True, candidates)
            s10 = _window_summary(_right_window5(cost, index, y1, x0 - 1, d), x0 - 1, d, True, candidates)
            s11 = _window_summary(_right_window5(cost, index, y1, x0, d), x0, d, True, candidates)
        s02 = _window_summary(_right_window5(cost, index, y0, x0 + 1, d), x0 + 1, d, True, candidates)
        s03 = _window_summary(_right_window5(cost, index, y0, x0 + 2, d), x0 + 2, d, True, candidates)
        s12 = _window_summary(_right_window5(cost, index, y1, x0 + 1, d), x0 + 1, d, True, candidates)
        s13 = _window_summary(_right_window5(cost, index, y1, x0 + 2, d), x0 + 2, d, True, candidates)
        prev_d = d
        q02, q03, q12, q13 = s02, s03, s12, s13
        least_out_r = _patch_reliable4(s01, s02, s11, s12)
        if least_out_r < 0.0:
            _write_patch(out, y0, u0, UNDECIDED, UNDECIDED, UNDECIDED, UNDECIDED)
            continue
        r00 = _right_decision(s00, d, least_out_r)
        r01 = _right_decision(s01, d, least_out_r)
        r02 = _right_decision(s02, d, least_out_r)
        r03 = _right_decision(s03, d, least_out_r)
        r10 = _right_decision(s10, d, least_out_r)
        r11 = _right_decision(s11, d, least_out_r)
        r12 = _right_decision(s12, d, least_out_r)
        r13 = _right_decision(s13, d, least_out_r)
        _write_patch(out, y0, u0,
                     _inherit_pixel_prc(l00, sl00, u0, d, x0, least_out_l, r00, r01, r02, r03,
                                        candidates),
                     _inherit_pixel_prc(l01, sl01, u0 + 1, d, x0, least_out_l, r00, r01, r02, r03,
                                        candidates),
                     _inherit_pixel_prc(l10, sl10, u0, d, x0, least_out_l, r10, r11, r12, r13,
                                        candidates),
                     _inherit_pixel_prc(l11, sl11, u0 + 1, d, x0, least_out_l, r10, r11, r12, r13,
                                        candidates))


@njit(cache=True, error_model="numpy", inline="always")
def _write_patch(out, v, u, o00, o01, o10, o11):
    """The (up to four) fine pixels of the patch at (u, v) (a patch of the last row or
    column may be cut by the border), as :func:`pixel.inherit_patch_into`."""
    out[v, u] = o00
    if u + 1 < out.shape[1]:
        out[v, u + 1] = o01
    if v + 1 < out.shape[0]:
        out[v + 1, u] = o10
        if u + 1 < out.shape[1]:
            out[v + 1, u + 1] = o11
