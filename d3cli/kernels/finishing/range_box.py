"""Edge-preserving smoothing with a box range kernel (host kernel for every backend).

``refine.smooth_kernel: box``: every finite pixel p becomes the mean of the residuals
``r_q`` of the valid pixels q in its (2 radius + 1)^2 box (clipped to the image) with
``|r_q - r_p| <= threshold``, i.e. a bilateral filter whose range kernel is a box instead
of a Gaussian.  Direct summation: (2 radius + 1)^2 compare-and-adds per pixel and no
``exp``, about ten times faster than the piecewise-linear Gaussian filter of
:func:`d3cli.method.refinement.smooth_disparity` at the radii used (4), with the same
accuracy on KITTI (README "Beside the peers"; docs/design.md, 'Finishing').

The kernels run as tasks over blocks of rows on the task pool
(:func:`d3cli.kernels.pool.run_tasks`), not with ``prange``: on a shared machine OpenMP's
spin-waiting makes two threads slower than one.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..pool import row_tasks, run_tasks
from .smoothing import _bodies

# the per-pixel bodies, written once for the CPU and CUDA (pixel_smoothing.py), as globals
# numba can type
_box_residual = _bodies.box_residual
_box_row_terms = _bodies.box_row_terms
_box_mean = _bodies.box_mean
_box_output = _bodies.box_output

_F32_ZERO = np.float32(0.0)
_F32_ONE = np.float32(1.0)
_F32_NAN = np.float32(np.nan)


@njit(cache=True, nogil=True)
def _masked_task(task, tasks, resid, use, masked):
    h, w = resid.shape
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    for v in range(y0, y1):
        for u in range(w):
            masked[v, u] = resid[v, u] if use[v, u] else _F32_NAN


@njit(cache=True, nogil=True)
def _residual_task(task, tasks, disp, base, valid, resid, masked):
    h, w = disp.shape
    has_base = base.shape[0] == h
    all_valid = valid.shape[0] != h  # no map: every finite pixel
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    for v in range(y0, y1):
        for u in range(w):
            resid[v, u], masked[v, u] = _box_residual(disp[v, u], base[v, u] if has_base else _F32_ZERO,
                                                      all_valid or valid[v, u])


@njit(cache=True, nogil=True)
def _smooth_task(task, tasks, resid, masked, radius, threshold, base, disp, non_negative, out):
    h, w = resid.shape
    combine = disp.shape[0] == h
    has_base = base.shape[0] == h
    thr = np.float32(threshold)
    # the task's row buffers: per output row the sums and counts of its pixels
    total = np.empty(w, np.float32)
    count = np.empty(w, np.float32)
    k = 2 * radius + 1
    lo_in = min(radius, w)
    hi_in = max(lo_in, w - radius)  # interior columns: every offset of the row inside the map
    n = hi_in - lo_in
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    for v in range(y0, y1):
        # Per source row, the interior columns take three offsets per pass (in order: each
        # pixel still sums its (2 radius + 1)^2 terms row after row, offset after offset)
        # and the border columns their offsets inside the row one by one: one load and
        # store of a pixel's sums per three offsets instead of per offset.
        total[:] = _F32_ZERO
        count[:] = _F32_ZERO
        centre = resid[v]
        # slices: indices from range(n) are known >= 0, so the loops vectorise
        ref = centre[lo_in:hi_in]
        tot = total[lo_in:hi_in]
        cnt = count[lo_in:hi_in]
        for y in range(max(0, v - radius), min(h - 1, v + radius) + 1):
            row = masked[y]
            g = 0
            while g + 3 <= k:
                s0 = row[lo_in + g - radius:hi_in + g - radius]
                s1 = row[lo_in + g + 1 - radius:hi_in + g + 1 - radius]
                s2 = row[lo_in + g + 2 - radius:hi_in + g + 2 - radius]
                for i in range(n):
                    r = ref[i]
                    q0 = s0[i]
                    q1 = s1[i]
                    q2 = s2[i]
                    in0 = abs(q0 - r) <= thr
                    in1 = abs(q1 - r) <= thr
                    in2 = abs(q2 - r) <= thr
                    tot[i] = ((tot[i] + (q0 if in0 else _F32_ZERO)) + (q1 if in1 else _F32_ZERO)) + (
                        q2 if in2 else _F32_ZERO)
                    cnt[i] = ((cnt[i] + (_F32_ONE if in0 else _F32_ZERO)) + (_F32_ONE if in1 else _F32_ZERO)) + (
                        _F32_ONE if in2 else _F32_ZERO)
                g += 3
            while g < k:
                s0 = row[lo_in + g - radius:hi_in + g - radius]
                for i in range(n):
                    q0 = s0[i]
                    in0 = abs(q0 - ref[i]) <= thr
                    tot[i] += q0 if in0 else _F32_ZERO
                    cnt[i] += _F32_ONE if in0 else _F32_ZERO
                g += 1
            for j in range(w - n):  # the border columns
                u = j if j < lo_in else hi_in + (j - lo_in)
                total[u], count[u] = _box_row_terms(masked, y, u, centre[u], radius, thr, total[u], count[u])
        for u in range(w):
            smoothed = _box_mean(centre[u], total[u], count[u])
            if combine:
                # the residual's sum back (+ 0 without a plane: -0 becomes +0 as in NumPy)
                out[v, u] = _box_output(smoothed, disp[v, u], base[v, u] if has_base else _F32_ZERO, non_negative)
            else:
                out[v, u] = smoothed


def box_range_smooth(resid, use, radius, threshold):
    """Mean of the in-range valid residuals around every finite pixel.

    Parameters
    ----------
    resid : ndarray, float32, (H, W), C-contiguous
        Residual disparity (disparity minus a reference plane, or the disparity);
        non-finite = no estimate.
    use : ndarray, bool, (H, W), C-contiguous
        Pixels that may be averaged into others (valid and finite).
    radius : int
        Box radius in pixels.
    threshold : float
        Largest ``|r_q - r_p|`` (disparity pixels) of a neighbour that is averaged in.

    Returns
    -------
    ndarray, float32, (H, W)
        The smoothed residual; non-finite pixels stay as they are, and a pixel with no
        usable neighbour in range keeps its value.  Sums in float32 (at most (2 radius + 1)^2
        terms), fixed order: the result does not depend on the number of threads.
    """
    h, w = resid.shape
    # Pixels that may not be averaged in read as NaN: NaN fails every comparison, so the
    # inner loop has no branch on validity (branch-free select, vectorisable).
    masked = np.empty((h, w), np.float32)
    run_tasks(_masked_task, row_tasks(h), resid, use, masked)
    out = np.empty((h, w), np.float32)
    none = np.empty((0, 0), np.float32)
    run_tasks(_smooth_task, row_tasks(h), resid, masked, int(radius), float(threshold), none, none, False, out)
    return out


def box_smooth_disparity(disp, base, valid, radius, threshold, non_negative=False):
    """The box range-kernel smoothing of a disparity map in two passes.

    ``resid = np.where(isfinite(disp), disp - base, inf)``, ``use = valid & isfinite(disp)``,
    :func:`box_range_smooth` of them, and ``np.where(isfinite(disp), smoothed + base, disp)``
    (float32); ``base`` None is a zero plane (``- 0`` and ``+ 0`` still applied: the sum
    back turns -0 into +0 as the NumPy sum did), ``valid`` None every finite pixel.  The
    residual pass writes the NaN-masked map the sums read, and the sums' pass adds the
    plane back: two passes over the map and two calls of the pool instead of five passes
    and three calls plus two parallel regions.  ``non_negative``: negative results become
    0 in the same pass (:func:`d3cli.kernels.finishing.smoothing.clamp_negative`).

    Parameters
    ----------
    disp : ndarray, float32, (H, W), C-contiguous
    base : ndarray, float32, (H, W), C-contiguous, or None
    valid : ndarray, bool, (H, W), C-contiguous, or None
    radius : int
    threshold : float
    non_negative : bool

    Returns
    -------
    ndarray, float32, (H, W)
    """
    h, w = disp.shape
    if base is None:
        base = np.empty((0, 0), np.float32)
    if valid is None:
        valid = np.empty((0, 0), np.bool_)
    resid = np.empty((h, w), np.float32)
    masked = np.empty((h, w), np.float32)
    run_tasks(_residual_task, row_tasks(h), disp, base, valid, resid, masked)
    out = np.empty((h, w), np.float32)
    run_tasks(_smooth_task, row_tasks(h), resid, masked, int(radius), float(threshold), base, disp,
              bool(non_negative), out)
    return out


#: The compiled kernels of this module (nogil, cached on disk), run by :func:`d3cli.kernels.pool.run_tasks`.
KERNELS = (_masked_task, _residual_task, _smooth_task)
