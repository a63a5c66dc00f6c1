"""Per-pixel functions of the decisive seeds (pipeline step 4): PKRN and the
left-right check.  Compiled for every target by :func:`build` (composed by
:func:`d3cli.kernels.ops.build_ops`)."""

from __future__ import annotations

from types import SimpleNamespace

from ..pixel import INF, UINT, UNDECIDED


# Over 80 lines by design, as every step's factory (see d3cli.kernels.ops.build_ops).
def build(jit, shared):
    """``seed_candidate, right_wta, seed_at`` compiled with ``jit`` (the protocol: :func:`d3cli.kernels.ops.build_ops`)."""
    least = shared.least
    least_two = shared.least_two
    first_at = shared.first_at

    @jit
    def seed_candidate(cost, index, v, u, pkrn_min, epsilon, exclusion):
        """Test (a) of :func:`seed_at`: the WTA disparity d1 of (u, v) when its PKRN passes
        and its match u - d1 lies in the image, else UNDECIDED.

        The least cost c1 and the second cost c2 are found by value (:func:`least_two`,
        :func:`least`), and d1 as the first disparity holding c1: the smallest on ties,
        as a scan with a strict ``<`` finds it (an in-order scan waits a compare and a
        select per cell).  (Cells are never NaN: the costs lie in [0, 1].)
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
        """Decisive seed at (u, v) of the coarsest level, or UNDECIDED (docs/design.md, step 4).

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

    return SimpleNamespace(
        seed_candidate=seed_candidate,
        right_wta=right_wta,
        seed_at=seed_at,
    )
