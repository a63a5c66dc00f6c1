"""Per-pixel functions of the perspective transformation: the shift of the road
model, the bilinear sample, the restore of a disparity.  Compiled for every target by
:func:`build` (composed by :func:`d3cli.kernels.ops.build_ops`)."""

from __future__ import annotations

import math
from types import SimpleNamespace

from ..pixel import INF


def build(jit, shared):
    """``pt_shift, bilinear_at, pt_restore_at`` compiled with ``jit`` (the protocol: :func:`d3cli.kernels.ops.build_ops`)."""

    @jit
    def pt_shift(a0, b1, b2, delta, v, u):
        """Perspective-transformation shift ``s(u, v) = a0 + b1 v + b2 u - delta`` (docs/design.md, step 6).

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
        warped right image (docs/design.md, step 6).

        Left (u, v) matches ``R'(u - d', v) = R(u - d' - s(u - d', v), v)``, so
        ``d = d' + s(u - d', v) = d' (1 - b2) + s(u, v)``; inf stays inf.
        """
        if not d_prime < INF:
            return INF
        return d_prime * (1.0 - b2) + pt_shift(a0, b1, b2, delta, v, u)

    return SimpleNamespace(
        pt_shift=pt_shift,
        bilinear_at=bilinear_at,
        pt_restore_at=pt_restore_at,
    )
