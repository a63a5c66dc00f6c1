"""Which estimates the finishing drops as occluded or impossible: the occlusion tests.

The uniqueness test (a right-image column claimed by a larger disparity), the left-border
test (out of view), both fused with the masking of the pipeline (:func:`drop_occluded`),
and the road model's rules over a map (:mod:`d3cli.kernels.road_model`): the validity after
the restore of the perspective transformation (:func:`restored_validity`) and the
right-image mask (:func:`right_image_mask`).  Each gives the bytes of its NumPy reference
formulation (``tests/reference/finishing.py``); see docs/design.md, 'Finishing'.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..pool import row_tasks, run_tasks
from ..road_model import host as _road_model
from .pixel_occlusion import build as build_rows

_F32_INF = np.float32(np.inf)
# the road model's rules (kernels/road_model.py), as globals numba can type
_restore_drops = _road_model.restore_drops
_in_right_image = _road_model.in_right_image


# ----------------------------------------------------------------------------- restore after PT
@njit(cache=True, nogil=True)
def _restored_task(task, tasks, valid, narrow, restored, hi, masked, keep_out, counts):
    h, w = valid.shape
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    n_ends = 0
    n_outside = 0
    n_negative = 0
    for y in range(y0, y1):
        for u in range(w):
            r = restored[y, u]
            # float32 u - r: the same verdict as float64 (road_model.in_right_image), vectorised
            ends, outside, negative = _restore_drops(valid[y, u], narrow[y, u], r, np.float32(u), hi)
            n_ends += ends
            n_outside += outside
            n_negative += negative & (not ends) & (not outside)
            keep = valid[y, u] & (not (ends | outside | negative))
            keep_out[y, u] = keep
            if masked.shape[0] == h:
                masked[y, u] = r if keep else _F32_INF
    counts[task, 0] = n_ends
    counts[task, 1] = n_outside
    counts[task, 2] = n_negative


def restored_validity(valid, narrow, restored, hi, masked=None):
    """The estimates that survive the restore of the perspective transformation, in one pass
    (counts, validity and masked map together, instead of a pass each): the road model's
    rule (:func:`d3cli.kernels.road_model.build`, ``restore_drops``) at every pixel.

    Parameters
    ----------
    valid : ndarray, bool, (H, W), C-contiguous
    narrow : ndarray, (H, W), C-contiguous
        Narrow-range disparities (any real dtype).
    restored : ndarray, float32, (H, W), C-contiguous
    hi : scalar
        Upper end of the narrow range, already of the type NumPy compares ``narrow`` with
        it in (``narrow >= hi``).
    masked : ndarray, float32, (H, W), optional
        Receives ``np.where(kept, restored, inf)`` (may be ``restored`` itself).

    Returns
    -------
    kept : ndarray, bool, (H, W)
        ``valid & ~ends & ~outside & ~negative`` with ``ends = (narrow <= 0) | (narrow >=
        hi)``, ``outside = ~(u - restored >= -0.5)``, ``negative = ~(restored >= 0)``.
    counts : ndarray, int64, (3,)
        Valid pixels at the range ends, outside, and negative but neither of the others.
    """
    h, w = valid.shape
    kept = np.empty((h, w), np.bool_)
    tasks = row_tasks(h)
    counts = np.zeros((tasks, 3), np.int64)
    if masked is None:
        masked = np.empty((0, 0), np.float32)
    run_tasks(_restored_task, tasks, valid, narrow, restored, hi, masked, kept, counts)
    return kept, counts.sum(axis=0)


def pt_validity(narrow, restored, narrow_range):
    """The CPU backend's ``pt_validity``: :func:`restored_validity` of a narrow-range integer
    map (decided where ``>= 0``) and its restored sub-pixel map, the map masked.

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.pt_validity`.
    """
    narrow = np.ascontiguousarray(narrow)
    restored = np.ascontiguousarray(restored, dtype=np.float32)
    # the type NumPy compares ``narrow >= narrow_range`` in (NEP 50: float32 stays float32)
    hi = np.result_type(narrow, narrow_range).type(narrow_range)
    masked = np.empty(restored.shape, np.float32)
    kept, counts = restored_validity(narrow >= 0, narrow, restored, hi, masked)
    return kept, masked, [int(c) for c in counts]


def count_range_ends(narrow, narrow_range):
    """The CPU backend's ``count_range_ends``: pixels of a narrow-range integer map at
    ``d' == 0`` or ``d' >= narrow_range``.

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.count_range_ends`.
    """
    narrow = np.asarray(narrow)
    return int(np.count_nonzero((narrow == 0) | (narrow >= narrow_range)))


@njit(cache=True, nogil=True)
def _right_image_task(task, tasks, disparity, finite, out):
    h, w = disparity.shape
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    for y in range(y0, y1):
        for u in range(w):
            d = disparity[y, u]
            seen = _in_right_image(np.float64(u), np.float64(d))
            out[y, u] = seen & (not finite or np.isfinite(d))


def right_image_mask(disparity, finite=False):
    """Where the match ``u - d`` of a disparity map lies in the right image: the road
    model's rule (:func:`d3cli.kernels.road_model.build`, ``in_right_image``) at every
    pixel, in float64.

    Parameters
    ----------
    disparity : ndarray, float32 or float64, (H, W), C-contiguous
    finite : bool
        Also require a finite disparity (``-inf`` otherwise passes the rule).

    Returns
    -------
    ndarray, bool, (H, W)
    """
    h, w = disparity.shape
    out = np.empty((h, w), np.bool_)
    run_tasks(_right_image_task, row_tasks(h), disparity, bool(finite), out)
    return out


# ----------------------------------------------------------------------------- occlusion tests
# the row bodies, written once for the CPU and CUDA (pixel_occlusion.py), as globals numba can type
_rows = build_rows(njit(cache=True, nogil=True))
_uniqueness_row = _rows.uniqueness_row
_out_of_view_row = _rows.out_of_view_row
_drop_occluded_row = _rows.drop_occluded_row


@njit(cache=True, nogil=True)
def _uniqueness_task(task, tasks, disparity, valid, tolerance, best, target, out):
    h = disparity.shape[0]
    row_best = best[task]
    row_target = target[task]
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    for y in range(y0, y1):
        _uniqueness_row(disparity, valid, tolerance, y, row_best, row_target, out)


def uniqueness_occluded(disparity, valid, tolerance):
    """Left pixels whose right-image match is claimed by a larger disparity.

    Parameters
    ----------
    disparity : ndarray, float32, (H, W), C-contiguous
    valid : ndarray, bool, (H, W), C-contiguous
    tolerance : float
        Pixels with ``d < max_d(match) - tolerance`` are occluded.

    Returns
    -------
    ndarray, bool, (H, W)
        Per row, the largest valid disparity that maps to each right column
        ``round(u - d)`` (a scatter-max into one row buffer per task), then the test; NaN
        wins the maximum as in ``np.maximum``.
    """
    h, w = disparity.shape
    out = np.zeros((h, w), np.bool_)
    tasks = row_tasks(h)
    best = np.empty((tasks, max(w, 1)), np.float64)
    target = np.empty((tasks, max(w, 1)), np.int64)
    run_tasks(_uniqueness_task, tasks, disparity, valid, float(tolerance), best, target, out)
    return out


@njit(cache=True, nogil=True)
def _out_of_view_task(task, tasks, disparity, valid, start, out):
    h = disparity.shape[0]
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    for y in range(y0, y1):
        _out_of_view_row(disparity, valid, start, y, out)


def out_of_view_mask(disparity, valid, start):
    """Left-border pixels below the first valid disparity ``b`` at or right of ``start``.

    Parameters
    ----------
    disparity : ndarray, float32, (H, W)
    valid : ndarray, bool, (H, W)
    start : int
        First column searched for ``b`` (0 <= start < W); rows without one get b = -inf.

    Returns
    -------
    ndarray, bool, (H, W)
        ``valid & (u < b) & (d < b - 1)`` (``b - 1`` in float32, as NumPy computes it).
    """
    h, w = disparity.shape
    out = np.zeros((h, w), np.bool_)
    run_tasks(_out_of_view_task, row_tasks(h), disparity, valid, int(start), out)
    return out


@njit(cache=True, nogil=True)
def _drop_occluded_task(task, tasks, disparity, valid, tolerance, start, best, target, out, occluded, counts):
    h = disparity.shape[0]
    row_best = best[task]
    row_target = target[task]
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    n = 0
    for y in range(y0, y1):
        n += _drop_occluded_row(disparity, valid, tolerance, start, y, row_best, row_target, out, occluded)
    counts[task] = n


def drop_occluded(disparity, valid, tolerance, start, out):
    """Both occlusion tests, their holes and the masked map, in one pass over the rows.

    ``occluded = uniqueness_occluded(...) | out_of_view_mask(...)`` (the tests read
    ``valid`` as it comes in), then ``valid &= ~occluded`` in place and
    ``out = np.where(valid, disparity, inf)``: what the pipeline did in six passes over the
    map (two tests, or, and-not, where, astype).

    Parameters
    ----------
    disparity : ndarray, float32, (H, W), C-contiguous
    valid : ndarray, bool, (H, W), C-contiguous; updated in place
    tolerance : float
    start : int
        As :func:`out_of_view_mask` (0 <= start < W).
    out : ndarray, float32, (H, W)
        Receives the masked map; may be ``disparity`` itself (each pixel is read before
        it is written, and the tests of a row finish before its first write).

    Returns
    -------
    occluded : ndarray, bool, (H, W)
    count : int
        Number of occluded pixels.
    """
    h, w = disparity.shape
    occluded = np.empty((h, w), np.bool_)
    tasks = row_tasks(h)
    best = np.empty((tasks, max(w, 1)), np.float64)
    target = np.empty((tasks, max(w, 1)), np.int64)
    counts = np.zeros(tasks, np.int64)
    run_tasks(_drop_occluded_task, tasks, disparity, valid, float(tolerance), int(start), best, target, out,
              occluded, counts)
    return occluded, int(counts.sum())


#: The compiled kernels of this module (nogil, cached on disk), run by :func:`d3cli.kernels.pool.run_tasks`.
KERNELS = (_restored_task, _right_image_task, _uniqueness_task, _out_of_view_task, _drop_occluded_task)
