"""The literal per-pixel form of inheritance (paper Algorithm 2, eq. 6-8), the reference
the kernels' per-patch form (``inherit_quad``, ``d3cli/kernels/decisive/pixel_inheritance.py``)
is held to: every candidate, outside cost and pixel test read from the volume as the
equations state it, cell by cell.

:func:`build_literal` compiles it with the same ``jit`` as the kernels' namespace ``ops``
(``d3cli.kernels.ops.build_ops(jit)``) and calls that namespace's shared helpers and
``candidate_range``; with ``jit`` the identity it runs as plain Python.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

UNDECIDED = -1
INF = math.inf


def build_literal(jit, ops):
    """``best_of_three, outside_cost, patch_reliable, pixel_decisive, inherit_patch,
    inherit_pixel, inherit_at`` compiled with ``jit``, over the per-pixel functions ``ops``
    (built with the same ``jit``)."""
    cost_or_inf = ops.cost_or_inf
    right_cost_or_inf = ops.right_cost_or_inf
    candidate_range = ops.candidate_range

    @jit
    def best_of_three(cost, index, v, x, d, right_view, candidates):
        """Least cost among the in-patch candidates at (x, v) (smaller disparity on ties).

        The candidates are d-1, d, d+1, or two of them (:func:`candidate_range`).
        ``right_view`` selects the right-view cost C_R(x, v, .) instead of C_L.
        Returns (disparity, cost); (-1, inf) when none of the cells exists.
        """
        best_d = UNDECIDED
        best_c = INF
        lo, hi = candidate_range(x, d, right_view, candidates)
        for s in range(lo, hi):
            if right_view:
                c = right_cost_or_inf(cost, index, v, x, s)
            else:
                c = cost_or_inf(cost, index, v, x, s)
            if c < best_c:
                best_c = c
                best_d = s
        return best_d, best_c


    @jit
    def outside_cost(cost, index, v, x, d, right_view, candidates):
        """Least cost at the 'outside' disparities (the G sets of eq. 6), lo - 1 and hi of
        :func:`candidate_range`: d - 2 and d + 2, or with ``candidates`` 1 the two pixels
        just beside the partner patch ({d-2, d+1} or {d-1, d+2})."""
        lo, hi = candidate_range(x, d, right_view, candidates)
        if right_view:
            return min(right_cost_or_inf(cost, index, v, x, lo - 1), right_cost_or_inf(cost, index, v, x, hi))
        return min(cost_or_inf(cost, index, v, x, lo - 1), cost_or_inf(cost, index, v, x, hi))


    @jit
    def patch_reliable(cost, index, y0, x0, d, right_view, candidates):
        """Patch reliability constraint (PRC, paper eq. 6-7) in one view.

        The 2x2 patch at rows y0, y0+1 and columns x0, x0+1 of the chosen view (the left
        patch for the left view, the right patch for the right view), with the
        in-patch disparities {d-1, d, d+1} (d = 2 dc, the coarse disparity doubled) and the
        outside disparities {d-2, d+2} of the pixels just beside the partner patch
        (``candidates`` 1: the per-pixel sets of :func:`candidate_range`).  The
        patch is reliable when the mean of the four best in-patch costs is below the least
        outside cost.  Returns that least outside cost, or -1 when the patch is unreliable.
        """
        sum_in = 0.0
        least_out = INF
        for b in range(2):
            for a in range(2):
                c_in = best_of_three(cost, index, y0 + b, x0 + a, d, right_view, candidates)[1]
                sum_in += c_in
                least_out = min(least_out, outside_cost(cost, index, y0 + b, x0 + a, d, right_view, candidates))
        if sum_in * 0.25 < least_out:
            return least_out
        return -1.0


    @jit
    def pixel_decisive(cost, index, v, x, d, right_view, prc, least_out, dfm_pkrn_min, epsilon, candidates):
        """Best in-patch disparity of one pixel if it passes the pixel test, else -1.

        With ``prc``: local minimum C(d*) < C(d* +- 1) and below the patch's least outside
        cost (eq. 8).  Without (DFM-style ablation): PKRN of the best against the second
        best in-patch cost >= dfm_pkrn_min.
        """
        best_d, best_c = best_of_three(cost, index, v, x, d, right_view, candidates)
        if best_d < 0 or best_c >= 1.0:
            return UNDECIDED
        if prc:
            if right_view:
                lo = right_cost_or_inf(cost, index, v, x, best_d - 1)
                hi = right_cost_or_inf(cost, index, v, x, best_d + 1)
            else:
                lo = cost_or_inf(cost, index, v, x, best_d - 1)
                hi = cost_or_inf(cost, index, v, x, best_d + 1)
            if best_c < lo and best_c < hi and best_c < least_out:
                return best_d
            return UNDECIDED
        second = INF
        lo, hi = candidate_range(x, d, right_view, candidates)
        for s in range(lo, hi):
            if s != best_d:
                if right_view:
                    c = right_cost_or_inf(cost, index, v, x, s)
                else:
                    c = cost_or_inf(cost, index, v, x, s)
                second = min(second, c)
        if second + epsilon >= dfm_pkrn_min * (best_c + epsilon):
            return best_d
        return UNDECIDED


    @jit
    def inherit_patch(cost, index, coarse, pv, pu, prc, candidates):
        """Patch part of inheritance (eq. 6-7) for the coarse pixel (pu, pv).

        Returns ``(d, least_out_l, least_out_r)``: ``d = 2 dc`` the doubled coarse
        disparity and the least outside costs of the left and the right patch, or
        ``d = -1`` when the coarse pixel is undecided or (with ``prc``) a patch is
        unreliable.  The four fine pixels of the patch share it (:func:`inherit_pixel`).
        """
        if pv >= coarse.shape[0] or pu >= coarse.shape[1]:
            return UNDECIDED, INF, INF
        dc = coarse[pv, pu]
        if dc < 0:
            return UNDECIDED, INF, INF
        d = 2 * dc
        y0 = 2 * pv
        u0 = 2 * pu
        x0 = u0 - d
        least_out_l = INF
        least_out_r = INF
        if prc:
            least_out_l = patch_reliable(cost, index, y0, u0, d, False, candidates)
            if least_out_l < 0.0:
                return UNDECIDED, INF, INF
            least_out_r = patch_reliable(cost, index, y0, x0, d, True, candidates)
            if least_out_r < 0.0:
                return UNDECIDED, INF, INF
        return d, least_out_l, least_out_r


    @jit
    def inherit_pixel(cost, index, v, u, d, least_out_l, least_out_r, prc, dfm_pkrn_min, epsilon, candidates):
        """Pixel part of inheritance (eq. 8) for fine pixel (u, v) of a patch that passed
        :func:`inherit_patch` with ``(d, least_out_l, least_out_r)``; bidirectional as in
        LRDC: the matched right pixel must pass its own test with the same disparity."""
        dl = pixel_decisive(cost, index, v, u, d, False, prc, least_out_l, dfm_pkrn_min, epsilon, candidates)
        if dl < 0:
            return UNDECIDED
        dr = pixel_decisive(cost, index, v, u - dl, d, True, prc, least_out_r, dfm_pkrn_min, epsilon, candidates)
        if dr != dl:
            return UNDECIDED
        return dl


    @jit
    def inherit_at(cost, index, coarse, v, u, prc, dfm_pkrn_min, epsilon, candidates):
        """Inherited disparity of fine pixel (u, v) from the coarser map, or UNDECIDED.

        Paper Algorithm 2, eq. 6-8.  The coarse pixel (u//2, v//2) with disparity dc maps
        to the 2x2 left patch at columns u0 = 2(u//2) + {0, 1} and the right patch at
        x0 = u0 - 2 dc + {0, 1}; co-row partners give the in-patch disparities
        {2dc - 1, 2dc, 2dc + 1} and the pixels just beside the partner patch the outside
        disparities {2dc - 2, 2dc + 2}.  With ``prc`` the patch must pass the patch
        reliability constraint in both views and the pixel the local-minimum constraint
        (:func:`pixel_decisive`); without, the DFM-style PKRN test.  This is
        :func:`inherit_patch` and :func:`inherit_pixel` composed for one pixel, the
        literal form; the drivers run :func:`inherit_quad`, which decides the same per
        patch with each cell read once (tests/kernels/decisive/test_inheritance.py).
        ``candidates`` 1 replaces the symmetric sets by the per-pixel sets of eq. 6-7 read literally (:func:`candidate_range`).
        """
        d, least_out_l, least_out_r = inherit_patch(cost, index, coarse, v // 2, u // 2, prc, candidates)
        if d < 0:
            return UNDECIDED
        return inherit_pixel(cost, index, v, u, d, least_out_l, least_out_r, prc, dfm_pkrn_min, epsilon, candidates)

    return SimpleNamespace(
        best_of_three=best_of_three,
        outside_cost=outside_cost,
        patch_reliable=patch_reliable,
        pixel_decisive=pixel_decisive,
        inherit_patch=inherit_patch,
        inherit_pixel=inherit_pixel,
        inherit_at=inherit_at,
    )
