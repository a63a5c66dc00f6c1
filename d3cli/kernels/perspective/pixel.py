"""Per-pixel functions of the perspective transformation besides the road model: the
bilinear sample of the warp.  The shift ``s(u, v)`` and the restore are the road model's
(:mod:`d3cli.kernels.road_model`, composed beside this module by
:func:`d3cli.kernels.ops.build_ops`).  Compiled for every target by :func:`build`."""

from __future__ import annotations

import math
from types import SimpleNamespace


def build(jit, shared):
    """``bilinear_at`` compiled with ``jit`` (the protocol: :func:`d3cli.kernels.ops.build_ops`)."""

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

    return SimpleNamespace(bilinear_at=bilinear_at)
