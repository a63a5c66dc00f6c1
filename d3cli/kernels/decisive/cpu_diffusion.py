"""CPU driver of the decisive diffusion (pipeline step 5): Jacobi sweeps over a
frontier of pixels near a change; and the least cost per pixel its gap test reads.  The contract: :mod:`d3cli.kernels.backend`."""

from __future__ import annotations

import numpy as np
from numba import njit, prange
from numba.cpython.unsafe.numbers import trailing_zeros

from .. import compile_cache as _compile_cache  # noqa: F401  (chooses the numba cache folder first)
from ..cpu_common import ops, unpack_volume
from ..intrinsics import prefetch_cells
from ..pixel import UINT, UNDECIDED


_diffuse_at = ops.diffuse_at


_holds_own_disparity = ops.holds_own_disparity


_band_min = ops.band_min


#: :func:`_evaluate_pixels` prefetches the cells of the next this many frontier pixels
#: before it evaluates this many.
PREFETCH_BLOCK = 8


@njit(cache=True, error_model="numpy")
def _evaluate_pixels(cost, index, flat_index, disp, min_cost, max_gap, active, i0, i1, new_values, tau, kappa_d,
                     adversarial):
    """``new_values[i]`` for the frontier pixels ``active[i0:i1]``; ``flat_index`` is
    ``index`` flat.

    Block by block, the next block's cells are prefetched first (the frontier is sparse,
    its cells are not in the cache and the hardware prefetcher cannot guess them).  A
    prefetch per pixel inside the loop makes the loop compile worse.
    """
    w = UINT(disp.shape[1])
    for b in range(i0, i1, PREFETCH_BLOCK):
        e = min(b + PREFETCH_BLOCK, i1)
        _prefetch_pixels(cost, flat_index, active, e, min(e + PREFETCH_BLOCK, i1))
        if tau == 1 and kappa_d == 1:  # the defaults as constants: unrolled neighbour loops
            for i in range(b, e):
                p = UINT(active[i])  # unsigned: a plain division, no sign fix-up
                new_values[i] = _diffuse_at(cost, index, disp, min_cost, max_gap, p // w, p % w, 1, 1, adversarial)
        else:
            for i in range(b, e):
                p = UINT(active[i])
                new_values[i] = _diffuse_at(cost, index, disp, min_cost, max_gap, p // w, p % w, tau, kappa_d,
                                            adversarial)


@njit(cache=True, error_model="numpy")
def _prefetch_pixels(cost, flat_index, active, i0, i1):
    """Prefetch the bands of the frontier pixels ``active[i0:i1]`` (and the first cells
    of their right neighbours, which :func:`pixel.accept_state` reads)."""
    for i in range(i0, i1):
        k = 3 * active[i]
        off = flat_index[k]
        # to the band's end: the line of the right neighbour's first cells too
        prefetch_cells(cost, off + flat_index[k + 1], off + flat_index[k + 2])


@njit(parallel=True, cache=True, error_model="numpy")
def _evaluate_frontier(cost, index, flat_index, disp, min_cost, max_gap, active, n_active, new_values, tau, kappa_d,
                       adversarial):
    n_chunks = (n_active + FRONTIER_CHUNK - 1) // FRONTIER_CHUNK
    for c in prange(n_chunks):
        _evaluate_pixels(cost, index, flat_index, disp, min_cost, max_gap, active, c * FRONTIER_CHUNK,
                         min(n_active, (c + 1) * FRONTIER_CHUNK), new_values, tau, kappa_d, adversarial)


@njit(cache=True, error_model="numpy")
def _evaluate_frontier_serial(cost, index, flat_index, disp, min_cost, max_gap, active, n_active, new_values, tau,
                              kappa_d, adversarial):
    _evaluate_pixels(cost, index, flat_index, disp, min_cost, max_gap, active, 0, n_active, new_values, tau, kappa_d,
                     adversarial)


#: Frontier pixels per parallel task.
FRONTIER_CHUNK = 1024


#: Frontiers smaller than this are evaluated in the calling thread: waking the worker
#: threads costs more than the work (late sweeps touch a few hundred pixels).
SERIAL_FRONTIER = 4096


#: :func:`_plain_neighbourhoods` codes: nothing known; no neighbour decided; the pixel
#: decided and its decided neighbours all at its disparity.
MIXED = 0


NONE_DECIDED = 1


UNIFORM = 2


@njit(cache=True, error_model="numpy")
def _plain_neighbourhoods(disp0, v, plain):
    """``plain[u]`` for the inner pixels of row v (0 < v < H - 1) of ``disp0``:
    NONE_DECIDED, UNIFORM (the pixel decided, its decided neighbours at its disparity)
    or MIXED.  Branch-free, one pass over three rows: the compiler vectorises it."""
    up = disp0[v - 1]
    row = disp0[v]
    down = disp0[v + 1]
    for u in range(1, disp0.shape[1] - 1):
        d = row[u]
        a = up[u - 1]
        b = up[u]
        c = up[u + 1]
        e = row[u - 1]
        f = row[u + 1]
        g = down[u - 1]
        i = down[u]
        j = down[u + 1]
        top = max(max(max(a, b), max(c, e)), max(max(f, g), max(i, j)))
        # an undecided neighbour adds no candidate
        same = (((a == d) | (a < 0)) & ((b == d) | (b < 0)) & ((c == d) | (c < 0)) & ((e == d) | (e < 0))
                & ((f == d) | (f < 0)) & ((g == d) | (g < 0)) & ((i == d) | (i < 0)) & ((j == d) | (j < 0)) & (d >= 0))
        plain[u] = NONE_DECIDED if top < 0 else (UNIFORM if same else MIXED)


@njit(parallel=True, cache=True, error_model="numpy")
def _evaluate_all(cost, index, disp0, min_cost, max_gap, disp, tau, kappa_d, adversarial, row_changes):
    """First sweep: the new state of every pixel of ``disp0`` into ``disp``;
    ``row_changes[v + 1]``: how many pixels of row v changed.

    With tau = kappa_d = 1 (the defaults), the plain pixels are settled without
    :func:`pixel.diffuse_at`: a pixel without a decided neighbour has no candidate, and a
    decided pixel whose decided neighbours all hold its disparity d keeps it when d wins
    its one candidate set (:func:`pixel.holds_own_disparity`); :func:`_plain_neighbourhoods`
    finds them a row at a time.  Most pixels of a first sweep are plain (road pair,
    finest level: 97 %, KITTI 65 %), and the candidate loop's branches are what a pixel
    costs.
    """
    h, w = disp0.shape
    for prange_v in prange(h):
        # int64 as the frontier passes it (a prange index is uint64): one compiled variant
        # of the per-pixel functions instead of two, a shorter first compile
        v = np.int64(prange_v)
        n = 0
        # tau = kappa_d = 1 (the defaults) as constants: the compiler unrolls the
        # neighbour loops
        if tau == 1 and kappa_d == 1:
            plain = np.zeros(w, np.uint8)  # border pixels stay MIXED
            if 0 < v < h - 1:
                _plain_neighbourhoods(disp0, v, plain)
            for u in range(w):
                cur = disp0[v, u]
                kind = plain[u]
                if kind == NONE_DECIDED or (kind == UNIFORM and _holds_own_disparity(cost, index, v, u, cur)):
                    s = cur
                else:
                    s = _diffuse_at(cost, index, disp0, min_cost, max_gap, v, u, 1, 1, adversarial)
                disp[v, u] = s
                n += s != cur
        else:
            for u in range(w):
                s = _diffuse_at(cost, index, disp0, min_cost, max_gap, v, u, tau, kappa_d, adversarial)
                disp[v, u] = s
                n += s != disp0[v, u]
        row_changes[v + 1] = n


@njit(parallel=True, cache=True, error_model="numpy")
def _list_changes(disp0, disp, row_changes, changed):
    """Flat indices of the pixels where ``disp`` differs from ``disp0``, in row-major
    order; row v's start at ``row_changes[v]`` (cumulative counts)."""
    h, w = disp0.shape
    for v in prange(h):
        j = row_changes[v]
        for u in range(w):
            if disp[v, u] != disp0[v, u]:
                changed[j] = v * w + u
                j += 1


@njit(cache=True, error_model="numpy")
def _build_frontier(changed, n_changed, listed, row_listed, active, h, w, kappa_d):
    """Pixels within ``kappa_d`` of a changed pixel (the pixel itself excluded), deduplicated,
    in row-major order.

    ``listed`` is a bitmap of the map, ``(w + 63) // 64`` uint64 words per row, and
    ``row_listed`` a flag per row; both are all zero on entry and on return.  The pixels
    are marked, then collected row by row (in row-major order the evaluation reads the
    cost volume nearly sequentially).
    """
    words = (w + 63) // 64
    one = np.uint64(1)
    for i in range(n_changed):
        p = changed[i]
        v = p // w
        u = p % w
        for dv in range(-kappa_d, kappa_d + 1):
            y = v + dv
            if y < 0 or y >= h:
                continue
            row_listed[y] = 1
            for du in range(-kappa_d, kappa_d + 1):
                x = u + du
                if x < 0 or x >= w or (dv == 0 and du == 0):
                    continue
                listed[y * words + (x >> 6)] |= one << np.uint64(x & 63)
    n_active = 0
    for y in range(h):
        if row_listed[y] == 0:
            continue
        row_listed[y] = 0
        for k in range(words):
            word = listed[y * words + k]
            if word == 0:
                continue
            listed[y * words + k] = 0
            base = y * w + 64 * k
            while word != 0:
                active[n_active] = base + trailing_zeros(word)
                n_active += 1
                word &= word - one  # clear the lowest set bit
    return n_active


def diffuse(cost, disp0, min_cost, max_gap, tau, kappa_d, adversarial, max_sweeps):
    """Intra-scale decisive diffusion with a frontier (paper Algorithm 1, eq. 4-5).

    ``min_cost`` None: ``pixel.diffuse_at`` finds the least cost for the few pixels whose
    candidate gets as far as the gap test (no :func:`min_cost` pass over the volume).

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.diffuse`.
    """
    flat, index, _, _ = unpack_volume(cost)
    if min_cost is None:
        min_cost = np.empty((0, 0), np.float32)  # empty: diffuse_at finds the least cost itself
    return _diffuse(flat, index, disp0, min_cost, float(max_gap), int(tau), int(kappa_d), bool(adversarial),
                    int(max_sweeps))


@njit(cache=True, error_model="numpy")
def _diffuse(cost, index, disp0, min_cost, max_gap, tau, kappa_d, adversarial, max_sweeps):
    h, w = disp0.shape
    any_decided = False
    for p in range(h * w):
        if disp0.flat[p] != UNDECIDED:
            any_decided = True
            break
    if not any_decided or max_sweeps <= 0:
        return disp0.copy(), 0
    # The first frontier is nearly the whole image: evaluate every pixel in parallel,
    # reading disp0 and writing the new map, instead of listing the pixels serially.  The
    # same result: a pixel without a decided neighbour has no candidate and keeps its
    # state.  No copy of disp0, no full-size zeroed stamp: every full-size array written
    # here costs its page faults.
    disp = np.empty((h, w), np.int32)
    row_changes = np.zeros(h + 1, np.int64)
    _evaluate_all(cost, index, disp0, min_cost, max_gap, disp, tau, kappa_d, adversarial, row_changes)
    for v in range(h):
        row_changes[v + 1] += row_changes[v]
    n_changed = row_changes[h]
    # pixel lists in int32: 12 bytes a pixel less than int64 (a 1280x720 level: 11 MB);
    # only their used part is ever touched
    changed = np.empty(h * w, np.int32)
    _list_changes(disp0, disp, row_changes, changed)
    flat = disp.reshape(h * w)  # a view: writes go to disp
    flat_index = index.reshape(-1)
    listed = np.zeros(h * ((w + 63) // 64), np.uint64)
    row_listed = np.zeros(h, np.uint8)
    active = np.empty(h * w, np.int32)
    new_values = np.empty(h * w, np.int32)
    sweeps = 1
    while n_changed > 0 and sweeps < max_sweeps:
        sweeps += 1
        n_active = _build_frontier(changed, n_changed, listed, row_listed, active, h, w, kappa_d)
        if n_active < SERIAL_FRONTIER:
            _evaluate_frontier_serial(cost, index, flat_index, disp, min_cost, max_gap, active, n_active, new_values,
                                      tau, kappa_d, adversarial)
        else:
            _evaluate_frontier(cost, index, flat_index, disp, min_cost, max_gap, active, n_active, new_values, tau,
                               kappa_d, adversarial)
        # Jacobi: every frontier pixel read the previous map; apply all changes after.
        n_changed = 0
        for i in range(n_active):
            p = active[i]
            if new_values[i] != flat[p]:
                changed[n_changed] = p
                n_changed += 1
                new_values[n_changed - 1] = new_values[i]
        for i in range(n_changed):
            flat[changed[i]] = new_values[i]
    return disp, sweeps


# ----------------------------------------------------------------------------- least costs (the gap test's)
def min_cost(cost):
    """Least cost of every pixel over its band; float32 (H, W) (1 for an empty band)."""
    flat, index, _, _ = unpack_volume(cost)
    return _min_cost(flat, index)


@njit(parallel=True, cache=True, error_model="numpy")
def _min_cost(cost, index):
    h, w, _ = index.shape
    out = np.empty((h, w), np.float32)
    for v in prange(h):
        for u in range(w):
            # pixel.band_min, as the diffusion finds it for itself (CPU) and CUDA's min_cost
            out[v, u] = _band_min(cost, index, v, u) if index[v, u, 2] > index[v, u, 1] else np.float32(1.0)
    return out
