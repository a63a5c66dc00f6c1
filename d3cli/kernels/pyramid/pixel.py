"""Per-pixel function of the pyramid: one pixel of the 2x2 area average.

Compiled for the CPU (``halve.py``, ``numba.njit``) and for CUDA (``cuda.py``,
``numba.cuda.jit(device=True)``) by :func:`build`, so that both targets evaluate the same
float32 expression.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

_F32_QUARTER = np.float32(0.25)


def build(jit):
    """``halve_at`` compiled with ``jit``."""

    @jit
    def halve_at(top, bottom, x):
        """Pixel ``x`` of the half-size row under the two rows ``top`` and ``bottom``:
        ``0.25 (((a00 + a10) + a01) + a11)`` in float32, the order of the NumPy reference
        (``(a[0::2, 0::2] + a[1::2, 0::2] + a[0::2, 1::2] + a[1::2, 1::2]) * 0.25``)."""
        return _F32_QUARTER * (((top[2 * x] + bottom[2 * x]) + top[2 * x + 1]) + bottom[2 * x + 1])

    return SimpleNamespace(halve_at=halve_at)
