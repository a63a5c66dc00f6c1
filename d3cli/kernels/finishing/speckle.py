"""The speckle filter's passes around ``cv2.filterSpeckles``: into OpenCV's fixed point and back.

:func:`fixed_point_16` and :func:`fixed_point_16_finite` write the disparities in 1/16 px
fixed point (-1 on the holes), ``cv2.filterSpeckles`` marks the speckles -1, and
:func:`drop_marked` makes them holes and masks the map, each in one pass over the rows
(docs/design.md, 'Finishing').  :func:`filter_speckles` marks the same speckles by a
union-find (the backend contract's CPU :func:`drop_speckles`, which the CUDA drivers of
``cuda_speckle.py`` equal; the per-pixel functions of both: ``pixel_speckle.py``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..pool import row_tasks, run_tasks
from .pixel_speckle import build as build_pixels
from .pixel_speckle import fixed_step

_F32_INF = np.float32(np.inf)

# the per-pixel functions, written once for the CPU and CUDA (pixel_speckle.py), as globals
# numba can type
_pixels = build_pixels(njit(cache=True, nogil=True))
_fixed_16 = _pixels.fixed_16
_joins = _pixels.joins


@njit(cache=True, nogil=True, error_model="numpy")
def _fixed_task(task, tasks, disp, valid, out):
    h, w = disp.shape
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    for y in range(y0, y1):
        for u in range(w):
            x = _fixed_16(disp[y, u])
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
            x = _fixed_16(d)
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


@njit(cache=True, nogil=True)
def _root(labels, x):
    """The root of ``x``, halving the path on the way (one thread: no other writer)."""
    while labels[x] != x:
        labels[x] = labels[labels[x]]
        x = labels[x]
    return x


@njit(cache=True, nogil=True)
def filter_speckles(fixed, max_size, max_diff):
    """``cv2.filterSpeckles(fixed, -1, max_size, max_diff)`` in place, by a union-find: the
    pixels of every region of at most ``max_size`` pixels become -1.

    The regions: the 4-connected components of the pixels that are not -1, two neighbours
    joined when their values differ by at most ``max_diff`` (``pixel_speckle.joins``).  The
    pixels are visited in row order, each joined to its left and upper neighbour (the
    root of the larger index linked to the smaller, as the device's union); then every
    pixel counts into its root, and the small regions' pixels are marked.

    Parameters
    ----------
    fixed : ndarray, int16, (H, W), C-contiguous; modified in place
    max_size : int
    max_diff : int
        In the map's units (1/16 px: :func:`d3cli.kernels.finishing.pixel_speckle.fixed_step`).
    """
    h, w = fixed.shape
    n = h * w
    labels = np.empty(n, np.int32)
    flat = fixed.reshape(n)
    for y in range(h):
        for u in range(w):
            i = y * w + u
            f = flat[i]
            labels[i] = i if f != -1 else -1
            if u > 0 and _joins(f, flat[i - 1], max_diff):
                a, b = _root(labels, i), _root(labels, i - 1)
                labels[max(a, b)] = min(a, b)
            if y > 0 and _joins(f, flat[i - w], max_diff):
                a, b = _root(labels, i), _root(labels, i - w)
                labels[max(a, b)] = min(a, b)
    sizes = np.zeros(n, np.int32)
    for i in range(n):  # a root precedes its pixels: labels[i] becomes the root itself
        if labels[i] >= 0:
            r = _root(labels, i)
            labels[i] = r
            sizes[r] += 1
    for i in range(n):
        if labels[i] >= 0 and sizes[labels[i]] <= max_size:
            flat[i] = -1


def drop_speckles(disparity, valid, max_size, max_diff, out):
    """The backends' ``drop_speckles`` on the CPU: the 1/16 px fixed point of the usable
    pixels (:func:`fixed_point_16_finite`), the speckles marked (:func:`filter_speckles`,
    the regions of ``cv2.filterSpeckles``) and dropped (:func:`drop_marked`).

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.drop_speckles`.
    """
    disp = np.ascontiguousarray(disparity, dtype=np.float32)
    fixed, _ = fixed_point_16_finite(disp, valid)
    filter_speckles(fixed, int(max_size), fixed_step(max_diff))
    return drop_marked(disp, valid, fixed, out)


#: The compiled kernels of this module (nogil, cached on disk), run by :func:`d3cli.kernels.pool.run_tasks`.
KERNELS = (_fixed_task, _fixed_finite_task, _drop_marked_task, filter_speckles)
