"""CUDA drivers of the matching cost: NCC from per-band integral images, the cosine
cost, the out-of-view invalidation.  The contract: :mod:`d3cli.kernels.backend`."""

from __future__ import annotations

import numba
import numpy as np
from numba import cuda

from ..cuda_launch import as_f64, grid_1d, grid_2d, is_device, on_device, ops, pack_volume, unpack_volume
from ..volume import MAX_CELLS
from .band_cuda import CELLS_BOUND


#: Largest float64 scratch (bytes) of the NCC cross-term prefix sums; the cost volume
#: is computed in bands of rows that fit (at least one row per band).
NCC_SCRATCH_BYTES = 1 << 29


_ncc_window_cost = ops.ncc_window_cost


_cosine_cost = ops.cosine_cost


def _index_and_cells(index, h, w, n_disp):
    """The device index (the full range, built on the device, when ``index`` is None) and
    the cells to allocate: the bound a device index from ``band_indexes`` carries, else
    read from the host index before the upload (any other device index costs one tiny
    download)."""
    if index is None:
        return dense_index(h, w, n_disp), int(h) * int(w) * int(n_disp)
    bound = getattr(index, CELLS_BOUND, None)
    if bound is not None:
        return index, int(bound)
    if is_device(index):
        last = index[index.shape[0] - 1:, index.shape[1] - 1:, :].copy_to_host()
    else:
        last = np.asarray(index)[-1:, -1:, :]
    return on_device(index), int(last[0, 0, 0]) + int(last[0, 0, 2])


@cuda.jit(cache=True)
def _dense_index(n_disp, index):
    u, v = cuda.grid(2)
    if v < index.shape[0] and u < index.shape[1]:
        index[v, u, 0] = (v * index.shape[1] + u) * n_disp
        index[v, u, 1] = 0
        index[v, u, 2] = n_disp


def dense_index(height, width, n_disp):
    """Index of the full-range volume (:func:`d3cli.kernels.volume.dense_index`), built on the device.

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.dense_index`.
    """
    h, w, n_disp = int(height), int(width), int(n_disp)
    if h * w * n_disp > MAX_CELLS:
        raise MemoryError(f"a {h}x{w}x{n_disp} cost volume has more than 2^31 cells")
    index = cuda.device_array((h, w, 3), np.int32)
    blocks, threads = grid_2d(w, h)
    _dense_index[blocks, threads](np.int32(n_disp), index)
    setattr(index, CELLS_BOUND, h * w * n_disp)  # its volume is sized without a copy
    return index


# ----------------------------------------------------------------------------- NCC cost (step 2)
@cuda.jit(cache=True)
def _row_prefixes(left, right, rows):
    """rows[k, y, x]: running sum of row y up to x of L, L^2, R, R^2 (k = 0..3), float64.

    One thread per (image and power, row), all four in one launch; each row is summed left to
    right as on the CPU, so the sums are the CPU's bit for bit.
    """
    i = cuda.grid(1)
    h = left.shape[0]
    if i >= 4 * h:
        return
    k = i // h
    y = i - k * h
    acc = 0.0
    for x in range(left.shape[1]):
        val = numba.float64(left[y, x]) if k < 2 else numba.float64(right[y, x])
        if k % 2 == 0:
            acc += val
        else:
            acc += val * val
        rows[k, y, x] = acc


@cuda.jit(cache=True)
def _column_prefixes(rows, ii):
    """(4, H+1, W+1) integral images from the row sums; one thread per (image, column).

    ``ii[k, y + 1, x + 1] = ii[k, y, x + 1] + rows[k, y, x]``: the CPU's recurrence, hence the
    same float64 values; the zero first row and column are written here too.
    """
    i = cuda.grid(1)
    n_cols = ii.shape[2]
    if i >= 4 * n_cols:
        return
    k = i // n_cols
    x = i - k * n_cols
    acc = 0.0
    ii[k, 0, x] = acc
    for y in range(rows.shape[1]):
        if x > 0:
            acc = acc + rows[k, y, x - 1]
        ii[k, y + 1, x] = acc


def _integral_images(d_left, d_right):
    """Integral images of L, L^2, R and R^2 (float64, (H+1, W+1) each) in two launches."""
    h, w = d_left.shape
    rows = cuda.device_array((4, h, w), np.float64)
    ii = cuda.device_array((4, h + 1, w + 1), np.float64)
    blocks, threads = grid_1d(4 * h)
    _row_prefixes[blocks, threads](d_left, d_right, rows)
    blocks, threads = grid_1d(4 * (w + 1))
    _column_prefixes[blocks, threads](rows, ii)
    return ii[0], ii[1], ii[2], ii[3]


@cuda.jit(cache=True)
def _cross_prefix(left, right, r, v_start, n_rows, prefix):
    """prefix[b, u + 1, d]: sum over columns <= u of the window-column sums of L(y, u) R(y, u - d).

    One thread per (disparity, row of the band); row v = v_start + b.  The same sums in
    the same order as ``cpu.ncc_cost_volume``.
    """
    d, b = cuda.grid(2)
    n_disp = prefix.shape[2]
    if d >= n_disp or b >= n_rows:
        return
    h = left.shape[0]
    w = left.shape[1]
    v = v_start + b
    v0 = max(0, v - r)
    v1 = min(h - 1, v + r)
    prefix[b, 0, d] = 0.0
    for u in range(w):
        s = 0.0
        if u - d >= 0:
            for y in range(v0, v1 + 1):
                s += numba.float64(left[y, u]) * numba.float64(right[y, u - d])
        prefix[b, u + 1, d] = prefix[b, u, d] + s


@cuda.jit(cache=True)
def _ncc_band(ii_l, ii_ll, ii_r, ii_rr, prefix, index, r, v_start, n_rows, min_variance, cost):
    """Costs of the bands of a band of rows; one thread per (column, row of the band)."""
    u, b = cuda.grid(2)
    h = index.shape[0]
    w = index.shape[1]
    if u >= w or b >= n_rows:
        return
    v = v_start + b
    off = index[v, u, 0]
    v0 = max(0, v - r)
    v1 = min(h - 1, v + r)
    for d in range(index[v, u, 1], index[v, u, 2]):
        if u - d < 0:
            cost[off + d] = 1.0
            continue
        c0 = max(u - r, d)
        c1 = min(u + r, w - 1)
        slr = prefix[b, c1 + 1, d] - prefix[b, c0, d]
        cost[off + d] = _ncc_window_cost(ii_l, ii_ll, ii_r, ii_rr, v0, v1, c0, c1, d, slr, min_variance)


def ncc_cost_volume(left, right, max_disparity, window, min_variance, index=None):
    """NCC cost volume ``(1 - NCC) / 2`` with box sums (docs/design.md, step 2), on the device.

    Integral images give the window sums of L, L^2, R and R^2; the cross term L*R comes
    from per-row prefix sums of window-column sums.  Rows are processed in bands so that
    the float64 scratch stays under :data:`NCC_SCRATCH_BYTES`.  The prefix sums cover
    every disparity of the level (one thread per disparity and row; cheap on a GPU),
    the costs only the cells of ``index``.

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.ncc_cost_volume`.
    """
    d_left = on_device(left)
    d_right = on_device(right)
    h, w = d_left.shape
    n_disp = int(max_disparity) + 1
    dense = index is None
    d_index, n_cells = _index_and_cells(index, h, w, n_disp)
    r = int(window) // 2
    ii_l, ii_ll, ii_r, ii_rr = _integral_images(d_left, d_right)
    cost = cuda.device_array(n_cells, np.float32)
    band = max(1, min(h, int(NCC_SCRATCH_BYTES) // ((w + 1) * n_disp * 8)))
    prefix = cuda.device_array((band, w + 1, n_disp), np.float64)
    for v_start in range(0, h, band):
        n_rows = min(band, h - v_start)
        blocks, threads = grid_2d(n_disp, n_rows)
        _cross_prefix[blocks, threads](d_left, d_right, r, v_start, n_rows, prefix)
        blocks, threads = grid_2d(w, n_rows)
        _ncc_band[blocks, threads](ii_l, ii_ll, ii_r, ii_rr, prefix, d_index, r, v_start, n_rows,
                                   as_f64(min_variance), cost)
    return pack_volume(cost, d_index, n_disp, (h, w, n_disp) if dense else None)


@cuda.jit(cache=True)
def _invalidate(cost, index):
    u, v = cuda.grid(2)
    if v < index.shape[0] and u < index.shape[1]:
        off = index[v, u, 0]
        for d in range(max(index[v, u, 1], u + 1), index[v, u, 2]):
            cost[off + d] = 1.0


def invalidate_out_of_view(cost):
    """Set every cell whose right pixel u - d is outside the image back to 1, in place.

    A host ``cost`` is updated in place as well; returns the device array (or Volume).

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.invalidate_out_of_view`.
    """
    flat, index, n_disp, dense_shape = unpack_volume(cost)
    h, w = index.shape[0], index.shape[1]
    blocks, threads = grid_2d(w, h)
    _invalidate[blocks, threads](flat, index)
    if dense_shape is not None and not is_device(cost):
        flat.reshape(*dense_shape).copy_to_host(cost)
    return pack_volume(flat, index, n_disp, dense_shape)


# ----------------------------------------------------------------------------- feature cost
@cuda.jit(cache=True)
def _cosine_kernel(fl, fr, nl, nr, index, cost):
    u, v = cuda.grid(2)
    if v < index.shape[0] and u < index.shape[1]:
        off = index[v, u, 0]
        for d in range(index[v, u, 1], index[v, u, 2]):
            cost[off + d] = _cosine_cost(fl, fr, nl, nr, v, u, d)


def cosine_cost_volume(fl, fr, nl, nr, max_disparity, index=None):
    """Deep-feature cost volume ``(1 - cos) / 2`` (see the CPU driver); a device array,
    or a Volume with ``index``.  One thread per pixel.

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.cosine_cost_volume`.
    """
    d_fl, d_fr, d_nl, d_nr = on_device(fl), on_device(fr), on_device(nl), on_device(nr)
    h, w = d_nl.shape
    n_disp = int(max_disparity) + 1
    dense = index is None
    d_index, n_cells = _index_and_cells(index, h, w, n_disp)
    cost = cuda.device_array(n_cells, np.float32)
    blocks, threads = grid_2d(w, h)
    _cosine_kernel[blocks, threads](d_fl, d_fr, d_nl, d_nr, d_index, cost)
    return pack_volume(cost, d_index, n_disp, (h, w, n_disp) if dense else None)
