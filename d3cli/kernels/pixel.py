"""Per-pixel math of D3Stereo, written once and compiled for every backend.

``build_ops(jit)`` returns a namespace of functions compiled with ``jit``:
``numba.njit`` for the CPU (``kernels/cpu.py``) and ``numba.cuda.jit(device=True)``
for CUDA (``kernels/cuda.py``).  The same Python source is compiled twice, so the two
backends cannot drift apart.  (Calling an ``@njit`` function from a CUDA kernel fails
in the CUDA simulator, hence the factory rather than shared dispatchers.)

Rules for everything in here: arguments are arrays, indices and scalars; results are
scalars; no allocation, no exceptions, no Python objects.  Scratch memory and loops over
the image belong to the drivers.

Conventions (DESIGN.md section 1)
---------------------------------
* A cost volume is a pair ``(cost, index)``: ``cost`` a flat float32 array, ``index``
  an int32 (H, W, 3) array ``[off, lo, hi]`` per pixel; the pixel (u, v) holds the
  disparities ``lo <= d < hi`` (its *band*) at ``cost[off + d]``.  The full-range volume
  is the band ``[0, D)`` everywhere with ``off = (v W + u) D``: exactly the (H, W, D)
  array, disparity innermost (:mod:`d3cli.kernels.volume`).  Fine pyramid levels store
  only a band around what the coarser level decided (issue 10; :mod:`d3cli.method.band`).
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


def build_ops(jit):
    """Compile the per-pixel functions with ``jit`` and return them in a namespace.

    Parameters
    ----------
    jit : callable
        A decorator such as ``numba.njit(cache=True)`` or ``numba.cuda.jit(device=True)``.

    Returns
    -------
    types.SimpleNamespace
        ``ncc_cost, cosine_cost, box_sum, cost_or_inf, right_cost_or_inf, rbf_weight, seed_at,
        diffuse_at, inherit_patch, inherit_pixel, inherit_at, inherit_quad, subpixel_at,
        pt_shift, bilinear_at, pt_restore_at`` and the helpers they use.  The drivers
        inherit with :func:`inherit_quad` (one 2x2 patch, each cell read once); the
        per-pixel form :func:`inherit_at` states eq. 7-9 literally and the tests hold
        the two to each other.
    """

    @jit
    def ncc_cost(n, sl, sll, sr, srr, slr, min_variance):
        """Matching cost ``(1 - NCC) / 2`` from window sums (DESIGN step 2).

        ``n`` pixels; ``sl, sll`` sums of L and L^2; ``sr, srr`` of R and R^2; ``slr`` of
        L*R (float64).  A window whose grey-level variance is <= ``min_variance`` is flat:
        NCC is undefined there, cost 1.
        """
        if n <= 0:
            return 1.0
        inv = 1.0 / n
        ml = sl * inv
        mr = sr * inv
        vl = sll * inv - ml * ml
        vr = srr * inv - mr * mr
        if vl <= min_variance or vr <= min_variance:
            return 1.0
        ncc = (slr * inv - ml * mr) / math.sqrt(vl * vr)
        if ncc > 1.0:
            ncc = 1.0
        elif ncc < -1.0:
            ncc = -1.0
        return 0.5 * (1.0 - ncc)

    @jit
    def cosine_cost(fl, fr, nl, nr, v, u, d):
        """Feature cost ``(1 - cos(f_L(u, v), f_R(u - d, v))) / 2`` (paper section III-A).

        ``fl, fr`` are (H, W, C) L2-normalised feature maps of the level and ``nl, nr``
        their (H, W) squared norms (1, or 0 where a feature vector is zero: "flat", cost
        1 like a flat NCC window).  ``u - d < 0`` costs 1.  Accumulated in float64.
        """
        x = u - d
        if x < 0 or nl[v, u] <= 0.0 or nr[v, x] <= 0.0:
            return 1.0
        dot = 0.0
        for c in range(fl.shape[2]):
            dot += float(fl[v, u, c]) * float(fr[v, x, c])
        if dot > 1.0:
            dot = 1.0
        elif dot < -1.0:
            dot = -1.0
        return 0.5 * (1.0 - dot)

    @jit
    def box_sum(ii, r0, c0, r1, c1):
        """Sum of rows r0..r1, columns c0..c1 (inclusive) from an (H+1, W+1) integral image."""
        return ii[r1 + 1, c1 + 1] - ii[r0, c1 + 1] - ii[r1 + 1, c0] + ii[r0, c0]

    @jit
    def ncc_window_cost(ii_l, ii_ll, ii_r, ii_rr, v0, v1, c0, c1, d, slr, min_variance):
        """Cost of a window clipped to rows v0..v1 and columns c0..c1 (right: c - d).

        The left and right sums come from the (H+1, W+1) integral images of L, L^2, R and
        R^2; ``slr`` is the window sum of L*R, which each driver keeps its own way.
        """
        n = (v1 - v0 + 1) * (c1 - c0 + 1)
        sl = box_sum(ii_l, v0, c0, v1, c1)
        sll = box_sum(ii_ll, v0, c0, v1, c1)
        sr = box_sum(ii_r, v0, c0 - d, v1, c1 - d)
        srr = box_sum(ii_rr, v0, c0 - d, v1, c1 - d)
        return ncc_cost(n, sl, sll, sr, srr, slr, min_variance)

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
    def rbf_weight(dy, dx, i_p, i_q, inv_sigma_space2, inv_sigma_color2):
        """Bilateral kernel K(p, q) of paper eq. 3 (unnormalised)."""
        di = i_p - i_q
        return math.exp(-(dy * dy + dx * dx) * inv_sigma_space2 - di * di * inv_sigma_color2)

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
    def seed_candidate(cost, index, v, u, pkrn_min, epsilon, exclusion):
        """Test (a) of :func:`seed_at`: the WTA disparity d1 of (u, v) when its PKRN passes
        and its match u - d1 lies in the image, else UNDECIDED.

        The least cost c1 and the second cost c2 are found by value (:func:`least_two`,
        :func:`least`), and d1 as the first disparity holding c1: the smallest on ties,
        as a scan with a strict ``<`` finds it.  Issue 10: the in-order scan waited a
        compare and a select per cell; KITTI finest level, 1 thread (CPU time), A/B on
        the pipeline's inputs: seeds 17.6 -> 12.3 ms.  (Cells are never NaN: the costs
        lie in [0, 1].)
        """
        off = index[v, u, 0]
        lo = index[v, u, 1]
        hi = index[v, u, 2]
        if hi <= lo:
            return UNDECIDED
        base = UINT(off + lo)
        if exclusion == 0:
            # naive PKRN: c2 is the least cost at any other disparity
            c1, c2 = least_two(cost, base, hi - lo)
            if c1 >= 1.0 or c2 == INF or c2 + epsilon < pkrn_min * (c1 + epsilon):
                return UNDECIDED
            d1 = lo + first_at(cost, base, c1)
        else:
            c1 = least(cost, base, hi - lo)
            if c1 >= 1.0:
                return UNDECIDED
            d1 = lo + first_at(cost, base, c1)
            # c2: the least cost farther than ``exclusion`` from d1, on either side
            below = d1 - exclusion - lo  # the cells lo .. d1 - exclusion - 1
            above = d1 + exclusion + 1  # the cells d1 + exclusion + 1 .. hi - 1
            c2 = least(cost, base, below)
            if above < hi:
                c2 = min(c2, least(cost, UINT(off + above), hi - above))
            if c2 == INF or c2 + epsilon < pkrn_min * (c1 + epsilon):
                return UNDECIDED
        if u - d1 < 0:
            return UNDECIDED  # the match lies outside the right image
        return d1

    @jit
    def right_wta(cost, index, n_disp, v, x):
        """The right view's winner-take-all at (x, v): the d of least ``C_L(x + d, v, d)``
        over the disparities below ``n_disp`` whose cell exists (the smallest on ties; 0
        when there is none)."""
        # x + d stays in the image (d < width - x), so no bounds test per cell (cost_or_inf's)
        vu = UINT(v)
        dr = 0
        cr = INF
        for d in range(min(n_disp, index.shape[1] - x)):
            xu = UINT(x + d)
            if index[vu, xu, 1] <= d < index[vu, xu, 2]:
                c = cost[UINT(index[vu, xu, 0] + d)]
                better = c < cr
                dr = d if better else dr
                cr = c if better else cr
        return dr

    @jit
    def seed_at(cost, index, n_disp, v, u, pkrn_min, epsilon, lr_tolerance, exclusion):
        """Decisive seed at (u, v) of the coarsest level, or UNDECIDED (DESIGN step 4).

        Winner-take-all ``d1`` (smallest disparity on ties) is kept when
        (a) PKRN = (c2 + eps) / (c1 + eps) >= pkrn_min, where c2 is the least cost at any
        disparity farther than ``exclusion`` from d1 (``exclusion = 0``: the naive peak
        ratio), and (b) the right view's WTA at (u - d1, v) is within ``lr_tolerance``.
        A cost of 1 (invalid or flat) never yields a seed.  Only the pixel's band is
        searched; the right view looks at every disparity below ``n_disp`` (the level's
        range) whose cell exists.  (a) is :func:`seed_candidate`, (b) :func:`right_wta`.
        """
        d1 = seed_candidate(cost, index, v, u, pkrn_min, epsilon, exclusion)
        if d1 == UNDECIDED:
            return UNDECIDED
        if abs(right_wta(cost, index, n_disp, v, u - d1) - d1) > lr_tolerance:
            return UNDECIDED
        return d1

    @jit
    def accept_state(cost, index, v, u, s, c):
        """Hypotheses (2) and (3) of the diffusion for candidate ``s`` of cost ``c``.

        (2) local minimum of the cost curve: C(p, s) < C(p, s - 1), C(p, s + 1);
        (3) right-view consistency: the matched right pixel (u - s, v) is not matched
        better by its neighbours along its own disparity line,
        C(p, s) < C((u - 1, v), s - 1) and C(p, s) < C((u + 1, v), s + 1).
        """
        if c >= 1.0:
            return False
        if not (c < cost_or_inf(cost, index, v, u, s - 1) and c < cost_or_inf(cost, index, v, u, s + 1)):
            return False
        if not (c < cost_or_inf(cost, index, v, u - 1, s - 1) and c < cost_or_inf(cost, index, v, u + 1, s + 1)):
            return False
        return True

    @jit
    def band_min(cost, index, v, u):
        """Least cost of pixel (u, v) over its band, which is not empty."""
        lo = index[v, u, 1]
        return least(cost, UINT(index[v, u, 0] + lo), index[v, u, 2] - lo)

    @jit
    def holds_own_disparity(cost, index, v, u, d):
        """True when :func:`diffuse_at` with ``tau = 1`` keeps disparity d at pixel (u, v)
        whose decided neighbours all hold d: their one candidate set is d - 1, d, d + 1
        (those in the band), and d wins it when it lies in the band, costs less than d - 1 and no
        more than d + 1 (ties go to the smaller disparity).  False (a neighbouring
        disparity wins, d outside the band, a NaN cost) says nothing.
        """
        off = index[v, u, 0]
        lo = index[v, u, 1]
        hi = index[v, u, 2]
        if d < lo or d >= hi:
            return False
        c = cost[UINT(off + d)]
        below = d - 1 < lo or c < cost[UINT(off + d - 1)]
        above = d + 1 >= hi or c <= cost[UINT(off + d + 1)]
        return below and above

    @jit
    def diffuse_at(cost, index, disp, min_cost, max_gap, v, u, tau, kappa_d, adversarial):
        """New state of pixel (u, v) in one Jacobi diffusion sweep (paper eq. 5-6).

        The candidates are ``D(q) + r`` for every decided neighbour q within radius
        ``kappa_d`` (p itself excluded) and r in [-tau, tau]; the state ``s`` is the
        candidate of least cost (smaller disparity on ties).  An undecided pixel takes
        ``s`` when it passes hypotheses (2)-(3); a decided pixel switches to ``s`` only in
        the adversarial mode and only when s also costs strictly less than its current
        disparity (eq. 6).  Reads ``disp`` (the previous sweep) only.

        Near-optimality (``max_gap >= 0``; an addition to the paper, see
        ``DiffusionConfig.max_gap``): the accepted state must also cost at most
        ``min_cost[v, u] + max_gap``, ``min_cost`` being the pixel's least cost over all
        disparities (an empty ``min_cost``: :func:`band_min`, here).  On noisy NCC cost curves almost every disparity is some local
        minimum, and without this test diffusion walks from a foreground edge deep into
        the background one +-1 step at a time.
        """
        height = disp.shape[0]
        width = disp.shape[1]
        off = index[v, u, 0]
        lo = index[v, u, 1]
        hi = index[v, u, 2]
        cur = disp[v, u]
        best_s = UNDECIDED
        best_c = INF
        last_q = UNDECIDED
        for dv in range(-kappa_d, kappa_d + 1):
            y = v + dv
            if y < 0 or y >= height:
                continue
            for du in range(-kappa_d, kappa_d + 1):
                x = u + du
                if x < 0 or x >= width or (dv == 0 and du == 0):
                    continue
                q = disp[UINT(y), UINT(x)]
                # Neighbours mostly share a disparity: a repeat of the previous one adds
                # no candidate (the arg-min does not depend on the order), so skip it.
                if q < 0 or q == last_q:
                    continue
                last_q = q
                for r in range(-tau, tau + 1):
                    s = q + r
                    if s < lo or s >= hi:
                        continue  # outside the band: the cell does not exist
                    c = cost[UINT(off + s)]
                    if c < best_c or (c == best_c and s < best_s):
                        best_c = c
                        best_s = s
        if best_s == UNDECIDED or best_s == cur:
            return cur
        if not accept_state(cost, index, v, u, best_s, best_c):
            return cur
        if max_gap >= 0.0:
            # an empty min_cost (the CPU driver's): the least cost is found here, only
            # for the pixels that get this far (issue 10: KITTI finest level, 13 % of
            # the first sweep's; the min_cost pass over the whole volume, 7 ms, is gone)
            least = min_cost[v, u] if min_cost.shape[0] > 0 else band_min(cost, index, v, u)
            if best_c > least + max_gap:
                return cur
        if cur < 0:
            return best_s
        if adversarial and best_c < cost_or_inf(cost, index, v, u, cur):
            return best_s
        return cur

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
        """Patch reliability constraint (PRC, paper eq. 7-8) in one view.

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
        cost (eq. 9).  Without (DFM-style ablation): PKRN of the best against the second
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
        """Patch part of inheritance (eq. 7-8) for the coarse pixel (pu, pv).

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
        """Pixel part of inheritance (eq. 9) for fine pixel (u, v) of a patch that passed
        :func:`inherit_patch` with ``(d, least_out_l, least_out_r)``; bidirectional as in
        LRDC: the matched right pixel must pass its own test with the same disparity."""
        dl = pixel_decisive(cost, index, v, u, d, False, prc, least_out_l, dfm_pkrn_min, epsilon, candidates)
        if dl < 0:
            return UNDECIDED
        dr = pixel_decisive(cost, index, v, u - dl, d, True, prc, least_out_r, dfm_pkrn_min, epsilon, candidates)
        if dr != dl:
            return UNDECIDED
        return dl

    # ------------------------------------------------------------------ inheritance, fast form
    # Every cell the tests above read for one pixel lies in d-2..d+2 (in-patch d-1..d+1,
    # outside d-2 and d+2, the best's neighbours best +- 1).  The functions below read those
    # five cells once per pixel and view (one index entry and one band test for the left
    # view) and decide from them, with the same comparisons in the same order as the
    # functions above, so the decisions are the same (tests/kernels/test_inheritance.py
    # holds them to each other on random banded volumes).  Issue 10: the per-pixel form
    # re-read every cell up to three times (road pair, level 1: 90 ms CPU).

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
        ``local_min``: C(best) < C(best - 1) and C(best) < C(best + 1) (eq. 9).  The
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

    @jit
    def inherit_at(cost, index, coarse, v, u, prc, dfm_pkrn_min, epsilon, candidates):
        """Inherited disparity of fine pixel (u, v) from the coarser map, or UNDECIDED.

        Paper Algorithm 2, eq. 7-9.  The coarse pixel (u//2, v//2) with disparity dc maps
        to the 2x2 left patch at columns u0 = 2(u//2) + {0, 1} and the right patch at
        x0 = u0 - 2 dc + {0, 1}; co-row partners give the in-patch disparities
        {2dc - 1, 2dc, 2dc + 1} and the pixels just beside the partner patch the outside
        disparities {2dc - 2, 2dc + 2}.  With ``prc`` the patch must pass the patch
        reliability constraint in both views and the pixel the local-minimum constraint
        (:func:`pixel_decisive`); without, the DFM-style PKRN test.  This is
        :func:`inherit_patch` and :func:`inherit_pixel` composed for one pixel, the
        literal form; the drivers run :func:`inherit_quad`, which decides the same per
        patch with each cell read once (tests/kernels/test_inheritance.py).  ``candidates`` 1 replaces the symmetric sets by
        the per-pixel sets of eq. 6-7 read literally (:func:`candidate_range`).
        """
        d, least_out_l, least_out_r = inherit_patch(cost, index, coarse, v // 2, u // 2, prc, candidates)
        if d < 0:
            return UNDECIDED
        return inherit_pixel(cost, index, v, u, d, least_out_l, least_out_r, prc, dfm_pkrn_min, epsilon, candidates)

    @jit
    def subpixel_at(cost, index, disp, v, u):
        """Sub-pixel disparity by a parabola through C(d-1), C(d), C(d+1) (DESIGN step 8).

        The offset is clamped to [-0.5, 0.5]; at the ends of the range or on a flat or
        concave curve the integer disparity is returned; inf where undecided.
        """
        d = disp[v, u]
        if d < 0:
            return INF
        c0 = cost_or_inf(cost, index, v, u, d - 1)
        c1 = cost_or_inf(cost, index, v, u, d)
        c2 = cost_or_inf(cost, index, v, u, d + 1)
        if c0 == INF or c1 == INF or c2 == INF:
            return float(d)  # an end of the range or of the band
        denom = c0 + c2 - 2.0 * c1
        if denom <= 0.0:
            return float(d)
        offset = 0.5 * (c0 - c2) / denom
        if offset > 0.5:
            offset = 0.5
        elif offset < -0.5:
            offset = -0.5
        return d + offset

    @jit
    def pt_shift(a0, b1, b2, delta, v, u):
        """Perspective-transformation shift ``s(u, v) = a0 + b1 v + b2 u - delta`` (DESIGN step 6).

        The road model ``d = a0 + a1 (v cos(theta) - u sin(theta))`` written linearly:
        ``b1 = a1 cos(theta)``, ``b2 = -a1 sin(theta)``; ``delta`` is the margin.  All in
        full-resolution pixels.
        """
        return a0 + b1 * v + b2 * u - delta

    @jit
    def bilinear_at(img, v, x):
        """Bilinear sample of row ``v`` of ``img`` (H, W) at real column ``x``.

        Outside [0, W - 1] the border sample is replicated.
        """
        w = img.shape[1]
        if x <= 0.0:
            return float(img[v, 0])
        if x >= w - 1:
            return float(img[v, w - 1])
        x0 = int(math.floor(x))
        t = x - x0
        return (1.0 - t) * img[v, x0] + t * img[v, x0 + 1]

    @jit
    def pt_restore_at(d_prime, a0, b1, b2, delta, v, u):
        """Full-range disparity of a left pixel from its disparity ``d_prime`` against the
        warped right image (DESIGN step 6).

        Left (u, v) matches ``R'(u - d', v) = R(u - d' - s(u - d', v), v)``, so
        ``d = d' + s(u - d', v) = d' (1 - b2) + s(u, v)``; inf stays inf.
        """
        if not d_prime < INF:
            return INF
        return d_prime * (1.0 - b2) + pt_shift(a0, b1, b2, delta, v, u)

    @jit
    def sgm_step(cost, index, v, u, prev, plo, phi, cur, p1, p2, acc, mode):
        """One pixel of one semi-global path over a banded volume (issue 16).

        ``L(p, d) = C(p, d) + min(L(q, d), L(q, d -+ 1) + P1, min_k L(q, k) + P2) -
        min_k L(q, k)`` over the pixel's band, with ``q`` the previous pixel of the path,
        whose band is ``[plo, phi)`` (empty at the path's start, where ``L = C``, as where
        its path costs are all inf).

        ``prev`` and ``cur`` are ``(buffer, base)``: ``L(., d)`` at ``buffer[base + d + 1]``,
        n_disp + 2 cells, inf outside the pixel's band; the two ends are sentinels, so
        ``d -+ 1`` needs no test and the loop over the band is branch-free.  The step keeps
        that so: it writes ``cur`` over its band and resets ``prev``'s band to inf (the
        cells the path writes two pixels on; start with all inf).  ``mode`` says what
        becomes of ``acc``: 0 ``acc = L`` (the first path), 1 ``acc += L``, 2 ``acc = (acc +
        L) / 4`` (the last path: the mean of four).  Float32 throughout (``p1``, ``p2``
        float32): the same operations in the same order on every backend.
        """
        pbuf, pbase = prev
        cbuf, cbase = cur
        off = index[v, u, 0]
        lo = index[v, u, 1]
        hi = index[v, u, 2]
        # Subscripts base + i made unsigned: no wraparound selects and no views (whose
        # reference counts cost more than the loops, measured), so the loops vectorise.
        seen = pbase + plo + 1
        # The least of the previous pixel's path costs in four interleaved chains: the
        # cells below wait for it, and one chain of compares over the band was a fifth of
        # the smoothing's time (KITTI, measured).  least() does the same, but called from
        # here (not inlined) it made the whole smoothing 30 % slower, measured.
        m0 = m1 = m2 = m3 = np.float32(INF)  # float32: a float64 pm would round the sums differently
        n = phi - plo
        k = 0
        while k + 4 <= n:
            at = seen + k
            x = pbuf[UINT(at)]
            m0 = x if x < m0 else m0
            x = pbuf[UINT(at + 1)]
            m1 = x if x < m1 else m1
            x = pbuf[UINT(at + 2)]
            m2 = x if x < m2 else m2
            x = pbuf[UINT(at + 3)]
            m3 = x if x < m3 else m3
            k += 4
        while k < n:
            x = pbuf[UINT(seen + k)]
            m0 = x if x < m0 else m0
            k += 1
        m0 = m1 if m1 < m0 else m0
        m2 = m3 if m3 < m2 else m2
        pm = m2 if m2 < m0 else m0
        cells = off + lo
        below = pbase + lo  # L(q, d - 1) of the band's first d
        out = cbase + lo + 1
        quarter = np.float32(0.25)
        for i in range(hi - lo):
            el = cost[UINT(cells + i)]
            if pm != INF:
                x = pbuf[UINT(below + 1 + i)]  # L(q, d)
                jump = pm + p2
                b = x if x < jump else jump
                y = pbuf[UINT(below + i)] + p1  # L(q, d - 1) + P1
                b = y if y < b else b
                y = pbuf[UINT(below + 2 + i)] + p1  # L(q, d + 1) + P1
                b = y if y < b else b
                el = el + (b - pm)
            cbuf[UINT(out + i)] = el
            if mode == 0:
                acc[UINT(cells + i)] = el
            elif mode == 1:
                acc[UINT(cells + i)] += el
            else:
                acc[UINT(cells + i)] = (acc[UINT(cells + i)] + el) * quarter
        for i in range(phi - plo):
            pbuf[UINT(seen + i)] = INF

    return SimpleNamespace(
        ncc_cost=ncc_cost,
        sgm_step=sgm_step,
        ncc_window_cost=ncc_window_cost,
        cosine_cost=cosine_cost,
        box_sum=box_sum,
        cost_or_inf=cost_or_inf,
        right_cost_or_inf=right_cost_or_inf,
        rbf_weight=rbf_weight,
        seed_at=seed_at,
        least=least,
        least_two=least_two,
        first_at=first_at,
        seed_candidate=seed_candidate,
        right_wta=right_wta,
        accept_state=accept_state,
        band_min=band_min,
        diffuse_at=diffuse_at,
        holds_own_disparity=holds_own_disparity,
        candidate_range=candidate_range,
        best_of_three=best_of_three,
        outside_cost=outside_cost,
        patch_reliable=patch_reliable,
        pixel_decisive=pixel_decisive,
        inherit_patch=inherit_patch,
        inherit_pixel=inherit_pixel,
        inherit_at=inherit_at,
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
        subpixel_at=subpixel_at,
        pt_shift=pt_shift,
        bilinear_at=bilinear_at,
        pt_restore_at=pt_restore_at,
    )
