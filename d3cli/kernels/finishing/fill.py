"""Hole filling: the usable pixels, the nearest valid values along rows and columns, the fill.

Row-wise filling with the smaller side (:func:`fill_rows_smaller_side`), the median of the
four nearest values inside surfaces (:func:`nearest_along_columns`, :func:`fill_inside`),
empty rows from the nearest filled row (:func:`copy_nearest_rows`) and the median's
write-back (:func:`keep_valid`); each the bytes of its NumPy reference formulation
(docs/design.md, 'Finishing').
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..pool import row_tasks, run_tasks, threads
from .pixel_fill import build as build_rows
from .pixel_fill_inside import build as build_inside

# the row and column bodies, written once for the CPU and CUDA (pixel_fill.py,
# pixel_fill_inside.py), as globals numba can type
_rows = build_rows(njit(cache=True, nogil=True))
_usable_row = _rows.usable_row
_fill_row = _rows.fill_row
_copy_nearest_row = _rows.copy_nearest_row
_median5_at = _rows.median5_at
_inside = build_inside(njit(cache=True, nogil=True))
_nearest_columns = _inside.nearest_columns
_fill_inside_row = _inside.fill_inside_row


@njit(cache=True, nogil=True)
def _usable_task(task, tasks, disp, valid, use, row_has, counts):
    h = disp.shape[0]
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    n = 0
    for y in range(y0, y1):
        m = _usable_row(disp, valid, use, y)
        row_has[y] = m > 0
        n += m
    counts[task] = n


def usable(disp, valid):
    """``valid & np.isfinite(disp)``, which rows have such a pixel, and how many there are:
    one pass instead of four (and, any, all, any per row)."""
    h, w = disp.shape
    use = np.empty((h, w), np.bool_)
    row_has = np.empty(h, np.bool_)
    tasks = row_tasks(h)
    counts = np.zeros(tasks, np.int64)
    run_tasks(_usable_task, tasks, disp, valid, use, row_has, counts)
    return use, row_has, int(counts.sum())


@njit(cache=True, nogil=True)
def _fill_rows_task(task, tasks, disp, valid, filled, row_has):
    h = disp.shape[0]
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    for y in range(y0, y1):
        row_has[y] = _fill_row(disp, valid, filled, y)


def fill_rows_smaller_side(disp, valid):
    """Row-wise fill: each hole takes the smaller of the nearest valid values left and right.

    Parameters
    ----------
    disp : ndarray, float32, (H, W)
    valid : ndarray, bool, (H, W)
        Pixels to keep and to fill from (finite values only).

    Returns
    -------
    filled : ndarray, float32, (H, W)
        ``disp`` where valid, else the smaller neighbour (inf where the row has none).
    row_has : ndarray, bool, (H,)
        Whether the row has a valid pixel.
    """
    h, w = disp.shape
    filled = np.empty((h, w), np.float32)
    row_has = np.zeros(h, np.bool_)
    run_tasks(_fill_rows_task, row_tasks(h), disp, valid, filled, row_has)
    return filled, row_has


@njit(cache=True, nogil=True)
def _nearest_columns_task(task, tasks, disp, valid, up, down):
    w = disp.shape[1]
    u0, u1 = (task * w) // tasks, ((task + 1) * w) // tasks
    if u1 <= u0:
        return
    _nearest_columns(disp, valid, up, down, u0, u1, np.empty(u1 - u0, np.float32))


def nearest_along_columns(disp, valid):
    """Values of the nearest usable pixel (valid and finite) above and below in each
    column, in the map's own (H, W) layout, without transposed copies (tasks over blocks of
    columns, rows streamed; the column body: ``pixel_fill_inside.nearest_columns``).

    Returns
    -------
    up, down : ndarray, float32, (H, W)
        The nearest usable value at or above (below) each pixel; inf where there is none.
    """
    h, w = disp.shape
    up = np.empty((h, w), np.float32)
    down = np.empty((h, w), np.float32)
    n = threads()
    tasks = 1 if n == 1 else max(1, min(w // 64, 4 * n))
    run_tasks(_nearest_columns_task, tasks, disp, valid, up, down)
    return up, down


@njit(cache=True, nogil=True)
def _fill_inside_task(task, tasks, disp, valid, occluded, up, down, out):
    w = disp.shape[1]
    left = np.empty(w, np.float32)  # the task's own row buffers
    right = np.empty(w, np.float32)
    h = disp.shape[0]
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    for y in range(y0, y1):
        _fill_inside_row(disp, valid, occluded, up, down, out, left, right, y)


def fill_inside(disp, valid, occluded, up, down):
    """Fill with the median of the finite nearest values in four directions where a hole
    is not occluded and has one, else with the smaller row neighbour.

    The row neighbours are found on the way, in two row buffers that stay in the cache (no
    left/right maps written and read back; the row body: ``pixel_fill_inside.fill_inside_row``).

    Parameters
    ----------
    disp : ndarray, float32, (H, W)
    valid, occluded : ndarray, bool, (H, W)
    up, down : ndarray, float32, (H, W)
        Nearest valid values above and below: finite, or +inf where there is none (what
        :func:`nearest_along_columns` gives).

    Returns
    -------
    ndarray, float32, (H, W)
        As ``np.nanmedian`` over the finite ones (mean of the middle two of an even count,
        in float32).
    """
    h, w = disp.shape
    out = np.empty((h, w), np.float32)
    run_tasks(_fill_inside_task, row_tasks(h), disp, valid, occluded, up, down, out)
    return out


@njit(cache=True, nogil=True)
def copy_nearest_rows(filled, row_has):
    """Rows without a valid pixel copy the nearest row that has one (the upper on a tie).

    Parameters
    ----------
    filled : ndarray, float32, (H, W), modified in place
    row_has : ndarray, bool, (H,)
        At least one True.
    """
    for y in range(filled.shape[0]):
        _copy_nearest_row(filled, row_has, y)


@njit(cache=True, nogil=True)
def _keep_valid_task(task, tasks, filled, valid, other):
    h, w = filled.shape
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    for y in range(y0, y1):
        for u in range(w):
            if not valid[y, u]:
                filled[y, u] = other[y, u]


def keep_valid(filled, valid, other):
    """``filled`` where valid, else ``other``, in place (float32 (H, W))."""
    run_tasks(_keep_valid_task, row_tasks(filled.shape[0]), filled, valid, other)


def fill_rows(disparity, valid):
    """The backends' ``fill_rows`` on the CPU: the usable pixels (:func:`usable`), the
    row-wise fill from them (:func:`fill_rows_smaller_side`), empty rows from the nearest
    filled row (:func:`copy_nearest_rows`).

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.fill_rows`.
    """
    disp = np.ascontiguousarray(disparity, dtype=np.float32)
    use, _, _ = usable(disp, np.ascontiguousarray(valid, dtype=np.bool_))
    filled, row_has = fill_rows_smaller_side(disp, use)
    if not row_has.all():
        copy_nearest_rows(filled, row_has)
    return filled, use


def fill_inside_holes(disparity, valid, occluded):
    """The backends' ``fill_inside`` on the CPU: the usable pixels (:func:`usable`), their
    nearest values along the columns (:func:`nearest_along_columns`), the fill
    (:func:`fill_inside`), empty rows from the nearest filled row
    (:func:`copy_nearest_rows`).

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.fill_inside`.
    """
    disp = np.ascontiguousarray(disparity, dtype=np.float32)
    use, row_has, _ = usable(disp, np.ascontiguousarray(valid, dtype=np.bool_))
    up, down = nearest_along_columns(disp, use)
    filled = fill_inside(disp, use, np.ascontiguousarray(occluded, dtype=np.bool_), up, down)
    if not row_has.all():
        copy_nearest_rows(filled, row_has)
    return filled, use


@njit(cache=True, nogil=True)
def _median_holes_task(task, tasks, filled, use, out):
    h, w = filled.shape
    buf = np.empty(25, np.float32)
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    for y in range(y0, y1):
        for u in range(w):
            out[y, u] = filled[y, u] if use[y, u] else _median5_at(filled, y, u, buf)


def median_of_holes(filled, use):
    """The backends' ``median_of_holes`` on the CPU: ``filled`` where ``use``, else the
    median of its 5x5 window, borders replicated (the values of ``cv2.medianBlur(filled,
    5)`` on a map without NaN, which the pipeline's host path takes); a new map.

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.median_of_holes`.
    """
    filled = np.ascontiguousarray(filled, dtype=np.float32)
    out = np.empty(filled.shape, np.float32)
    run_tasks(_median_holes_task, row_tasks(filled.shape[0]), filled, np.ascontiguousarray(use, dtype=np.bool_),
              out)
    return out


#: The compiled kernels of this module (nogil, cached on disk), run by :func:`d3cli.kernels.pool.run_tasks`.
KERNELS = (_usable_task, _fill_rows_task, _nearest_columns_task, _fill_inside_task, copy_nearest_rows,
           _keep_valid_task, _median_holes_task)
