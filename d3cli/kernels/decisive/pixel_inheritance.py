"""Per-pixel functions of the disparity inheritance (paper Algorithm 2, eq. 6-8): the
per-patch form the drivers run, each cell read once.  The literal per-pixel form of eq.
6-8, which the tests hold it to, is a test reference (``tests/reference/inheritance.py``).
Compiled for every target by :func:`build` (composed by :func:`d3cli.kernels.ops.build_ops`)."""

from __future__ import annotations

from types import SimpleNamespace

from ..pixel import INF, UINT, UNDECIDED


# Over 80 lines by design, as every step's factory (see d3cli.kernels.ops.build_ops).
def build(jit, shared):
    """``candidate_range, window5, band_cell, right_window5, pick5, window_best, window_summary, patch_reliable4, pixel_decisive5, inherit_pixel5, inherit_quad, inherit_patch_into`` compiled with ``jit`` (the protocol: :func:`d3cli.kernels.ops.build_ops`)."""
    cost_or_inf = shared.cost_or_inf
    right_cost_or_inf = shared.right_cost_or_inf

    @jit
    def candidate_range(x, d, right_view, candidates):
        """In-patch candidate disparities ``lo <= s < hi`` of the patch pixel in column x.

        ``candidates`` 0 (symmetric): {d-1, d, d+1} for every pixel.  1 (paper eq. 6-7 read
        literally): the two co-row partners only; with u0 and x0 = u0 - d both even, the
        left pixel in patch column a = x & 1 gets {d-1+a, d+a}, the right pixel in column
        b = x & 1 gets {d-b, d+1-b}.
        """
        if candidates == 0:
            return d - 1, d + 2
        s = 1 - (x & 1) if right_view else x & 1
        return d - 1 + s, d + 1 + s


    # ------------------------------------------------------------------ inheritance, per patch
    # Every cell the literal per-pixel tests of eq. 6-8 read for one pixel lies in d-2..d+2
    # (in-patch d-1..d+1, outside d-2 and d+2, the best's neighbours best +- 1).  The
    # functions below read those five cells once per pixel and view (one index entry and
    # one band test for the left view) and decide from them, with the same comparisons in
    # the same order as the literal form (tests/reference/inheritance.py), so the
    # decisions are the same (tests/kernels/decisive/test_inheritance.py holds them to each
    # other on random banded volumes).  The literal form re-reads every cell up to three
    # times.

    @jit
    def window5(cost, index, v, u, d):
        """``C(u, v, d - 2 + k)`` for k = 0..4 as five float64 (inf where a cell is missing)."""
        if v < 0 or v >= index.shape[0] or u < 0 or u >= index.shape[1]:
            return INF, INF, INF, INF, INF
        vu = UINT(v)
        uu = UINT(u)
        off = index[vu, uu, 0]
        lo = index[vu, uu, 1]
        hi = index[vu, uu, 2]
        s0 = d - 2
        if s0 >= lo and s0 + 5 <= hi:  # the whole window inside the band: one test
            b = UINT(off + s0)
            return float(cost[b]), float(cost[b + 1]), float(cost[b + 2]), float(cost[b + 3]), float(cost[b + 4])
        c0 = float(cost[UINT(off + s0)]) if lo <= s0 < hi else INF
        c1 = float(cost[UINT(off + s0 + 1)]) if lo <= s0 + 1 < hi else INF
        c2 = float(cost[UINT(off + s0 + 2)]) if lo <= s0 + 2 < hi else INF
        c3 = float(cost[UINT(off + s0 + 3)]) if lo <= s0 + 3 < hi else INF
        c4 = float(cost[UINT(off + s0 + 4)]) if lo <= s0 + 4 < hi else INF
        return c0, c1, c2, c3, c4


    @jit
    def band_cell(cost, index, vu, uu, s):
        """``C(u, v, s)`` of a pixel known to be in the image (unsigned subscripts), inf
        outside its band."""
        if s < index[vu, uu, 1] or s >= index[vu, uu, 2]:
            return INF
        return float(cost[UINT(index[vu, uu, 0] + s)])


    @jit
    def right_window5(cost, index, v, x, d):
        """Right-view ``C_R(x, v, d - 2 + k) = C_L(x + d - 2 + k, v, d - 2 + k)``, k = 0..4."""
        u = x + d - 2
        if 0 <= v < index.shape[0] and u >= 0 and u + 4 < index.shape[1]:
            # the five left pixels are in the image: one test for all of them
            vu = UINT(v)
            uu = UINT(u)
            return (band_cell(cost, index, vu, uu, d - 2), band_cell(cost, index, vu, uu + UINT(1), d - 1),
                    band_cell(cost, index, vu, uu + UINT(2), d), band_cell(cost, index, vu, uu + UINT(3), d + 1),
                    band_cell(cost, index, vu, uu + UINT(4), d + 2))
        return (
            float(cost_or_inf(cost, index, v, u, d - 2)),
            float(cost_or_inf(cost, index, v, u + 1, d - 1)),
            float(cost_or_inf(cost, index, v, u + 2, d)),
            float(cost_or_inf(cost, index, v, u + 3, d + 1)),
            float(cost_or_inf(cost, index, v, u + 4, d + 2)),
        )


    @jit
    def pick5(c, k):
        """``c[k]`` of a five-cell window (constant subscripts only: every backend compiles them)."""
        if k == 0:
            return c[0]
        if k == 1:
            return c[1]
        if k == 2:
            return c[2]
        if k == 3:
            return c[3]
        return c[4]


    @jit
    def window_best(c, lo_k, hi_k):
        """Least of ``c[lo_k:hi_k]``, the first on ties: (k, cost), or (-1, inf) when all are inf."""
        best_k = -1
        best_c = INF
        for k in range(lo_k, hi_k):
            ck = pick5(c, k)
            if ck < best_c:
                best_c = ck
                best_k = k
        return best_k, best_c


    @jit
    def window_summary(c, x, d, right_view, candidates):
        """What the tests need of one pixel's window ``c`` (at (x, d), either view), in
        one go: ``(best_k, best_c, out_c, local_min)``.

        ``best_k, best_c``: the least in-patch cell (:func:`window_best`; the disparity
        is d - 2 + best_k); ``out_c``: the least outside cell (:func:`outside_cost`);
        ``local_min``: C(best) < C(best - 1) and C(best) < C(best + 1) (eq. 8).  The
        patch test and the pixel test of the same pixel share it.
        """
        lo, hi = candidate_range(x, d, right_view, candidates)
        lo_k = lo - d + 2
        hi_k = hi - d + 2
        best_k, best_c = window_best(c, lo_k, hi_k)
        out_c = min(pick5(c, lo_k - 1), pick5(c, hi_k))
        # tested at every candidate and the best's result kept (& instead of branches:
        # which candidate is best is data)
        local_min = False
        for k in range(lo_k, hi_k):
            ck = pick5(c, k)
            local_min |= (k == best_k) & (ck < pick5(c, k - 1)) & (ck < pick5(c, k + 1))
        return best_k, best_c, out_c, local_min


    @jit
    def patch_reliable4(s00, s01, s10, s11):
        """:func:`patch_reliable` from the four pixels' :func:`window_summary` (row b,
        column a: ``s_ba``), summed and compared in the same order."""
        sum_in = 0.0
        sum_in += s00[1]
        sum_in += s01[1]
        sum_in += s10[1]
        sum_in += s11[1]
        least_out = min(INF, s00[2])
        least_out = min(least_out, s01[2])
        least_out = min(least_out, s10[2])
        least_out = min(least_out, s11[2])
        if sum_in * 0.25 < least_out:
            return least_out
        return -1.0


    @jit
    def pixel_decisive5(c, summary, x, d, right_view, prc, least_out, dfm_pkrn_min, epsilon, candidates):
        """:func:`pixel_decisive` from the pixel's window ``c`` (:func:`window5` or
        :func:`right_window5` at (x, d)) and its :func:`window_summary`."""
        best_k = summary[0]
        best_c = summary[1]
        if best_k < 0 or best_c >= 1.0:
            return UNDECIDED
        if prc:
            if summary[3] and best_c < least_out:
                return d - 2 + best_k
            return UNDECIDED
        lo, hi = candidate_range(x, d, right_view, candidates)
        second = INF
        for k in range(lo - d + 2, hi - d + 2):
            if k != best_k:
                second = min(second, pick5(c, k))
        if second + epsilon >= dfm_pkrn_min * (best_c + epsilon):
            return d - 2 + best_k
        return UNDECIDED


    @jit
    def inherit_pixel5(cost, index, v, u, d, x0, left, left_s, right0, right0_s, right1, right1_s, least_out_l,
                       least_out_r, prc, dfm_pkrn_min, epsilon, candidates):
        """:func:`inherit_pixel` for fine pixel (u, v) from its left window and summary and
        those of the right pixels x0, x0 + 1 of the patch row; a matched right pixel outside
        those two columns reads its own window."""
        dl = pixel_decisive5(left, left_s, u, d, False, prc, least_out_l, dfm_pkrn_min, epsilon, candidates)
        if dl < 0:
            return UNDECIDED
        x = u - dl
        if x == x0:
            right = right0
            right_s = right0_s
        elif x == x0 + 1:
            right = right1
            right_s = right1_s
        else:
            right = right_window5(cost, index, v, x, d)
            right_s = window_summary(right, x, d, True, candidates)
        dr = pixel_decisive5(right, right_s, x, d, True, prc, least_out_r, dfm_pkrn_min, epsilon, candidates)
        if dr != dl:
            return UNDECIDED
        return dl


    @jit
    def inherit_quad(cost, index, coarse, pv, pu, prc, dfm_pkrn_min, epsilon, candidates):
        """Inherited disparities of the four fine pixels of coarse pixel (pu, pv).

        :func:`inherit_patch` and :func:`inherit_pixel` for the 2x2 patch, each cell read
        once and each window summarised once (:func:`window_summary`) for the patch and
        the pixel tests.  Returns ``(o00, o01, o10, o11)``, ``o_ba`` for the fine pixel
        (2 pu + a, 2 pv + b); a pixel outside the image gets a value too (the drivers do
        not store it).
        """
        if pv >= coarse.shape[0] or pu >= coarse.shape[1]:
            return UNDECIDED, UNDECIDED, UNDECIDED, UNDECIDED
        dc = coarse[pv, pu]
        if dc < 0:
            return UNDECIDED, UNDECIDED, UNDECIDED, UNDECIDED
        d = 2 * dc
        y0 = 2 * pv
        u0 = 2 * pu
        x0 = u0 - d
        l00 = window5(cost, index, y0, u0, d)
        l01 = window5(cost, index, y0, u0 + 1, d)
        l10 = window5(cost, index, y0 + 1, u0, d)
        l11 = window5(cost, index, y0 + 1, u0 + 1, d)
        sl00 = window_summary(l00, u0, d, False, candidates)
        sl01 = window_summary(l01, u0 + 1, d, False, candidates)
        sl10 = window_summary(l10, u0, d, False, candidates)
        sl11 = window_summary(l11, u0 + 1, d, False, candidates)
        least_out_l = INF
        least_out_r = INF
        if prc:
            least_out_l = patch_reliable4(sl00, sl01, sl10, sl11)
            if least_out_l < 0.0:
                return UNDECIDED, UNDECIDED, UNDECIDED, UNDECIDED
        r00 = right_window5(cost, index, y0, x0, d)
        r01 = right_window5(cost, index, y0, x0 + 1, d)
        r10 = right_window5(cost, index, y0 + 1, x0, d)
        r11 = right_window5(cost, index, y0 + 1, x0 + 1, d)
        sr00 = window_summary(r00, x0, d, True, candidates)
        sr01 = window_summary(r01, x0 + 1, d, True, candidates)
        sr10 = window_summary(r10, x0, d, True, candidates)
        sr11 = window_summary(r11, x0 + 1, d, True, candidates)
        if prc:
            least_out_r = patch_reliable4(sr00, sr01, sr10, sr11)
            if least_out_r < 0.0:
                return UNDECIDED, UNDECIDED, UNDECIDED, UNDECIDED
        o00 = inherit_pixel5(cost, index, y0, u0, d, x0, l00, sl00, r00, sr00, r01, sr01, least_out_l, least_out_r,
                             prc, dfm_pkrn_min, epsilon, candidates)
        o01 = inherit_pixel5(cost, index, y0, u0 + 1, d, x0, l01, sl01, r00, sr00, r01, sr01, least_out_l,
                             least_out_r, prc, dfm_pkrn_min, epsilon, candidates)
        o10 = inherit_pixel5(cost, index, y0 + 1, u0, d, x0, l10, sl10, r10, sr10, r11, sr11, least_out_l,
                             least_out_r, prc, dfm_pkrn_min, epsilon, candidates)
        o11 = inherit_pixel5(cost, index, y0 + 1, u0 + 1, d, x0, l11, sl11, r10, sr10, r11, sr11, least_out_l,
                             least_out_r, prc, dfm_pkrn_min, epsilon, candidates)
        return o00, o01, o10, o11


    @jit
    def inherit_patch_into(out, cost, index, coarse, pv, pu, prc, dfm_pkrn_min, epsilon, candidates):
        """:func:`inherit_quad` of the coarse pixel (pu, pv) written to the (up to four)
        fine pixels of its patch in ``out`` (int32 (H, W)): the one write the CPU and the
        CUDA drivers share (a patch of the last row or column may be cut by the border)."""
        h = out.shape[0]
        w = out.shape[1]
        v = 2 * pv
        u = 2 * pu
        o00, o01, o10, o11 = inherit_quad(cost, index, coarse, pv, pu, prc, dfm_pkrn_min, epsilon, candidates)
        out[v, u] = o00
        if u + 1 < w:
            out[v, u + 1] = o01
        if v + 1 < h:
            out[v + 1, u] = o10
            if u + 1 < w:
                out[v + 1, u + 1] = o11


    return SimpleNamespace(
        candidate_range=candidate_range,
        window5=window5,
        band_cell=band_cell,
        right_window5=right_window5,
        pick5=pick5,
        window_best=window_best,
        window_summary=window_summary,
        patch_reliable4=patch_reliable4,
        pixel_decisive5=pixel_decisive5,
        inherit_pixel5=inherit_pixel5,
        inherit_quad=inherit_quad,
        inherit_patch_into=inherit_patch_into,
    )
