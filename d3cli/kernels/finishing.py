"""Numba kernels of step 8, the finishing of the disparity map (DESIGN step 8).

CPU only: the finishing runs on the host for every backend (the CUDA backend downloads
its integer and sub-pixel maps first, see ``D3Stereo._finish``), so these kernels serve
the CPU and the CUDA pipeline alike.  ``d3cli.method.refinement`` calls them; its
docstrings say what each step means.

Every kernel gives exactly the values of the NumPy/OpenCV formulation it replaced (kept
as the reference in ``tests/kernels/test_finishing.py``): the same float32/float64
operations in the same order, bit for bit.  The kernels release the GIL (``nogil``) and
run as tasks over blocks of rows (or groups of range levels) on the calling thread and a
pool, numba's thread count of threads in all (:func:`run_tasks`); tasks write disjoint
cells, so the results do not depend on the thread count.  A thread pool, not ``prange``: OpenMP's
spin-waiting made the parallel kernels slower than one thread whenever the 2-core test
machine was shared (smoothing of the road pair: 128 ms CPU with two threads against
54 ms with one, at a load of 6); idle pool threads block instead of spinning.

The box sums of the smoothing reproduce ``cv2.boxFilter(..., normalize=False,
borderType=cv2.BORDER_CONSTANT)`` on float32 as OpenCV 5.0 computes them (float64 running
sums along the rows, then down the columns; direct 3- and 5-tap sums for radius 1 and 2).
The range weights are NumPy's float32 ``exp`` computed inside the kernel
(:func:`numpy_expf`, NumPy's SIMD algorithm transcribed, equal on all 2^32 arguments): the
C library's ``expf`` (what numba's ``math.exp`` calls) differs in the last bit for about a
third of the arguments.
"""

from __future__ import annotations

import itertools
import os
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

# cpu.py chooses a writable numba cache folder (NUMBA_CACHE_DIR) for a read-only install
# when it is imported; the decorators below read that setting, so it must run first.
from . import cpu as _cpu  # noqa: F401,E402  (import for its side effect)

_POOL: ThreadPoolExecutor | None = None
_POOL_KEY: tuple[int, int] = (0, 0)  # (process id, threads) the pool was made for
_LOADED: set = set()  # (process id, task function) already called once in this process


def threads() -> int:
    """Threads the finishing runs on: numba's thread count (``--threads``, NUMBA_NUM_THREADS)."""
    return max(1, numba.get_num_threads())


def run_tasks(func, n_tasks, *args):
    """``func(i, n_tasks, *args)`` for every task i, on the pool; returns when all are done.

    The calling thread and ``threads() - 1`` pool threads take the tasks in turn from a
    shared counter: one submission per helping thread, not one per task, and the calling
    thread works instead of waiting (issue 10: a call of eight empty tasks on two threads
    150 -> 50 us; the finishing makes about ten such calls per map).  With one thread (or
    one task) everything runs in the calling thread, and so does task 0 of the first call
    of ``func`` in a process (it compiles or loads the kernel) before any other.
    Exceptions of a task are raised here, once every thread has stopped taking tasks.
    """
    global _POOL, _POOL_KEY
    n = threads()
    if n == 1 or n_tasks <= 1:
        for i in range(n_tasks):
            func(i, n_tasks, *args)
        return
    start = 0
    if (os.getpid(), func) not in _LOADED:
        # The first call of a kernel in a process compiles it or loads it from numba's
        # cache: do that here, in the calling thread, with task 0, and fan out after.
        # A pool thread loading a kernel while Ctrl-C interrupted the main thread hung
        # once in llvmlite's global lock (seen in gdb, 1 of 13 runs of the interrupt
        # tests); with the loading in the main thread an interrupt cannot strand it.
        func(0, n_tasks, *args)
        _LOADED.add((os.getpid(), func))
        start = 1
    key = (os.getpid(), n)
    if _POOL is None or _POOL_KEY != key:
        if _POOL is not None and _POOL_KEY[0] == key[0]:
            _POOL.shutdown(wait=False)  # the thread count changed (numba.set_num_threads)
        # a forked worker inherits the pool object but not its threads: make a new one
        _POOL = ThreadPoolExecutor(max_workers=n, thread_name_prefix="d3stereo-finish")
        _POOL_KEY = key
    counter = itertools.count(start)  # next() of a count is atomic (one C call under the GIL)

    def take():
        for i in counter:
            if i >= n_tasks:
                return
            func(i, n_tasks, *args)

    helpers = [_POOL.submit(take) for _ in range(min(n, n_tasks - start) - 1)]
    try:
        take()
    finally:
        for future in helpers:
            future.result()


def row_tasks(h: int) -> int:
    """Blocks of rows: a few per thread, so that a thread that was descheduled on a
    shared machine holds up little."""
    n = threads()
    return 1 if n == 1 else max(1, min(h, 4 * n))


_F32_ONE = np.float32(1.0)
_F32_TWO = np.float32(2.0)
_F32_ZERO = np.float32(0.0)
_F32_INF = np.float32(np.inf)
# NumPy's float -> int64 cast of a value outside the int64 range (and of NaN) gives
# INT64_MIN on x86, which the reference's clip then maps to column 0
_INT64_LIMIT = 9.223372036854775807e18


# ----------------------------------------------------------------------------- restore of step 6
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
            q = narrow[y, u]
            # bitwise & and | of bools: selects, no branches
            valid_yu = valid[y, u]
            ends = valid_yu & ((q <= 0) | (q >= hi))
            outside = valid_yu & (not (np.float32(u) - r >= -0.5))
            negative = valid_yu & (not (r >= 0))
            n_ends += ends
            n_outside += outside
            n_negative += negative & (not ends) & (not outside)
            keep = valid_yu & (not (ends | outside | negative))
            keep_out[y, u] = keep
            if masked.shape[0] == h:
                masked[y, u] = r if keep else _F32_INF
    counts[task, 0] = n_ends
    counts[task, 1] = n_outside
    counts[task, 2] = n_negative


def restored_validity(valid, narrow, restored, hi, masked=None):
    """The estimates that survive the restore of step 6, in one pass (issue 10).

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
        hi)``, ``outside = ~(float32(u) - restored >= -0.5)``, ``negative = ~(restored >= 0)``.
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


# ----------------------------------------------------------------------------- occlusion tests
@njit(cache=True, inline="always")
def _right_column(u, d, w):
    """Column ``round(u - d)`` clipped to [0, w-1], as NumPy computes it (float64, half to
    even): 0 where ``u - d`` is NaN, infinite or beyond the int64 range (NumPy's cast gives
    INT64_MIN there, which the clip maps to 0).  Selects only, so that a loop over a row
    vectorises."""
    x = np.float64(u) - d
    inside = (x > -0.5) & (x < w - 0.5)  # rounds to 0 .. w-1 (False for NaN)
    beyond = (x >= w - 0.5) & (abs(x) < _INT64_LIMIT)  # rounds to w - 1 or above
    # np.rint (half to even) of |x| < 2^51: adding and subtracting 1.5 * 2^52 rounds to an
    # integer in the current (nearest-even) mode; measured 25 % faster than np.rint here
    r = np.int64(((x if inside else 0.0) + 6755399441055744.0) - 6755399441055744.0)
    return r if inside else (w - 1 if beyond else 0)


@njit(cache=True, nogil=True)
def _nearest_claims(disparity, valid, y, row_best, row_target):
    """The uniqueness test's scatter for row y: ``row_target[u]`` the right column of every
    pixel u, ``row_best[x]`` the largest valid disparity that claims right column x (-inf
    where none does; a NaN disparity wins its column); shared by the test alone and by
    the fused hole-making pass.  Returns the number of valid pixels of the row."""
    w = disparity.shape[1]
    d_row = disparity[y]
    v_row = valid[y]
    for u in range(w):  # no branch: vectorised (the scatter below is not)
        row_target[u] = _right_column(u, np.float64(d_row[u]), w)
    row_best[:] = -np.inf
    n_valid = 0
    for u in range(w):
        if v_row[u]:
            n_valid += 1
            d = np.float64(d_row[u])
            xr = row_target[u]
            if d > row_best[xr] or d != d:
                row_best[xr] = d
    return n_valid


@njit(cache=True, nogil=True)
def _uniqueness_task(task, tasks, disparity, valid, tolerance, best, target, out):
    h, w = disparity.shape
    row_best = best[task]
    row_target = target[task]
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    for y in range(y0, y1):
        _nearest_claims(disparity, valid, y, row_best, row_target)
        for u in range(w):
            out[y, u] = valid[y, u] and np.float64(disparity[y, u]) < row_best[row_target[u]] - tolerance


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
def _first_valid_from(disparity, valid, y, start):
    """The left-border test's ``b`` of row y: the first valid disparity at or right of
    column ``start`` (float32), -inf when the row has none."""
    for u in range(start, disparity.shape[1]):
        if valid[y, u]:
            return disparity[y, u]
    return -_F32_INF


@njit(cache=True, nogil=True)
def _out_of_view_task(task, tasks, disparity, valid, start, out):
    h, w = disparity.shape
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    for y in range(y0, y1):
        b = _first_valid_from(disparity, valid, y, start)
        b_minus_1 = b - _F32_ONE
        for u in range(w):
            out[y, u] = valid[y, u] and u < b and disparity[y, u] < b_minus_1


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
    h, w = disparity.shape
    row_best = best[task]
    row_target = target[task]
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    n = 0
    for y in range(y0, y1):
        # both tests read the row's validity before any of it is dropped
        n_valid = _nearest_claims(disparity, valid, y, row_best, row_target)
        b = _first_valid_from(disparity, valid, y, start)
        b_minus_1 = b - _F32_ONE
        d_row = disparity[y]
        v_row = valid[y]
        o_row = out[y]
        c_row = occluded[y]
        # Issue 10: the loop by the row's share of holes, 1 thread, A/B on the pipeline's
        # inputs (with the vectorised right columns), medians of 41: road 2.13 -> 1.86,
        # KITTI 2.20 -> 1.76, Middlebury 1.39 -> 1.16, road-full 2.79 -> 2.56 ms
        if 8 * (w - n_valid) > w:
            # many holes: selects (a branch on validity is mispredicted); every pixel has a
            # right column, so reading row_best there is safe
            for u in range(w):
                d32 = d_row[u]
                keep = v_row[u]
                claimed = np.float64(d32) < row_best[row_target[u]] - tolerance
                occ = keep & (claimed | ((u < b) & (d32 < b_minus_1)))
                c_row[u] = occ
                keep = keep & (not occ)
                v_row[u] = keep
                o_row[u] = d32 if keep else _F32_INF
                n += occ
        else:
            # few holes: branches (predicted; the vectorised loop above gathers row_best,
            # slower here)
            for u in range(w):
                d32 = d_row[u]
                keep = v_row[u]
                occ = keep and (np.float64(d32) < row_best[row_target[u]] - tolerance
                                or (u < b and d32 < b_minus_1))
                c_row[u] = occ
                keep = keep and not occ
                v_row[u] = keep
                o_row[u] = d32 if keep else _F32_INF
                n += occ
    counts[task] = n


def drop_occluded(disparity, valid, tolerance, start, out):
    """Both occlusion tests, their holes and the masked map, in one pass over the rows.

    ``occluded = uniqueness_occluded(...) | out_of_view_mask(...)`` (the tests read
    ``valid`` as it comes in), then ``valid &= ~occluded`` in place and
    ``out = np.where(valid, disparity, inf)``: issue 10, what the pipeline did in six
    passes over the map (two tests, or, and-not, where, astype).

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


# ----------------------------------------------------------------------------- speckle filter
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
            # bitwise & of bools: no short-circuit branches (KITTI 1.1 -> 0.56 ms)
            speck = keep & np.isfinite(d) & (fixed[y, u] == -1)
            keep = keep & (not speck)
            valid[y, u] = keep
            x = d if keep else _F32_INF
            # in place through disp itself (no output map): a separate output argument
            # that is disp failed the vectorised loop's overlap check and the scalar loop
            # ran (issue 10: KITTI, 1 thread, CPU time, medians of 41: 0.46 -> 0.07 ms)
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


# ----------------------------------------------------------------------------- hole filling
@njit(cache=True, nogil=True)
def _usable_task(task, tasks, disp, valid, use, row_has, counts):
    h, w = disp.shape
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    n = 0
    for y in range(y0, y1):
        m = 0
        for u in range(w):
            ok = valid[y, u] & np.isfinite(disp[y, u])  # &: no branch
            use[y, u] = ok
            m += ok
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


@njit(cache=True, inline="always")
def _np_minimum(a, b):
    """``np.minimum`` of two non-NaN values (the second when they compare equal)."""
    return a if a < b else b


@njit(cache=True, nogil=True)
def _fill_rows_task(task, tasks, disp, valid, filled, row_has):
    h, w = disp.shape
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    for y in range(y0, y1):
        # One pass: the holes of a run between two valid pixels (or a row end, inf) all
        # take the same value, the smaller of the two, written when the run ends (issue 10,
        # instead of a right-to-left scan of the whole row and a second pass: 1 thread,
        # medians of 41: road 1.00 -> 0.69, Middlebury 0.65 -> 0.51, road-full 1.22 ->
        # 0.74 ms; random holes, half of the map, 4.3 -> 3.6 ms)
        d_row = disp[y]
        v_row = valid[y]
        f_row = filled[y]
        left = _F32_INF
        start = 0  # the first hole of the current run
        has = False
        for u in range(w):
            x = d_row[u]
            f_row[u] = x
            if v_row[u]:
                if start < u:
                    fill = _np_minimum(left, x)
                    for j in range(start, u):
                        f_row[j] = fill
                left = x
                has = True
                start = u + 1
        fill = _np_minimum(left, _F32_INF)
        for j in range(start, w):
            f_row[j] = fill
        row_has[y] = has


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
    h, w = disp.shape
    u0, u1 = (task * w) // tasks, ((task + 1) * w) // tasks
    if u1 <= u0:
        return
    last = np.full(u1 - u0, _F32_INF, np.float32)
    n = u1 - u0
    for y in range(h):  # top down: the nearest valid value at or above
        d_row = disp[y, u0:u1]
        v_row = valid[y, u0:u1]
        o_row = up[y, u0:u1]
        for i in range(n):  # selects: vectorised across the columns
            x = d_row[i]  # both loaded before the select: a load in its arm is a branch
            # (issue 10: KITTI 1.33 -> 0.35 ms, 1 thread)
            prev = last[i]
            value = x if v_row[i] else prev
            last[i] = value
            o_row[i] = value
    last[:] = _F32_INF
    for y in range(h - 1, -1, -1):  # bottom up: at or below
        d_row = disp[y, u0:u1]
        v_row = valid[y, u0:u1]
        o_row = down[y, u0:u1]
        for i in range(n):
            x = d_row[i]
            prev = last[i]
            value = x if v_row[i] else prev
            last[i] = value
            o_row[i] = value


def nearest_along_columns(disp, valid):
    """Values of the nearest valid pixel above and below in each column, in the map's own
    (H, W) layout, without transposed copies (tasks over blocks of columns, rows streamed).

    Returns
    -------
    up, down : ndarray, float32, (H, W)
        The nearest valid value at or above (below) each pixel; inf where there is none.
    """
    h, w = disp.shape
    up = np.empty((h, w), np.float32)
    down = np.empty((h, w), np.float32)
    n = threads()
    tasks = 1 if n == 1 else max(1, min(w // 64, 4 * n))
    run_tasks(_nearest_columns_task, tasks, disp, valid, up, down)
    return up, down


@njit(cache=True, inline="always")
def _order(a, b):
    """``(a, b)`` in increasing order, swapped only when ``a > b`` (equal values keep their
    order: a network of such adjacent exchanges sorts stably, as an insertion sort)."""
    swap = a > b
    return (b if swap else a), (a if swap else b)


@njit(cache=True, inline="always")
def _inside_value(l_v, r_v, up_v, down_v, occluded):
    """The fill of one hole from its four nearest values (see :func:`fill_inside`)."""
    side = _np_minimum(l_v, r_v)
    # The nearest values are finite or +inf (none): sorting all four with +inf
    # last gives the finite ones in the order of the reference's insertion sort
    # of the finite values alone (left, right, up, down; stable on ties).  Selects
    # only: the pattern of holes is random, and branches mispredicted.
    a0, a1 = _order(l_v, r_v)
    a1, a2 = _order(a1, up_v)
    a0, a1 = _order(a0, a1)
    a2, a3 = _order(a2, down_v)
    a1, a2 = _order(a1, a2)
    a0, a1 = _order(a0, a1)
    n = (l_v != _F32_INF) + (r_v != _F32_INF) + (up_v != _F32_INF) + (down_v != _F32_INF)
    # median of the n finite ones: the middle one, or the float32 mean of the two
    median = a0 if n == 1 else ((a0 + a1) / _F32_TWO if n == 2 else (a1 if n == 3 else (a1 + a2) / _F32_TWO))
    return side if (occluded or n == 0) else median


@njit(cache=True, nogil=True)
def _fill_inside_task(task, tasks, disp, valid, occluded, up, down, out):
    h, w = disp.shape
    left = np.empty(w, np.float32)  # the task's own row buffers
    right = np.empty(w, np.float32)
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    for y in range(y0, y1):
        d_row = disp[y]
        v_row = valid[y]
        # the nearest valid value at or left of u and at or right of j = w - 1 - u: two
        # independent chains of selects in one loop (issue 10: two scans before; KITTI
        # _fill_inside_task, 1 thread, CPU time, medians of 41: 0.96 -> 0.61, 0.92 -> 0.59 ms)
        a = _F32_INF
        b = _F32_INF
        for u in range(w):
            j = w - 1 - u
            x = d_row[u]  # loaded before the select: a load in its arm compiles to a branch
            z = d_row[j]
            a = x if v_row[u] else a
            b = z if v_row[j] else b
            left[u] = a
            right[j] = b
        for u in range(w):  # no carried value: this loop vectorises
            fill = _inside_value(left[u], right[u], up[y, u], down[y, u], occluded[y, u])
            out[y, u] = disp[y, u] if valid[y, u] else fill


def fill_inside(disp, valid, occluded, up, down):
    """Fill with the median of the finite nearest values in four directions where a hole
    is not occluded and has one, else with the smaller row neighbour.

    The row neighbours are found on the way, in two row buffers that stay in the cache
    (issue 10: no left/right maps written and read back; KITTI fill 4.6 -> 2.6 ms with
    the column kernel).

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
    h = filled.shape[0]
    above = np.full(h, -1, np.int64)
    last = -1
    for y in range(h):
        if row_has[y]:
            last = y
        above[y] = last
    below = -1
    for y in range(h - 1, -1, -1):
        if row_has[y]:
            below = y
            continue
        up = above[y]
        if below < 0 or (up >= 0 and y - up <= below - y):
            filled[y, :] = filled[up, :]
        else:
            filled[y, :] = filled[below, :]


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


# ----------------------------------------------------------------------------- NumPy's float32 exp
@intrinsic
def _fma_f32(typingctx, a, b, c):
    """``a * b + c`` rounded once (``llvm.fma.f32``: the CPU's FMA instruction, or a correctly
    rounded library call where there is none)."""
    sig = types.float32(types.float32, types.float32, types.float32)

    def codegen(context, builder, signature, args):
        f32 = ir.FloatType()
        fn = builder.module.declare_intrinsic("llvm.fma", [f32], ir.FunctionType(f32, [f32, f32, f32]))
        return builder.call(fn, args)

    return sig, codegen


@intrinsic
def _int64_as_float64(typingctx, a):
    """The float64 whose bits are the int64 ``a``."""
    sig = types.float64(types.int64)

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.DoubleType())

    return sig, codegen


def _f32(bits: int) -> np.float32:
    """The float32 with these bits."""
    return np.array([bits], np.uint32).view(np.float32)[0]


# Constants of NumPy's SIMD float32 exp (numpy/_core/src/umath/npy_simd_data.h and the
# limits of simd_exp_FLOAT in loops_exponent_log.dispatch.c.src), as bit patterns
_EXP_LN2_HI = _f32(0xBF317200)  # NPY_CODY_WAITE_LOGE_2_HIGHf, -ln 2 high part
_EXP_LN2_LO = _f32(0xB5BFBE8E)  # NPY_CODY_WAITE_LOGE_2_LOWf
_EXP_MAGIC = _f32(0x4B400000)  # NPY_RINT_CVT_MAGICf, 1.5 * 2^23: adding it rounds to an integer
_EXP_LOG2E = _f32(0x3FB8AA3B)  # NPY_LOG2Ef
_EXP_P0, _EXP_P1, _EXP_P2, _EXP_P3, _EXP_P4, _EXP_P5 = (
    _f32(b) for b in (0x3F800000, 0x3F39CBD5, 0x3E7D4C58, 0x3D517D8C, 0x3BDD7159, 0x3A053DD8))
_EXP_Q0, _EXP_Q1, _EXP_Q2 = (_f32(b) for b in (0x3F800000, 0xBE8C6857, 0x3CB0E832))
_EXP_XMAX = _f32(0x42B17218)  # 88.72283935546875: inf at and above
_EXP_XMIN = _f32(0xC2CFF1B5)  # -103.97208404541015625: 0 at and below
_F32_NAN = np.float32(np.nan)


@njit(cache=True, inline="always", error_model="numpy")
def numpy_expf(x):
    """``np.exp`` of a float32, bit for bit, as NumPy computes it on x86 with AVX2+FMA3 or
    AVX512F (``simd_exp_FLOAT``): Cody-Waite reduction ``r = x - k ln 2`` with
    ``k = rint(x log2 e)``, the rational minimax ``P5(r) / Q2(r)`` by FMA (Horner), times
    ``2^k`` rounded once (AVX512's ``scalef``; the AVX2 path's integer exponent add and
    its division for subnormal results round the same).  Checked equal to ``np.exp`` on
    all 2^32 float32 values, NaN payloads included (``tests/kernels/test_finishing.py``
    checks a sample of every range).  Branch-free (selects), so that loops over it
    vectorise.

    Why not numba's ``math.exp``: it calls the C library's ``expf``, which differs from
    NumPy's in the last bit for about a third of the arguments, and the smoothing's
    reference (and so the maps this package produced so far) used ``np.exp``.
    """
    nan = x != x
    big = x >= _EXP_XMAX
    small = x <= _EXP_XMIN
    x = _F32_ZERO if (nan or big or small) else x
    k = x * _EXP_LOG2E
    k = k + _EXP_MAGIC
    k = k - _EXP_MAGIC
    r = _fma_f32(k, _EXP_LN2_HI, x)
    r = _fma_f32(k, _EXP_LN2_LO, r)
    r = _fma_f32(k, _F32_ZERO, r)  # NumPy's third Cody-Waite step (c3 = 0); kept for -0
    num = _fma_f32(_EXP_P5, r, _EXP_P4)
    num = _fma_f32(num, r, _EXP_P3)
    num = _fma_f32(num, r, _EXP_P2)
    num = _fma_f32(num, r, _EXP_P1)
    num = _fma_f32(num, r, _EXP_P0)
    den = _fma_f32(_EXP_Q2, r, _EXP_Q1)
    den = _fma_f32(den, r, _EXP_Q0)
    poly = num / den
    # poly * 2^k, k in [-150, 128]: exact in float64 (2^k built from its exponent bits),
    # then one rounding to float32, subnormal results included
    out = np.float32(np.float64(poly) * _int64_as_float64((np.int64(k) + np.int64(1023)) << np.int64(52)))
    out = _F32_NAN if nan else out
    out = _F32_INF if big else out
    return _F32_ZERO if small else out


@njit(cache=True, nogil=True, error_model="numpy")
def _exp_task(task, tasks, values, out):
    n = values.shape[0]
    i0, i1 = (task * n) // tasks, ((task + 1) * n) // tasks
    for i in range(i0, i1):
        out[i] = numpy_expf(values[i])


def numpy_exp(values):
    """:func:`numpy_expf` of a flat float32 array (a new array); the test hook of the kernel."""
    values = np.ascontiguousarray(values, np.float32).reshape(-1)
    out = np.empty_like(values)
    _exp_task(0, 1, values, out)
    return out


# ----------------------------------------------------------------------------- smoothing
@njit(cache=True, nogil=True)
def _residual_task(task, tasks, disp, base, valid, resid, use, row_lo, row_hi, row_use):
    h, w = disp.shape
    all_valid = valid.shape[0] != h  # no map: every finite pixel
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    for y in range(y0, y1):
        lo = _F32_INF
        hi = -_F32_INF
        any_use = False
        for u in range(w):
            d = disp[y, u]
            if np.isfinite(d):
                r = d - base[y, u]
                resid[y, u] = r
                lo = min(lo, r)
                hi = max(hi, r)
                ok = all_valid or valid[y, u]
                use[y, u] = ok
                any_use |= ok
            else:
                resid[y, u] = _F32_ZERO
                use[y, u] = False
        row_lo[y] = lo
        row_hi[y] = hi
        row_use[y] = any_use


def residual_and_range(disp, base, valid):
    """Residual ``disp - base`` (0 where disp is not finite), the pixels that may be
    averaged into others and the residual's finite range.

    Parameters
    ----------
    disp, base : ndarray, float32, (H, W)
    valid : ndarray, bool, (H, W), or None
        None: every finite pixel (no map to build and read).

    Returns
    -------
    resid : ndarray, float32, (H, W)
    use : ndarray, bool, (H, W)
        Valid and finite.
    row_lo, row_hi : ndarray, float32, (H,)
        Per-row minimum and maximum of the finite residuals (+inf / -inf: none).
    row_use : ndarray, bool, (H,)
        Whether the row has a pixel in ``use``.
    """
    h, w = disp.shape
    resid = np.empty((h, w), np.float32)
    use = np.empty((h, w), np.bool_)
    row_lo = np.empty(h, np.float32)
    row_hi = np.empty(h, np.float32)
    row_use = np.empty(h, np.bool_)
    if valid is None:
        valid = np.empty((0, 0), np.bool_)
    run_tasks(_residual_task, row_tasks(h), disp, base, valid, resid, use, row_lo, row_hi, row_use)
    return resid, use, row_lo, row_hi, row_use


@njit(cache=True, inline="always", error_model="numpy")
def _level_position(r, lo, step, top, top_plus_1):
    """Lower range level ``k = clip(floor((r - lo) / step), 0, top).astype(int32)`` of a
    residual (float32 arithmetic; NaN casts to INT32_MIN) and its interpolation weight
    ``t = pos - k`` (float64 difference rounded to float32, as NumPy promotes it).  Selects
    only (the cast of a clamped value), so that loops over it vectorise."""
    pos = (r - lo) / step
    inside = pos if pos < top_plus_1 else top
    k = np.int32(inside if pos >= _F32_ZERO else _F32_ZERO)
    k = k if pos == pos else np.int32(-2147483648)
    return k, np.float32(np.float64(pos) - np.float64(k))


@njit(cache=True, nogil=True, error_model="numpy")
def _row_levels(r_row, lo, step, top, top_plus_1, k_row, t_row):
    """:func:`_level_position` of a row of residuals into ``k_row`` and ``t_row``."""
    for u in range(r_row.shape[0]):
        k, t = _level_position(r_row[u], lo, step, top, top_plus_1)
        k_row[u] = k
        t_row[u] = t


@njit(cache=True, nogil=True, error_model="numpy")
def _range_levels_task(task, tasks, resid, lo, step, n_levels, low, up, row_used, k_row):
    h, w = resid.shape
    top = np.float32(n_levels - 2)
    top_plus_1 = np.float32(n_levels - 1)
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    k_row = k_row[task]
    for y in range(y0, y1):
        r_row = resid[y]
        for u in range(w):
            k_row[u] = _level_position(r_row[u], lo, step, top, top_plus_1)[0]
        flags = row_used[y]
        flags[:] = False
        for u in range(w):
            k = k_row[u]
            if k >= 0:
                flags[k] = True
            else:  # NaN residual: no level writes its shares
                low[y, u] = _F32_ZERO
                up[y, u] = _F32_ZERO


def range_levels(resid, lo, step, n_levels, low, up):
    """Which range levels the pixels interpolate from, per row and in all.

    The pixel's lower level is ``k0 = clip(floor((resid - lo) / step), 0, n_levels - 2)``
    (float32 arithmetic, :func:`_level_position`), its upper one ``k0 + 1``.

    Parameters
    ----------
    resid : ndarray, float32, (H, W)
    lo, step : float32
        Level k sits at ``lo + k step``.
    n_levels : int (>= 2)
    low, up : ndarray, float32, (H, W)
        The shares maps :func:`smooth_groups` fills: set to 0 here where the residual is
        NaN (no level, so no share is written there).

    Returns
    -------
    used : ndarray, bool, (n_levels,)
        Level k is the lower (k0) or the upper (k0 + 1) level of some pixel.
    row_lower : ndarray, bool, (H, n_levels)
        Row y has a pixel whose lower level is k (what :func:`smooth_groups` needs).
    """
    h, w = resid.shape
    row_used = np.empty((h, n_levels), np.bool_)
    tasks = row_tasks(h)
    run_tasks(_range_levels_task, tasks, resid, np.float32(lo), np.float32(step), int(n_levels), low, up,
              row_used, np.empty((tasks, w), np.int32))
    lower = row_used.any(axis=0)
    used = lower.copy()
    used[1:] |= lower[:-1]
    return used, row_used


@njit(cache=True, inline="always", error_model="numpy")
def _level_weights(resid, use, y, level, neg_inv2s2, radius, pad_n, pad_d, tmp):
    """Row y of a level's range weights ``w = exp(neg_inv2s2 (r - level)^2)`` (+0 where not
    used; NumPy's float32 ``exp``) and of ``w r`` (float32 product) into the float64 pad
    rows, as ``range_exponents`` + ``np.exp`` + ``cv2.boxFilter``'s row pass read them.
    Two loops (float32 weights into ``tmp``, then the float64 rows): one loop that mixes
    the float32 exp with float64 stores did not vectorise (2.3 vs 1.0 ms per level of a
    1280x720 map)."""
    r_row = resid[y]
    u_row = use[y]
    w = r_row.shape[0]
    for u in range(w):
        a = r_row[u] - level
        x = neg_inv2s2 * (a * a)
        # -inf where not used (exp gives +0), NaN stays NaN: the reference's use * exp(x)
        tmp[u] = numpy_expf(x if (u_row[u] or x != x) else -_F32_INF)
    dst_n = pad_n[radius:radius + w]
    dst_d = pad_d[radius:radius + w]
    for u in range(w):
        e = tmp[u]
        dst_d[u] = e
        dst_n[u] = e * r_row[u]


@njit(cache=True, inline="always", error_model="numpy")
def _direct_sums(pad, dst, k):
    """3- and 5-tap box sums of a padded row, left to right (``cv2.boxFilter``'s small kernels)."""
    w = dst.shape[0]
    if k == 3:
        for i in range(w):
            dst[i] = pad[i] + pad[i + 1] + pad[i + 2]
    else:
        for i in range(w):
            dst[i] = pad[i] + pad[i + 1] + pad[i + 2] + pad[i + 3] + pad[i + 4]


@njit(cache=True, inline="always", error_model="numpy")
def _running_sums_2(pa, pb, da, db, k):
    """Running box sums (window k) of two padded rows: add the entering element minus the
    leaving one, as ``cv2.boxFilter``'s row pass; two independent chains."""
    w = da.shape[0]
    sa = 0.0
    sb = 0.0
    for j in range(k):
        sa += pa[j]
        sb += pb[j]
    da[0] = sa
    db[0] = sb
    for i in range(w - 1):
        sa += pa[i + k] - pa[i]
        sb += pb[i + k] - pb[i]
        da[i + 1] = sa
        db[i + 1] = sb


@njit(cache=True, inline="always", error_model="numpy")
def _running_sums_4(pa, pb, pc, pd, da, db, dc, dd, k):
    """:func:`_running_sums_2` of four rows at once: four independent chains hide the
    latency of the float64 adds (each chain is serial, element after element)."""
    w = da.shape[0]
    sa = 0.0
    sb = 0.0
    sc = 0.0
    sd = 0.0
    for j in range(k):
        sa += pa[j]
        sb += pb[j]
        sc += pc[j]
        sd += pd[j]
    da[0] = sa
    db[0] = sb
    dc[0] = sc
    dd[0] = sd
    for i in range(w - 1):
        sa += pa[i + k] - pa[i]
        sb += pb[i + k] - pb[i]
        sc += pc[i + k] - pc[i]
        sd += pd[i + k] - pd[i]
        da[i + 1] = sa
        db[i + 1] = sb
        dc[i + 1] = sc
        dd[i + 1] = sd


@njit(cache=True, inline="always", error_model="numpy")
def _group_row_sums(resid, use, y, values, g0, active, n_active, neg_inv2s2, radius, pad, ring, tmp):
    """Box sums along row y of ``w r`` and ``w`` of the task's active levels into the ring
    slot of row y: level ``g0 + i`` (``values[g0 + i]``) for each ``i = active[j]``,
    j < n_active, in ``pad[i]`` and ``ring[i]``.  The task's buffers are
    indexed, never sliced: numba types a slice as of unknown layout, and the loops over it
    stopped vectorising (20.9 against 16.5 ms for the road pair)."""
    k = 2 * radius + 1
    slot = y % k
    for j in range(n_active):
        i = active[j]
        _level_weights(resid, use, y, values[g0 + i], neg_inv2s2, radius, pad[i, 0], pad[i, 1], tmp)
    if k == 3 or k == 5:
        for j in range(n_active):
            i = active[j]
            _direct_sums(pad[i, 0], ring[i, 0, slot], k)
            _direct_sums(pad[i, 1], ring[i, 1, slot], k)
        return
    j = 0
    while j + 1 < n_active:  # levels in pairs: four chains
        i = active[j]
        m = active[j + 1]
        _running_sums_4(pad[i, 0], pad[i, 1], pad[m, 0], pad[m, 1],
                        ring[i, 0, slot], ring[i, 1, slot], ring[m, 0, slot], ring[m, 1, slot], k)
        j += 2
    if j < n_active:
        i = active[j]
        _running_sums_2(pad[i, 0], pad[i, 1], ring[i, 0, slot], ring[i, 1, slot], k)


@njit(cache=True, nogil=True, error_model="numpy")
def _smooth_group_task(task, tasks, resid, use, lo, step, n_levels, level_ids, level_values, bounds, last_row,
                       row_used, neg_inv2s2, radius, low, up):
    h, w = resid.shape
    g0, g1 = bounds[task], bounds[task + 1]
    ng = g1 - g0
    if ng <= 0:
        return
    k = 2 * radius + 1
    eps = np.float32(1e-6)
    # the group's scratch, allocated per task (a few levels at a time: all levels' rings at
    # once would take 256 x 2 (2 radius + 1) W float64 on a wide-range map): per level a
    # ring of 2 radius + 1 row sums (w r and w), a zero-padded weight row, the column sums
    rings = np.empty((ng, 2, k, w))
    pads = np.zeros((ng, 2, w + 2 * radius))
    all_sums = np.zeros((ng, 2, w))
    zero = np.zeros(w)
    tmp = np.empty(w, np.float32)
    k_row = np.empty(w, np.int32)  # the output row's lower levels and weights
    t_row = np.empty(w, np.float32)
    top = np.float32(n_levels - 2)
    top_plus_1 = np.float32(n_levels - 1)
    active = np.arange(ng)
    y_end = 0
    for i in range(ng):
        y_end = max(y_end, last_row[g0 + i] + 1)
    for j in range(k - 1):  # padded rows 0 .. k-2 (image rows -radius .. radius-1)
        y = j - radius
        if 0 <= y < h:
            _group_row_sums(resid, use, y, level_values, g0, active, ng, neg_inv2s2, radius, pads, rings,
                            tmp)
        for i in range(ng):
            rn = rings[i, 0, y % k] if 0 <= y < h else zero
            rd = rings[i, 1, y % k] if 0 <= y < h else zero
            sum_n = all_sums[i, 0]
            sum_d = all_sums[i, 1]
            for u in range(w):
                sum_n[u] += rn[u]
                sum_d[u] += rd[u]
    # A level's running column sums carry their float64 rounding from the top row down (as
    # cv2.boxFilter's), so every level starts at row 0; it stops after the last row that
    # interpolates from it, and only rows that do divide and store shares.
    for y in range(y_end):
        n_active = 0
        for i in range(ng):
            if last_row[g0 + i] >= y:
                active[n_active] = i
                n_active += 1
        yp = y + radius  # entering row
        ym = y - radius  # leaving row
        if yp < h:
            _group_row_sums(resid, use, yp, level_values, g0, active, n_active, neg_inv2s2, radius, pads,
                            rings, tmp)
        r_row = resid[y]
        low_row = low[y]
        up_row = up[y]
        # the levels and weights of the row, once for all the task's levels (no maps: issue
        # 10, they were written by range_levels and read back per level)
        _row_levels(r_row, lo, step, top, top_plus_1, k_row, t_row)
        for j in range(n_active):
            i = active[j]
            g = g0 + i
            pn = rings[i, 0, yp % k] if yp < h else zero
            pd = rings[i, 1, yp % k] if yp < h else zero
            mn = rings[i, 0, ym % k] if ym >= 0 else zero
            md = rings[i, 1, ym % k] if ym >= 0 else zero
            sum_n = all_sums[i, 0]
            sum_d = all_sums[i, 1]
            if not row_used[y, g]:
                for u in range(w):
                    sum_n[u] = (sum_n[u] + pn[u]) - mn[u]
                    sum_d[u] = (sum_d[u] + pd[u]) - md[u]
                continue
            level = np.int32(level_ids[g])
            for u in range(w):
                s0n = sum_n[u] + pn[u]
                s0d = sum_d[u] + pd[u]
                sum_n[u] = s0n - mn[u]
                sum_d[u] = s0d - md[u]
                num = np.float32(s0n)
                den = np.float32(s0d)
                # the reference's np.maximum(den, 1e-6) is den where it is used
                tmp[u] = num / den if den > eps else r_row[u]
            # the shares where this level is the pixel's lower (upper) one: conditional
            # stores (a select that wrote the old value back elsewhere would race with the
            # task of the pixel's other level)
            for u in range(w):
                kk = k_row[u]
                if kk == level:
                    low_row[u] = (_F32_ONE - t_row[u]) * tmp[u]
                elif kk == level - 1:
                    up_row[u] = t_row[u] * tmp[u]


def _balanced_groups(cost, tasks, max_group):
    """Consecutive groups of levels, at most ``tasks`` groups of at most ``max_group`` levels,
    whose largest total ``cost`` is the least possible; the bounds of the groups (int64)."""
    n = cost.shape[0]
    total = int(cost.sum())

    def cuts(cap):
        out = [0]
        acc = 0
        for g in range(n):
            c = int(cost[g])
            if g > out[-1] and (acc + c > cap or g - out[-1] == max_group):
                out.append(g)
                acc = 0
            acc += c
        out.append(n)
        return out

    lo, hi = int(cost.max()), total
    while lo < hi:  # the least capacity that needs no more than ``tasks`` groups
        mid = (lo + hi) // 2
        if len(cuts(mid)) - 1 <= tasks:
            hi = mid
        else:
            lo = mid + 1
    return np.array(cuts(lo), np.int64)


def smooth_groups(resid, use, lo, step, n_levels, level_ids, level_values, row_lower, neg_inv2s2, radius, low, up,
                  max_group=4):
    """The box-filtered range levels of the piecewise-linear bilateral filter and each
    pixel's shares of its two levels, all in one pass per group of levels.

    A task takes a group of consecutive used levels (at most ``max_group``; at least one
    group per thread) and streams the rows through it: per entering row the range weights
    of its levels (:func:`numpy_expf`) and their row box sums (the float64 row pass of
    ``cv2.boxFilter(..., normalize=False, borderType=cv2.BORDER_CONSTANT)``, two levels'
    running sums interleaved), per output row the float64 running column sums, the
    estimate ``num / den`` (``resid`` where ``den <= 1e-6``) and, where the level is the
    pixel's lower (upper) level, the share ``(1 - t) est`` (``t est``).  No weight or
    estimate maps: a pixel's shares go to ``low`` and ``up`` (each pixel has one lower and
    one upper level, so the tasks write disjoint cells).  The values are those of the
    reference (``np.exp`` of the float32 exponents, one pair of ``cv2.boxFilter`` calls per
    level, the blend) bit for bit.  Before (issue 10, first round) the weights of a group
    of levels were maps, their ``np.exp`` a pass of its own and the estimates maps
    blended in a further pass.

    A level is filtered down to the last row that interpolates from it (its running sums
    still start at the top: their float64 rounding is the reference's), and only rows
    that interpolate from it divide and store shares; the groups split these rows evenly
    between the tasks (issue 10: on the road pair the five levels end at rows 343, 365,
    673, 719, 719 of 720, and the split was two levels against three; road smoothing, A/B
    in one process on the pipeline's inputs, medians of 21 on the loaded 2-core machine:
    2 threads 24.7 -> 13.7 ms, 1 thread 33.4 -> 24.9 ms).  Each task finds the levels and
    weights of an output row itself (:func:`_level_position`), and ``low``, ``up`` come
    without a zeroing pass (every pixel with a level gets both its shares written): no
    level, weight or zeroed maps (road smoothing, one thread, CPU time, medians of 21: 12.6
    -> 11.5, 12.0 -> 11.3 ms).

    Parameters
    ----------
    resid : ndarray, float32, (H, W)
    use : ndarray, bool, (H, W)
    lo, step : float32
        Level k sits at ``lo + k step``.
    n_levels : int
    level_ids : ndarray, int64, (L,)
        The used levels, increasing.
    level_values : ndarray, float32, (L,)
        Their residual values ``lo + k step``.
    row_lower : ndarray, bool, (H, n_levels)
        Whether row y has a pixel whose lower level is k (from :func:`range_levels`).
    neg_inv2s2 : float32
    radius : int (>= 1)
    low, up : ndarray, float32, (H, W)
        Receive the shares of each pixel's lower and upper level; the pixels without a
        level (NaN residual) must hold 0 already (what :func:`range_levels` writes).
    max_group : int

    Returns
    -------
    low, up : ndarray, float32, (H, W)
    """
    h, w = resid.shape
    n = level_ids.shape[0]
    if n == 0:
        return low, up
    level_ids = np.ascontiguousarray(level_ids, np.int64)
    # rows that interpolate from each used level: its lower or its upper level there
    row_used = row_lower[:, level_ids]
    below = level_ids > 0
    row_used[:, below] |= row_lower[:, level_ids[below] - 1]
    row_used = np.ascontiguousarray(row_used)
    last_row = (h - 1) - np.argmax(row_used[::-1], axis=0).astype(np.int64)  # each level is used somewhere
    # the work of a level: its row passes (to radius rows past its last row) and column passes
    cost = np.minimum(last_row + 1 + int(radius), h) + last_row + 1
    tasks = min(n, max(threads(), -(-n // int(max_group))))
    bounds = _balanced_groups(cost, tasks, int(max_group))
    run_tasks(_smooth_group_task, bounds.shape[0] - 1, resid, use, np.float32(lo), np.float32(step), int(n_levels),
              level_ids, np.ascontiguousarray(level_values, np.float32), bounds, last_row, row_used,
              np.float32(neg_inv2s2), int(radius), low, up)
    return low, up


@njit(cache=True, nogil=True, error_model="numpy")
def _combine_task(task, tasks, low, up, base, disp, non_negative):
    h, w = low.shape
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    for y in range(y0, y1):
        for u in range(w):
            d = disp[y, u]
            x = ((_F32_ZERO + low[y, u]) + up[y, u]) + base[y, u] if np.isfinite(d) else d
            # written over low through low itself: with a separate output argument that is
            # low, the vectorised loop's runtime overlap check failed and the scalar loop ran
            # (issue 10: road, 1 thread, CPU time, medians of 41: 0.66 -> 0.25 ms)
            low[y, u] = at_least_zero(x) if non_negative else x


def combine_shares(low, up, base, disp, non_negative=False):
    """The smoothed map: ``(0 + low) + up + base`` where ``disp`` is finite (the blend's
    float32 sum started at zero, lower share first), else ``disp``; float32 (H, W),
    written over ``low`` (no new map, no fresh pages) and returned.  ``non_negative``:
    then :func:`clamp_negative` of it, in the same pass."""
    run_tasks(_combine_task, row_tasks(disp.shape[0]), low, up, base, disp, bool(non_negative))
    return low


@njit(cache=True, nogil=True)
def _plane_task(task, tasks, a0, b1, b2, margin, out):
    h, w = out.shape
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    for y in range(y0, y1):
        row = a0 + b1 * np.float64(y)
        for u in range(w):
            out[y, u] = np.float32((row + b2 * np.float64(u)) - margin)


def shift_plane_f32(a0, b1, b2, margin, shape):
    """``shift_map(...).astype(np.float32)`` in one pass: ``((a0 + b1 v) + b2 u) - margin``
    in float64, rounded once to float32."""
    h, w = shape
    out = np.empty((h, w), np.float32)
    run_tasks(_plane_task, row_tasks(h), float(a0), float(b1), float(b2), float(margin), out)
    return out


@njit(cache=True, inline="always")
def at_least_zero(x):
    """``x``, or 0 where ``x < 0`` (NaN and -0 stay): the finished map's disparities are
    >= 0 (:func:`clamp_negative`, and the smoothing passes that clamp as they write)."""
    return _F32_ZERO if x < _F32_ZERO else x


@njit(cache=True, nogil=True)
def _clamp_task(task, tasks, a):
    h, w = a.shape
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    for y in range(y0, y1):
        for u in range(w):
            a[y, u] = at_least_zero(a[y, u])


def clamp_negative(a):
    """``a[a < 0] = 0`` in place (NaN and -0 stay), one pass; float32 (H, W)."""
    run_tasks(_clamp_task, row_tasks(a.shape[0]), a)
    return a


#: The compiled kernels of this module (nogil, cached on disk), run by :func:`run_tasks`.
KERNELS = (
    _uniqueness_task, _out_of_view_task, _fill_rows_task,
    copy_nearest_rows, _keep_valid_task, _residual_task, _range_levels_task, _exp_task, _smooth_group_task,
    _combine_task,
    _nearest_columns_task, _fixed_task,
    _restored_task, _drop_occluded_task, _fixed_finite_task, _drop_marked_task, _plane_task, _clamp_task,
    _fill_inside_task, _usable_task,
)
