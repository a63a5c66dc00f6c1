"""The speckle filter's per-pixel functions, written once for the CPU and for CUDA.

:func:`build` defines them with a given ``jit`` inside one closure (as
:mod:`d3cli.kernels.finishing.pixel_fill`): ``numba.njit`` for the CPU passes of
:mod:`d3cli.kernels.finishing.speckle`, ``numba.cuda.jit(device=True)`` for the union-find
of :mod:`d3cli.kernels.finishing.cuda_speckle`.  The regions are those of
``cv2.filterSpeckles(fixed, -1, max_size, max_diff)`` on OpenCV's 1/16 px fixed point: the
4-connected components of the pixels that are not -1, two neighbours joined when their
fixed-point values differ by at most ``max_diff``; a component of at most ``max_size``
pixels is a speckle.

May import: numpy.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

_F32_ZERO = np.float32(0.0)
_F32_RINT_MAGIC = np.float32(12582912.0)  # 1.5 * 2^23: adding and subtracting it rounds half to even
_F32_16 = np.float32(16.0)
_F32_INT16_MAX = np.float32(32767.0)


def fixed_step(max_diff: float) -> int:
    """``max_diff`` pixels in 1/16 px, at least 1: the ``maxDiff`` the filter is given."""
    return max(1, int(round(float(max_diff) * 16.0)))


def build(jit):
    """The speckle filter's per-pixel functions compiled with ``jit``.

    Returns
    -------
    types.SimpleNamespace
        ``fixed_16(d)`` (float32), ``joins(a, b, max_diff)`` and ``find(labels, x)``.
    """

    @jit
    def fixed_16(d):
        """The 1/16 px fixed point of a float32 disparity, as a float32 integer:
        ``np.clip(np.round(d * 16), 0, 32767)`` (float32 product, rounding half to even;
        clipped before the rounding, the same integer; NaN gives 0)."""
        x = d * _F32_16
        x = _F32_ZERO if not x > _F32_ZERO else (x if x < _F32_INT16_MAX else _F32_INT16_MAX)
        return (x + _F32_RINT_MAGIC) - _F32_RINT_MAGIC

    @jit
    def joins(a, b, max_diff):
        """Whether two 4-neighbours of fixed-point values ``a`` and ``b`` (-1: a hole, in no
        region) belong to one region: ``|a - b| <= max_diff`` (``cv2.filterSpeckles``'s
        test, in integers)."""
        return (a != -1) & (b != -1) & (abs(a - b) <= max_diff)

    @jit
    def find(labels, x):
        """The root of pixel ``x`` in a union-find forest whose parents are smaller
        indices (``labels[r] == r`` at a root): the chain of parents, read only."""
        p = labels[x]
        while p != x:
            x = p
            p = labels[x]
        return x

    return SimpleNamespace(fixed_16=fixed_16, joins=joins, find=find)
