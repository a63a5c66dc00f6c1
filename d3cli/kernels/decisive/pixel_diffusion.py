"""Per-pixel functions of the decisive diffusion (pipeline step 5, paper eq. 4-5).
Compiled for every target by :func:`build` (composed by
:func:`d3cli.kernels.ops.build_ops`)."""

from __future__ import annotations

from types import SimpleNamespace

from ..pixel import INF, UINT, UNDECIDED


# Over 80 lines by design, as every step's factory (see d3cli.kernels.ops.build_ops).
def build(jit, shared):
    """``accept_state, holds_own_disparity, diffuse_at`` compiled with ``jit`` (the protocol: :func:`d3cli.kernels.ops.build_ops`)."""
    cost_or_inf = shared.cost_or_inf
    band_min = shared.band_min

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
        """New state of pixel (u, v) in one Jacobi diffusion sweep (paper eq. 4-5).

        The candidates are ``D(q) + r`` for every decided neighbour q within radius
        ``kappa_d`` (p itself excluded) and r in [-tau, tau]; the state ``s`` is the
        candidate of least cost (smaller disparity on ties).  An undecided pixel takes
        ``s`` when it passes hypotheses (2)-(3); a decided pixel switches to ``s`` only in
        the adversarial mode and only when s also costs strictly less than its current
        disparity (eq. 5).  Reads ``disp`` (the previous sweep) only.

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
            # for the pixels that get this far (a small share: no min_cost pass over
            # the whole volume)
            least = min_cost[v, u] if min_cost.shape[0] > 0 else band_min(cost, index, v, u)
            if best_c > least + max_gap:
                return cur
        if cur < 0:
            return best_s
        if adversarial and best_c < cost_or_inf(cost, index, v, u, cur):
            return best_s
        return cur

    return SimpleNamespace(
        accept_state=accept_state,
        holds_own_disparity=holds_own_disparity,
        diffuse_at=diffuse_at,
    )
