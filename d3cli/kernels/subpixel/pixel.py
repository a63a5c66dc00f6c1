"""Per-pixel function of the sub-pixel refinement: a parabola or two lines of equal slope
through three costs.
Compiled for every target by :func:`build` (composed by
:func:`d3cli.kernels.ops.build_ops`)."""

from __future__ import annotations

from types import SimpleNamespace

from ..pixel import INF


def build(jit, shared):
    """``subpixel_at`` compiled with ``jit`` (the protocol: :func:`d3cli.kernels.ops.build_ops`)."""
    cost_or_inf = shared.cost_or_inf

    @jit
    def subpixel_at(cost, index, disp, v, u, equiangular):
        """Sub-pixel disparity through C(d-1), C(d), C(d+1) (docs/design.md, step 8).

        The vertex of the parabola through the three costs, ``0.5 (C(d-1) - C(d+1)) /
        (C(d-1) + C(d+1) - 2 C(d))`` (the paper's step), or with ``equiangular`` the
        crossing of two lines of equal and opposite slope through them (equiangular line
        fitting, Shimizu and Okutomi), ``0.5 (C(d-1) - C(d+1)) / (max(C(d-1), C(d+1)) -
        C(d))``: the shape of a cost whose minimum is a V, as the semi-global smoothing's
        linear penalties make it.  The offset is clamped to [-0.5, 0.5]; at the ends of the
        range or on a flat or concave curve the integer disparity is returned; inf where
        undecided.
        """
        d = disp[v, u]
        if d < 0:
            return INF
        # float64 costs: what numba makes of cost_or_inf's float32 cell or float64 inf;
        # float() says so for NumPy's float32 scalars too (the CUDA simulator)
        c0 = float(cost_or_inf(cost, index, v, u, d - 1))
        c1 = float(cost_or_inf(cost, index, v, u, d))
        c2 = float(cost_or_inf(cost, index, v, u, d + 1))
        if c0 == INF or c1 == INF or c2 == INF:
            return float(d)  # an end of the range or of the band
        if equiangular:
            denom = (c0 if c0 > c2 else c2) - c1
        else:
            denom = c0 + c2 - 2.0 * c1
        if denom <= 0.0:
            return float(d)
        offset = 0.5 * (c0 - c2) / denom
        if offset > 0.5:
            offset = 0.5
        elif offset < -0.5:
            offset = -0.5
        return d + offset

    return SimpleNamespace(
        subpixel_at=subpixel_at,
    )
