"""CPU driver of the pyramid (the backend's ``pyramid``): the levels halved by ``halve.py``."""

from __future__ import annotations

import numpy as np

from .halve import halve_area


def pyramid(image, levels):
    """Grey pyramid of a uint8 or float32 (H, W) image, finest first (float32 arrays).

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.pyramid`.
    """
    out = [np.ascontiguousarray(image, dtype=np.float32)]
    for _ in range(int(levels) - 1):
        out.append(halve_area(out[-1]))
    return out
