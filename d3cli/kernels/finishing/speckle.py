"""The speckle filter's passes around ``cv2.filterSpeckles``: into OpenCV's fixed point and back.

:func:`fixed_point_16` and :func:`fixed_point_16_finite` write the disparities in 1/16 px
fixed point (-1 on the holes), ``cv2.filterSpeckles`` marks the speckles -1, and
:func:`drop_marked` makes them holes and masks the map, each in one pass over the rows
(docs/design.md, 'Finishing').
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..pool import row_tasks, run_tasks

_F32_ZERO = np.float32(0.0)
_F32_INF = np.float32(np.inf)
_F32_RINT_MAGIC = np.float32(12582912.0)  # 1.5 * 2^23: adding and subtracting it rounds half to even
_F32_16 = np.float32(16.0)
_F32_INT16_MAX = np.float32(32767.0)


@njit(cache=True, nogil=True, error_model="numpy")
def _fixed_task(task, tasks, disp, valid, out):
    h, w = disp.shape
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    for y in range(y0, y1):
        for u in range(w):
            x = disp[y, u] * _F32_16
            # clipped before the rounding: the same integer as np.clip(np.round(x), 0, 32767)
            x = _F32_ZERO if not x > _F32_ZERO else (x if x < _F32_INT16_MAX else _F32_INT16_MAX)
            x = (x + _F32_RINT_MAGIC) - _F32_RINT_MAGIC
            out[y, u] = np.int16(x) if valid[y, u] else np.int16(-1)


def fixed_point_16(disp, valid):
    """Disparities in OpenCV's 1/16 px fixed point, -1 on the holes.

    Parameters
    ----------
    disp : ndarray, float32, (H, W)
    valid : ndarray, bool, (H, W)
        Finite estimates only.

    Returns
    -------
    ndarray, int16, (H, W)
        ``np.where(valid, np.clip(np.round(disp * 16), 0, 32767), -1).astype(np.int16)``
        (float32 product, rounding half to even), in one pass.
    """
    h, w = disp.shape
    out = np.empty((h, w), np.int16)
    run_tasks(_fixed_task, row_tasks(h), disp, valid, out)
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def _fixed_finite_task(task, tasks, disp, valid, out, counts):
    h, w = disp.shape
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    n = 0
    for y in range(y0, y1):
        for u in range(w):
            d = disp[y, u]
            ok = valid[y, u] & np.isfinite(d)  # selects, no branches (holes are scattered)
            x = d * _F32_16
            x = _F32_ZERO if not x > _F32_ZERO else (x if x < _F32_INT16_MAX else _F32_INT16_MAX)
            x = (x + _F32_RINT_MAGIC) - _F32_RINT_MAGIC
            out[y, u] = np.int16(x) if ok else np.int16(-1)
            n += ok
    counts[task] = n


def fixed_point_16_finite(disp, valid):
    """:func:`fixed_point_16` of ``valid & np.isfinite(disp)``, and how many pixels that is
    (one pass instead of three)."""
    h, w = disp.shape
    out = np.empty((h, w), np.int16)
    tasks = row_tasks(h)
    counts = np.zeros(tasks, np.int64)
    run_tasks(_fixed_finite_task, tasks, disp, valid, out, counts)
    return out, int(counts.sum())


@njit(cache=True, nogil=True)
def _drop_marked_task(task, tasks, disp, valid, fixed, out, counts):
    h, w = disp.shape
    in_place = out.shape[0] != h  # no output map: write disp
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    n = 0
    for y in range(y0, y1):
        for u in range(w):  # selects, no branches: speckles are scattered
            d = disp[y, u]
            keep = valid[y, u]
            # bitwise & of bools: no short-circuit branches (half the time on KITTI)
            speck = keep & np.isfinite(d) & (fixed[y, u] == -1)
            keep = keep & (not speck)
            valid[y, u] = keep
            x = d if keep else _F32_INF
            # in place through disp itself (no output map): a separate output argument
            # that is disp fails the vectorised loop's overlap check and the scalar loop
            # runs
            if in_place:
                disp[y, u] = x
            else:
                out[y, u] = x
            n += speck
    counts[task] = n


def drop_marked(disp, valid, fixed, out):
    """Drop the finite valid pixels that ``cv2.filterSpeckles`` marked (-1 in ``fixed``).

    ``speck = valid & isfinite(disp) & (fixed == -1)``; ``valid &= ~speck`` in place and
    ``out = np.where(valid, disp, inf)`` (``out`` may be ``disp``); returns the number of
    speckle pixels.
    """
    tasks = row_tasks(disp.shape[0])
    counts = np.zeros(tasks, np.int64)
    if out is disp:
        out = np.empty((0, 0), np.float32)
    run_tasks(_drop_marked_task, tasks, disp, valid, fixed, out, counts)
    return int(counts.sum())


#: The compiled kernels of this module (nogil, cached on disk), run by :func:`d3cli.kernels.pool.run_tasks`.
KERNELS = (_fixed_task, _fixed_finite_task, _drop_marked_task)
