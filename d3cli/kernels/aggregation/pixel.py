"""Per-pixel functions of the cost aggregation (pipeline step 3): the bilateral kernel.
Compiled for every target by :func:`build` (composed by
:func:`d3cli.kernels.ops.build_ops`)."""

from __future__ import annotations

import math
from types import SimpleNamespace



def build(jit, shared):
    """``rbf_weight`` compiled with ``jit`` (the protocol: :func:`d3cli.kernels.ops.build_ops`)."""

    @jit
    def rbf_weight(dy, dx, i_p, i_q, inv_sigma_space2, inv_sigma_color2):
        """Bilateral kernel K(p, q) of paper eq. 3 (unnormalised)."""
        di = i_p - i_q
        return math.exp(-(dy * dy + dx * dx) * inv_sigma_space2 - di * di * inv_sigma_color2)

    return SimpleNamespace(
        rbf_weight=rbf_weight,
    )
