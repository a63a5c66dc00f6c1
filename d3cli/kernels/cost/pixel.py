"""Per-pixel functions of the matching cost (pipeline step 2): NCC from window sums,
the cosine cost of feature vectors.  Compiled for every target by :func:`build`
(composed by :func:`d3cli.kernels.ops.build_ops`)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

F32_ONE = np.float32(1.0)
F32_HALF = np.float32(0.5)
F32_TINY = np.float32(np.finfo(np.float32).tiny)


# Over 80 lines by design, as every step's factory (see d3cli.kernels.ops.build_ops).
def build(jit, shared):
    """``ncc_cost, ncc_finish, cosine_cost, box_sum, ncc_window_cost`` compiled with ``jit`` (the protocol: :func:`d3cli.kernels.ops.build_ops`)."""

    @jit
    def ncc_finish(num, den):
        """``(1 - NCC) / 2`` from the numerator ``num`` and the variance product ``den``
        (den > 0; float64, or float32 already rounded), the square root, the division and
        the clip in float32 (docs/design.md, step 2).

        The cost is stored as float32 anyway, and in float64 the square root and the
        division run 4 lanes per vector on the CPU instead of 8 (the row's last pass 2.6x
        slower, docs/performance.md).  The result is within 2 ulp of 1.0 of the float64
        formula's (7e-8), and both targets compute it alike (IEEE float32 operations).
        """
        # den at least float32's least normal: a product of two variances that small
        # (min_variance 0) would flush to 0 and make 0 / 0
        ncc = np.float32(num) / math.sqrt(max(np.float32(den), F32_TINY))
        if ncc > F32_ONE:
            ncc = F32_ONE
        elif ncc < -F32_ONE:
            ncc = -F32_ONE
        return F32_HALF * (F32_ONE - ncc)


    @jit
    def ncc_cost(n, sl, sll, sr, srr, slr, min_variance):
        """Matching cost ``(1 - NCC) / 2`` from window sums (docs/design.md, step 2).

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
        return ncc_finish(slr * inv - ml * mr, vl * vr)


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

    return SimpleNamespace(
        ncc_cost=ncc_cost,
        ncc_finish=ncc_finish,
        cosine_cost=cosine_cost,
        box_sum=box_sum,
        ncc_window_cost=ncc_window_cost,
    )
