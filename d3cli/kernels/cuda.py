"""CUDA backend: the per-pixel functions of ``pixel.py`` compiled with
``numba.cuda.jit(device=True)`` and driven by one thread per pixel or per
(pixel, disparity) cell.

Every public function mirrors the driver of the same name in ``kernels/cpu.py`` (the
reference: same arguments, shapes, dtypes and results) and accepts device arrays or
host arrays (uploaded on the way in).  Results stay on the device, so the pipeline
uploads the pair once and downloads the result once; :func:`to_host` brings any array
back.  Within a level the only per-step downloads are single counters
(:func:`count_decided`, the change counter of each diffusion sweep).

Exactness: the drivers evaluate the same expressions in the same order as the CPU
drivers (float64 window sums, float32 filter accumulation, Jacobi diffusion over the
same frontier set), so integer maps are equal and costs agree to rounding (the GPU
may contract a multiply-add into one FMA and its ``exp`` is not libm's).  Under the
CUDA simulator (``NUMBA_ENABLE_CUDASIM=1``) the kernels run as Python and the tests
compare them with the CPU drivers.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import cuda

from .pixel import UNDECIDED, build_ops
from .volume import Volume, dense_index

#: Threads per block (x, y) of the image-shaped grids; x runs along columns (or
#: column x disparity cells), y along rows.  Tests make it small to get several partly
#: filled blocks on odd sizes.
BLOCK_2D = (16, 16)
#: Threads per block of the one-dimensional grids (rows, columns, pixel lists).
BLOCK_1D = 256
#: Largest float64 scratch (bytes) of the NCC cross-term prefix sums; the cost volume
#: is computed in bands of rows that fit (at least one row per band).
NCC_SCRATCH_BYTES = 1 << 29

ops = build_ops(cuda.jit(device=True))
_ncc_window_cost = ops.ncc_window_cost
_cosine_cost = ops.cosine_cost
_rbf_weight = ops.rbf_weight
_seed_at = ops.seed_at
_diffuse_at = ops.diffuse_at
_band_min = ops.band_min
_inherit_patch_into = ops.inherit_patch_into
_subpixel_at = ops.subpixel_at
_sgm_step = ops.sgm_step
_pt_shift = ops.pt_shift
_bilinear_at = ops.bilinear_at
_pt_restore_at = ops.pt_restore_at


# ----------------------------------------------------------------------------- launch helpers
def _grid_1d(n):
    """(blocks, threads) covering ``n`` items with :data:`BLOCK_1D` threads per block."""
    threads = int(BLOCK_1D)
    return (max(1, -(-int(n) // threads)),), (threads,)


def _grid_2d(nx, ny):
    """(blocks, threads) covering an ``nx`` (fast, x) by ``ny`` (rows, y) grid."""
    bx, by = (int(b) for b in BLOCK_2D)
    return (max(1, -(-int(nx) // bx)), max(1, -(-int(ny) // by))), (bx, by)


def _per_pixel(kernel, shape, dtype, *args):
    """Launch ``kernel(*args, out)`` with one thread per pixel of an (H, W) map.

    ``out`` is a new (H, W) device array of ``dtype`` (the kernel's last argument), and
    is returned.
    """
    h, w = int(shape[0]), int(shape[1])
    out = cuda.device_array((h, w), dtype)
    blocks, threads = _grid_2d(w, h)
    kernel[blocks, threads](*args, out)
    return out


def _f64(x):
    """A float scalar argument as float64 (the CPU drivers' type, also under the simulator)."""
    return np.float64(x)


def _is_device(array) -> bool:
    """True for a CUDA device array (real or simulated), False for host arrays."""
    return not isinstance(array, np.ndarray) and hasattr(array, "copy_to_host")


def _dev(array):
    """``array`` on the device (uploaded when it is a host array)."""
    if _is_device(array):
        return array
    return cuda.to_device(np.ascontiguousarray(array))


def _copy(d_array):
    """A device copy of a device array."""
    out = cuda.device_array(d_array.shape, d_array.dtype)
    out.copy_to_device(d_array)
    return out


@cuda.jit
def _fill_zero(flat):
    i = cuda.grid(1)
    if i < flat.shape[0]:
        flat[i] = 0


def _zeros(n, dtype):
    """A zeroed 1-D device array, filled on the device (no host transfer)."""
    out = cuda.device_array(int(n), dtype)
    blocks, threads = _grid_1d(n)
    _fill_zero[blocks, threads](out)
    return out


def _unpack(cost):
    """``(flat device cost, device index, n_disp, dense shape or None)`` of a Volume or an
    (H, W, D) array (host or device), as ``cpu._unpack``."""
    if isinstance(cost, Volume):
        return _dev(cost.cost), _dev(cost.index), int(cost.n_disp), None
    d_cost = _dev(cost)
    h, w, n_disp = d_cost.shape
    return d_cost.reshape(h * w * n_disp), cuda.to_device(dense_index(h, w, n_disp)), n_disp, (h, w, n_disp)


def _pack(flat, index, n_disp, dense_shape):
    """The result in the caller's kind: a Volume of device arrays, or an (H, W, D) device array."""
    if dense_shape is not None:
        return flat.reshape(*dense_shape)
    return Volume(flat, index, n_disp)


def _index_and_cells(index, h, w, n_disp):
    """The device index (the full range when ``index`` is None) and its number of cells,
    read from the host index before the upload (a device index costs one tiny download)."""
    if index is None:
        index = dense_index(h, w, n_disp)
    if _is_device(index):
        last = index[index.shape[0] - 1:, index.shape[1] - 1:, :].copy_to_host()
    else:
        last = np.asarray(index)[-1:, -1:, :]
    return _dev(index), int(last[0, 0, 0]) + int(last[0, 0, 2])


# ----------------------------------------------------------------------------- NCC cost (step 2)
@cuda.jit
def _row_prefix(img, power, rows):
    """rows[y, x] = sum of img[y, :x + 1] ** power in float64 (one thread per row)."""
    y = cuda.grid(1)
    if y < img.shape[0]:
        row = 0.0
        for x in range(img.shape[1]):
            val = numba.float64(img[y, x])
            if power == 1:
                row += val
            else:
                row += val * val
            rows[y, x] = row


@cuda.jit
def _column_prefix(rows, ii):
    """(H+1, W+1) integral image from row prefix sums (one thread per column of ``ii``).

    ``ii[y + 1, x + 1] = ii[y, x + 1] + rows[y, x]``: the CPU's recurrence, hence the
    same float64 values.
    """
    x = cuda.grid(1)
    if x < ii.shape[1]:
        acc = 0.0
        ii[0, x] = acc
        for y in range(rows.shape[0]):
            if x > 0:
                acc = acc + rows[y, x - 1]
            ii[y + 1, x] = acc


def _integral_image(d_img, power):
    h, w = d_img.shape
    rows = cuda.device_array((h, w), np.float64)
    ii = cuda.device_array((h + 1, w + 1), np.float64)
    blocks, threads = _grid_1d(h)
    _row_prefix[blocks, threads](d_img, power, rows)
    blocks, threads = _grid_1d(w + 1)
    _column_prefix[blocks, threads](rows, ii)
    return ii


@cuda.jit
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


@cuda.jit
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
    """NCC cost volume ``(1 - NCC) / 2`` with box sums (DESIGN step 2), on the device.

    Integral images give the window sums of L, L^2, R and R^2; the cross term L*R comes
    from per-row prefix sums of window-column sums.  Rows are processed in bands so that
    the float64 scratch stays under :data:`NCC_SCRATCH_BYTES`.  The prefix sums cover
    every disparity of the level (one thread per disparity and row; cheap on a GPU),
    the costs only the cells of ``index``.

    Parameters
    ----------
    left, right : float32 (H, W), device or host
        Grey images, 0-255 scale.
    max_disparity : int
        Largest disparity of the level (``n_disp = max_disparity + 1``).
    window : int
        Odd window size.
    min_variance : float
        Grey-level variance at or below which a window is flat (cost 1).
    index : int32 (H, W, 3), host (uploaded here, once) or device, optional
        Bands to compute (:mod:`d3cli.kernels.volume`); default the full range.

    Returns
    -------
    device array, float32, (H, W, max_disparity + 1); with ``index`` a Volume
        1 where u - d < 0 or a window is flat.
    """
    d_left = _dev(left)
    d_right = _dev(right)
    h, w = d_left.shape
    n_disp = int(max_disparity) + 1
    dense = index is None
    d_index, n_cells = _index_and_cells(index, h, w, n_disp)
    r = int(window) // 2
    ii_l = _integral_image(d_left, 1)
    ii_ll = _integral_image(d_left, 2)
    ii_r = _integral_image(d_right, 1)
    ii_rr = _integral_image(d_right, 2)
    cost = cuda.device_array(n_cells, np.float32)
    band = max(1, min(h, int(NCC_SCRATCH_BYTES) // ((w + 1) * n_disp * 8)))
    prefix = cuda.device_array((band, w + 1, n_disp), np.float64)
    for v_start in range(0, h, band):
        n_rows = min(band, h - v_start)
        blocks, threads = _grid_2d(n_disp, n_rows)
        _cross_prefix[blocks, threads](d_left, d_right, r, v_start, n_rows, prefix)
        blocks, threads = _grid_2d(w, n_rows)
        _ncc_band[blocks, threads](ii_l, ii_ll, ii_r, ii_rr, prefix, d_index, r, v_start, n_rows,
                                   _f64(min_variance), cost)
    return _pack(cost, d_index, n_disp, (h, w, n_disp) if dense else None)


@cuda.jit
def _invalidate(cost, index):
    u, v = cuda.grid(2)
    if v < index.shape[0] and u < index.shape[1]:
        off = index[v, u, 0]
        for d in range(max(index[v, u, 1], u + 1), index[v, u, 2]):
            cost[off + d] = 1.0


def invalidate_out_of_view(cost):
    """Set every cell whose right pixel u - d is outside the image back to 1, in place.

    A host ``cost`` is updated in place as well; returns the device array (or Volume).

    Returns
    -------
    device array, float32, (H, W, D), or a Volume
    """
    flat, index, n_disp, dense_shape = _unpack(cost)
    h, w = index.shape[0], index.shape[1]
    blocks, threads = _grid_2d(w, h)
    _invalidate[blocks, threads](flat, index)
    if dense_shape is not None and not _is_device(cost):
        flat.reshape(*dense_shape).copy_to_host(cost)
    return _pack(flat, index, n_disp, dense_shape)


# ----------------------------------------------------------------------------- aggregation (step 3)
@cuda.jit
def _rbf_weights_kernel(img, inv_ss2, inv_sc2, weights):
    u, v = cuda.grid(2)
    h = img.shape[0]
    w = img.shape[1]
    if v >= h or u >= w:
        return
    total = 0.0
    for k in range(9):
        dy = k // 3 - 1
        dx = k % 3 - 1
        y = v + dy
        x = u + dx
        if 0 <= y < h and 0 <= x < w:
            wk = _rbf_weight(dy, dx, numba.float64(img[v, u]), numba.float64(img[y, x]), inv_ss2, inv_sc2)
            weights[v, u, k] = wk
            total += wk
        else:
            weights[v, u, k] = 0.0
    for k in range(9):
        # float64 division as on the CPU (explicit: the simulator follows NumPy's promotion)
        weights[v, u, k] = numba.float64(weights[v, u, k]) / total


def rbf_weights(img, sigma_space, sigma_color):
    """Normalised 3x3 bilateral weights per pixel (paper eq. 3), computed once per level.

    Returns
    -------
    device array, float32, (H, W, 9)
        Slot k is the neighbour (dy, dx) = (k // 3 - 1, k % 3 - 1); neighbours outside
        the image get weight 0.
    """
    d_img = _dev(img)
    h, w = d_img.shape
    weights = cuda.device_array((h, w, 9), np.float32)
    blocks, threads = _grid_2d(w, h)
    inv_ss2 = 1.0 / (sigma_space * sigma_space)
    inv_sc2 = 1.0 / (sigma_color * sigma_color)
    _rbf_weights_kernel[blocks, threads](d_img, _f64(inv_ss2), _f64(inv_sc2), weights)
    return weights


@cuda.jit
def _rbf_pass(src, dst, index, weights):
    """One pass of eq. 2; one thread per pixel, float32 accumulation in slot order as on
    the CPU; a neighbour whose band lacks the disparity contributes the pixel's own cell
    (``cpu._rbf_passes``)."""
    u, v = cuda.grid(2)
    h = index.shape[0]
    w = index.shape[1]
    if v >= h or u >= w:
        return
    off = index[v, u, 0]
    for d in range(index[v, u, 1], index[v, u, 2]):
        acc = numba.float32(0.0)
        for k in range(9):
            y = min(max(v + k // 3 - 1, 0), h - 1)
            x = min(max(u + k % 3 - 1, 0), w - 1)
            wk = weights[v, u, k]
            if index[y, x, 1] <= d and d < index[y, x, 2]:
                acc += wk * src[index[y, x, 0] + d]
            else:
                acc += wk * src[off + d]
        dst[off + d] = acc


def rbf_filter(cost, weights, t_max, overwrite_input=False):
    """Recursive bilateral filtering: ``t_max`` passes of the 3x3 kernel (paper eq. 2).

    Parameters
    ----------
    cost : Volume or float32 (H, W, D), device or host
    weights : float32 (H, W, 9), device or host
        From :func:`rbf_weights`.
    t_max : int
    overwrite_input : bool
        Use ``cost`` as the second ping-pong buffer (two volumes at the peak, not three);
        same result, ``cost`` is then clobbered (as ``kernels.cpu.rbf_filter``).

    Returns
    -------
    device array, float32, (H, W, D), or a Volume (the kind of ``cost``)
    """
    flat, index, n_disp, dense_shape = _unpack(cost)
    d_weights = _dev(weights)
    if t_max == 0:
        return _pack(flat if overwrite_input else _copy(flat), index, n_disp, dense_shape)
    h, w = index.shape[0], index.shape[1]
    blocks, threads = _grid_2d(w, h)
    src = cuda.device_array(flat.shape, flat.dtype)
    _rbf_pass[blocks, threads](flat, src, index, d_weights)
    if t_max > 1:
        dst = flat if overwrite_input else cuda.device_array(flat.shape, flat.dtype)
        for _ in range(t_max - 1):
            _rbf_pass[blocks, threads](src, dst, index, d_weights)
            src, dst = dst, src
    return _pack(src, index, n_disp, dense_shape)


@cuda.jit
def _bilateral_kernel(cost, index, img, radius, inv_ss2, inv_sc2, out):
    u, v = cuda.grid(2)
    h = index.shape[0]
    w = index.shape[1]
    if v >= h or u >= w:
        return
    off = index[v, u, 0]
    i_p = numba.float64(img[v, u])
    for d in range(index[v, u, 1], index[v, u, 2]):
        acc = 0.0
        total = 0.0
        for dy in range(-radius, radius + 1):
            y = v + dy
            if y < 0 or y >= h:
                continue
            for dx in range(-radius, radius + 1):
                xx = u + dx
                if xx < 0 or xx >= w:
                    continue
                wk = _rbf_weight(dy, dx, i_p, numba.float64(img[y, xx]), inv_ss2, inv_sc2)
                total += wk
                if index[y, xx, 1] <= d and d < index[y, xx, 2]:
                    acc += wk * numba.float64(cost[index[y, xx, 0] + d])
                else:
                    acc += wk * numba.float64(cost[off + d])
        out[off + d] = acc / total


def bilateral_filter(cost, img, radius, sigma_space, sigma_color):
    """One pass of a plain (2 radius + 1)^2 bilateral filter over every disparity slice.

    The ablation counterpart of RBF (paper Fig. 4): same kernel as eq. 3, larger
    support.  Returns a new device array (or Volume) of the kind of ``cost``.
    """
    flat, index, n_disp, dense_shape = _unpack(cost)
    d_img = _dev(img)
    h, w = index.shape[0], index.shape[1]
    out = cuda.device_array(flat.shape, flat.dtype)
    inv_ss2 = 1.0 / (sigma_space * sigma_space)
    inv_sc2 = 1.0 / (sigma_color * sigma_color)
    blocks, threads = _grid_2d(w, h)
    _bilateral_kernel[blocks, threads](flat, index, d_img, int(radius), _f64(inv_ss2), _f64(inv_sc2), out)
    return _pack(out, index, n_disp, dense_shape)


# ----------------------------------------------------------------------------- seeds (step 4)
@cuda.jit
def _seeds_kernel(cost, index, n_disp, pkrn_min, epsilon, lr_tolerance, exclusion, skip, has_skip, out):
    u, v = cuda.grid(2)
    if v < index.shape[0] and u < index.shape[1]:
        if has_skip and skip[v, u] >= 0:
            out[v, u] = UNDECIDED
        else:
            out[v, u] = _seed_at(cost, index, n_disp, v, u, pkrn_min, epsilon, lr_tolerance, exclusion)


def decisive_seeds(cost, pkrn_min, epsilon, lr_tolerance, exclusion, skip=None):
    """Sparse seed map (DESIGN step 4); int32 (H, W), -1 undecided; ``skip`` as on the CPU."""
    flat, index, n_disp, _ = _unpack(cost)
    has_skip = skip is not None
    d_skip = _dev(skip) if has_skip else _zeros(1, np.int32).reshape(1, 1)
    return _per_pixel(
        _seeds_kernel, index.shape, np.int32, flat, index, n_disp, _f64(pkrn_min), _f64(epsilon),
        int(lr_tolerance), int(exclusion), d_skip, has_skip,
    )


@cuda.jit
def _min_cost_kernel(cost, index, out):
    u, v = cuda.grid(2)
    if v < index.shape[0] and u < index.shape[1]:
        # pixel.band_min: the least cost the CPU's diffusion finds for itself
        out[v, u] = _band_min(cost, index, v, u) if index[v, u, 2] > index[v, u, 1] else numba.float32(1.0)


def min_cost(cost):
    """Least cost of every pixel over its band; float32 (H, W) device array (1 if empty)."""
    flat, index, _, _ = _unpack(cost)
    return _least_costs(flat, index)


def _least_costs(flat, index):
    """:func:`min_cost` of an unpacked volume (device arrays)."""
    return _per_pixel(_min_cost_kernel, index.shape, np.float32, flat, index)


# ----------------------------------------------------------------------------- diffusion (step 5)
# Counters of the frontier loop (one int32 device array): the number of active pixels of
# the sweep and the number of pixels the sweep changed.
_N_ACTIVE = 0
_N_CHANGED = 1


@cuda.jit
def _collect_decided(disp, changed, counters):
    """Flat indices of every decided pixel, appended through an atomic counter."""
    u, v = cuda.grid(2)
    w = disp.shape[1]
    if v < disp.shape[0] and u < w and disp[v, u] != UNDECIDED:
        i = cuda.atomic.add(counters, _N_CHANGED, 1)
        changed[i] = v * w + u


@cuda.jit
def _reset_counters(counters):
    if cuda.grid(1) == 0:
        counters[_N_ACTIVE] = 0
        counters[_N_CHANGED] = 0


@cuda.jit
def _build_frontier(changed, n_changed, stamp, sweep, active, counters, h, w, kappa_d):
    """Pixels within ``kappa_d`` of a changed pixel (the pixel itself excluded), deduplicated.

    One thread per changed pixel.  ``stamp[q]`` holds the last sweep that listed q; the
    atomic max lets exactly one thread list a pixel per sweep (the set is that of
    ``cpu._build_frontier``; only the order of the list differs).
    """
    i = cuda.grid(1)
    if i >= n_changed:
        return
    p = changed[i]
    v = p // w
    u = p % w
    for dv in range(-kappa_d, kappa_d + 1):
        y = v + dv
        if y < 0 or y >= h:
            continue
        for du in range(-kappa_d, kappa_d + 1):
            x = u + du
            if x < 0 or x >= w or (dv == 0 and du == 0):
                continue
            q = y * w + x
            if cuda.atomic.max(stamp, q, sweep) != sweep:
                j = cuda.atomic.add(counters, _N_ACTIVE, 1)
                active[j] = q


@cuda.jit
def _evaluate_frontier(cost, index, disp, min_cost, max_gap, active, counters, new_values, tau, kappa_d,
                       adversarial):
    """New state of every frontier pixel, reading the previous map only (Jacobi)."""
    i = cuda.grid(1)
    if i < counters[_N_ACTIVE]:
        p = active[i]
        w = disp.shape[1]
        new_values[i] = _diffuse_at(cost, index, disp, min_cost, max_gap, p // w, p % w, tau, kappa_d, adversarial)


@cuda.jit
def _apply_changes(disp, active, new_values, changed, counters):
    """Write the new states; list the pixels that changed (each frontier pixel is unique)."""
    i = cuda.grid(1)
    if i < counters[_N_ACTIVE]:
        p = active[i]
        w = disp.shape[1]
        v = p // w
        u = p % w
        if new_values[i] != disp[v, u]:
            disp[v, u] = new_values[i]
            j = cuda.atomic.add(counters, _N_CHANGED, 1)
            changed[j] = p


def diffuse(cost, disp0, min_cost, max_gap, tau, kappa_d, adversarial, max_sweeps):
    """Intra-scale decisive diffusion with a frontier (paper Algorithm 1, eq. 5-6).

    The frontier lives on the device: each sweep lists the pixels within ``kappa_d`` of
    the pixels the previous sweep changed (atomic counter + per-pixel stamp), evaluates
    them against the previous map, then applies the changes (Jacobi).  The only
    download per sweep is the change counter.

    Parameters
    ----------
    cost : Volume or float32 (H, W, D), device or host
    disp0 : int32 (H, W), device or host
        Sparse decisive map D_i^S (-1 undecided); not modified.
    min_cost : float32 (H, W), device or host, or None
        Least cost of each pixel (:func:`min_cost`); not read when ``max_gap < 0``;
        None: computed here when the gap test needs it.
    max_gap : float
        Accepted states cost at most min_cost + max_gap; < 0: off.
    tau, kappa_d : int
        Disparity tolerance and neighbourhood radius.
    adversarial : bool
        Allow decided pixels to switch to a strictly cheaper accepted candidate.
    max_sweeps : int
        Safeguard on the number of sweeps.

    Returns
    -------
    disp : device array, int32, (H, W)
    sweeps : int
        Sweeps run (the last one changed nothing unless the safeguard stopped it).
    """
    d_cost, d_index, _, _ = _unpack(cost)
    disp = _copy(disp0) if _is_device(disp0) else _dev(disp0)  # a new map either way
    if min_cost is None:
        # the gap test reads every frontier pixel's least cost: one pass over the volume
        # (the CPU driver finds it per pixel instead, pixel.band_min)
        d_min = _least_costs(d_cost, d_index) if max_gap >= 0 else _dev(np.zeros((1, 1), np.float32))
    else:
        d_min = _dev(min_cost)
    h, w = disp.shape
    n_pixels = h * w
    tau = int(tau)
    kappa_d = int(kappa_d)
    adversarial = bool(adversarial)
    max_gap = _f64(max_gap)
    neighbours = (2 * kappa_d + 1) ** 2 - 1
    counters = _zeros(2, np.int32)
    changed = cuda.device_array(n_pixels, np.int32)
    active = cuda.device_array(n_pixels, np.int32)
    new_values = cuda.device_array(n_pixels, np.int32)
    stamp = _zeros(n_pixels, np.int32)
    blocks, threads = _grid_2d(w, h)
    _collect_decided[blocks, threads](disp, changed, counters)
    n_changed = int(counters.copy_to_host()[_N_CHANGED])
    sweeps = 0
    while n_changed > 0 and sweeps < max_sweeps:
        sweeps += 1
        _reset_counters[1, 1](counters)
        blocks, threads = _grid_1d(n_changed)
        _build_frontier[blocks, threads](changed, n_changed, stamp, sweeps, active, counters, h, w, kappa_d)
        # The frontier size stays on the device: the grid covers its upper bound and
        # threads past the counter return at once.
        bound = min(n_pixels, n_changed * neighbours)
        if bound > 0:
            blocks, threads = _grid_1d(bound)
            _evaluate_frontier[blocks, threads](
                d_cost, d_index, disp, d_min, max_gap, active, counters, new_values, tau, kappa_d, adversarial
            )
            _apply_changes[blocks, threads](disp, active, new_values, changed, counters)
        n_changed = int(counters.copy_to_host()[_N_CHANGED])
    return disp, sweeps


# ----------------------------------------------------------------------------- inheritance (step 7)
@cuda.jit
def _inherit_kernel(cost, index, coarse, prc, dfm_pkrn_min, epsilon, candidates, out):
    """One thread per 2x2 patch: the patch tests once for its four fine pixels."""
    pu, pv = cuda.grid(2)
    if 2 * pv < index.shape[0] and 2 * pu < index.shape[1]:
        _inherit_patch_into(out, cost, index, coarse, pv, pu, prc, dfm_pkrn_min, epsilon, candidates)


def inherit(cost, coarse, prc, dfm_pkrn_min, epsilon, candidates=0):
    """Inter-scale decisive inheritance (paper Algorithm 2, eq. 7-9).

    Parameters
    ----------
    cost : Volume or float32 (H, W, D), device or host
        Cost volume of the finer level i (one thread per 2x2 patch, as the CPU's
        ``pixel.inherit_quad``: the patch tests once for its four pixels).
    coarse : int32 (>= H // 2, >= W // 2), device or host
        Disparity map of level i + 1 (-1 undecided).
    candidates : int
        0: symmetric candidate sets; 1: the per-pixel sets of the paper.

    Returns
    -------
    device array, int32, (H, W)
        Sparse map D_i^S.
    """
    flat, index, _, _ = _unpack(cost)
    h, w = int(index.shape[0]), int(index.shape[1])
    out = cuda.device_array((h, w), np.int32)
    blocks, threads = _grid_2d((w + 1) // 2, (h + 1) // 2)
    _inherit_kernel[blocks, threads](flat, index, _dev(coarse), bool(prc), _f64(dfm_pkrn_min), _f64(epsilon),
                                     np.int32(candidates), out)
    return out


# ----------------------------------------------------------------------------- semi-global smoothing (issue 16)
@cuda.jit(device=True)
def _all_inf(buffer, start, stop):
    for k in range(start, stop):
        buffer[k] = np.inf


@cuda.jit(device=True)
def _sgm_line(cost, index, line, along_rows, p1, p2, scratch, size, acc, forward_mode, backward_mode):
    """Both paths along one row (``along_rows``) or column of the image, forward then
    backward, with the line's two path buffers in ``scratch`` (``pixel.sgm_step``'s layout,
    inf outside the band); ``*_mode`` as the step's ``mode``."""
    n = index.shape[1] if along_rows else index.shape[0]
    start = 2 * size * line
    a, b = start, start + size
    _all_inf(scratch, start, start + 2 * size)
    plo, phi = 0, 0
    for i in range(n):
        v, u = (line, i) if along_rows else (i, line)
        _sgm_step(cost, index, v, u, (scratch, a), plo, phi, (scratch, b), p1, p2, acc, forward_mode)
        plo, phi = index[v, u, 1], index[v, u, 2]
        a, b = b, a
    _all_inf(scratch, start, start + 2 * size)
    plo, phi = 0, 0
    for i in range(n):
        v, u = (line, n - 1 - i) if along_rows else (n - 1 - i, line)
        _sgm_step(cost, index, v, u, (scratch, a), plo, phi, (scratch, b), p1, p2, acc, backward_mode)
        plo, phi = index[v, u, 1], index[v, u, 2]
        a, b = b, a


@cuda.jit
def _sgm_rows_kernel(cost, index, p1, p2, scratch, size, acc):
    v = cuda.grid(1)
    if v < index.shape[0]:
        _sgm_line(cost, index, v, True, p1, p2, scratch, size, acc, 0, 1)  # the first path stores


@cuda.jit
def _sgm_columns_kernel(cost, index, p1, p2, scratch, size, acc):
    u = cuda.grid(1)
    if u < index.shape[1]:
        _sgm_line(cost, index, u, False, p1, p2, scratch, size, acc, 1, 2)  # the last one scales


def sgm_smooth(cost, p1, p2):
    """Mean of four semi-global path costs of a volume (as the CPU backend's): one thread
    per row for the row paths, one per column for the column paths."""
    flat, index, n_disp, dense = _unpack(cost)
    h, w = int(index.shape[0]), int(index.shape[1])
    acc = _zeros(flat.shape[0], np.float32)  # cells outside every visible band stay 0
    p1, p2 = np.float32(p1), np.float32(p2)
    size = n_disp + 2
    scratch = cuda.device_array(2 * size * max(h, w), np.float32)  # inf-filled by the kernels
    blocks, threads = _grid_1d(h)
    _sgm_rows_kernel[blocks, threads](flat, index, p1, p2, scratch, size, acc)
    blocks, threads = _grid_1d(w)
    _sgm_columns_kernel[blocks, threads](flat, index, p1, p2, scratch, size, acc)
    return _pack(acc, index, n_disp, dense)


# ----------------------------------------------------------------------------- sub-pixel (step 8)
@cuda.jit
def _subpixel_kernel(cost, index, disp, out):
    u, v = cuda.grid(2)
    if v < disp.shape[0] and u < disp.shape[1]:
        out[v, u] = _subpixel_at(cost, index, disp, v, u)


def subpixel(cost, disp):
    """Parabola sub-pixel refinement (DESIGN step 8); float32 (H, W), inf where undecided."""
    d_disp = _dev(disp)
    flat, index, _, _ = _unpack(cost)
    return _per_pixel(_subpixel_kernel, d_disp.shape, np.float32, flat, index, d_disp)


# ----------------------------------------------------------------------------- perspective transformation (step 6)
@cuda.jit
def _pt_warp_kernel(right, a0, b1, b2, delta, out):
    x, v = cuda.grid(2)
    if v < right.shape[0] and x < right.shape[1]:
        out[v, x] = _bilinear_at(right, v, x - _pt_shift(a0, b1, b2, delta, v, x))


def pt_warp(right, a0, b1, b2, delta):
    """Right image warped by the road model (DESIGN step 6): ``R'(x, v) = R(x - s(x, v), v)``.

    Parameters
    ----------
    right : float32 (H, W), device or host
        Full-resolution grey right image.
    a0, b1, b2, delta : float
        Road model ``d = a0 + b1 v + b2 u`` and margin, full-resolution pixels.

    Returns
    -------
    device array, float32, (H, W)
        Bilinear samples; columns beyond the image replicate the border.
    """
    d_right = _dev(right)
    return _per_pixel(_pt_warp_kernel, d_right.shape, np.float32, d_right, _f64(a0), _f64(b1), _f64(b2), _f64(delta))


@cuda.jit
def _pt_restore_kernel(disp, a0, b1, b2, delta, out):
    u, v = cuda.grid(2)
    if v < disp.shape[0] and u < disp.shape[1]:
        out[v, u] = _pt_restore_at(disp[v, u], a0, b1, b2, delta, v, u)


def pt_restore(disp, a0, b1, b2, delta):
    """Full-range disparity from the disparity against the warped right image.

    ``d = d' (1 - b2) + s(u, v)`` (exact inverse of :func:`pt_warp`); inf stays inf.

    Parameters
    ----------
    disp : float32 (H, W), device or host
        Disparity ``d'`` of the left image against ``pt_warp(right, ...)``.

    Returns
    -------
    device array, float32, (H, W)
    """
    d_disp = _dev(disp)
    return _per_pixel(_pt_restore_kernel, d_disp.shape, np.float32, d_disp, _f64(a0), _f64(b1), _f64(b2), _f64(delta))


# ----------------------------------------------------------------------------- feature cost
@cuda.jit
def _cosine_kernel(fl, fr, nl, nr, index, cost):
    u, v = cuda.grid(2)
    if v < index.shape[0] and u < index.shape[1]:
        off = index[v, u, 0]
        for d in range(index[v, u, 1], index[v, u, 2]):
            cost[off + d] = _cosine_cost(fl, fr, nl, nr, v, u, d)


def cosine_cost_volume(fl, fr, nl, nr, max_disparity, index=None):
    """Deep-feature cost volume ``(1 - cos) / 2`` (see the CPU driver); a device array,
    or a Volume with ``index``.  One thread per pixel."""
    d_fl, d_fr, d_nl, d_nr = _dev(fl), _dev(fr), _dev(nl), _dev(nr)
    h, w = d_nl.shape
    n_disp = int(max_disparity) + 1
    dense = index is None
    d_index, n_cells = _index_and_cells(index, h, w, n_disp)
    cost = cuda.device_array(n_cells, np.float32)
    blocks, threads = _grid_2d(w, h)
    _cosine_kernel[blocks, threads](d_fl, d_fr, d_nl, d_nr, d_index, cost)
    return _pack(cost, d_index, n_disp, (h, w, n_disp) if dense else None)


# ----------------------------------------------------------------------------- array handling
def to_device(array):
    """The array on the device: host arrays are uploaded (C-contiguous), device arrays kept."""
    return _dev(array)


def to_host(array):
    """NumPy array of a device array (one download); host arrays pass through."""
    if _is_device(array):
        return array.copy_to_host()
    return np.asarray(array)


@cuda.jit
def _merge_kernel(primary, fallback, out):
    u, v = cuda.grid(2)
    if v < primary.shape[0] and u < primary.shape[1]:
        if primary[v, u] >= 0:
            out[v, u] = primary[v, u]
        else:
            out[v, u] = fallback[v, u]


def merge_sparse(primary, fallback):
    """``primary`` where decided (>= 0), else ``fallback``; int32 (H, W), a new device map."""
    d_primary = _dev(primary)
    return _per_pixel(_merge_kernel, d_primary.shape, np.int32, d_primary, _dev(fallback))


@cuda.jit
def _count_kernel(disp, counter):
    u, v = cuda.grid(2)
    if v < disp.shape[0] and u < disp.shape[1] and disp[v, u] >= 0:
        cuda.atomic.add(counter, 0, 1)


def count_decided(disparity) -> int:
    """Number of decided pixels (>= 0) of an integer disparity map (one scalar download)."""
    if not _is_device(disparity):
        return int(np.count_nonzero(np.asarray(disparity) >= 0))
    h, w = disparity.shape
    counter = _zeros(1, np.int64)
    blocks, threads = _grid_2d(w, h)
    _count_kernel[blocks, threads](disparity, counter)
    return int(counter.copy_to_host()[0])


__all__ = [
    "BLOCK_1D",
    "BLOCK_2D",
    "NCC_SCRATCH_BYTES",
    "bilateral_filter",
    "cosine_cost_volume",
    "count_decided",
    "decisive_seeds",
    "diffuse",
    "inherit",
    "invalidate_out_of_view",
    "min_cost",
    "merge_sparse",
    "ncc_cost_volume",
    "pt_restore",
    "pt_warp",
    "rbf_filter",
    "rbf_weights",
    "subpixel",
    "to_device",
    "to_host",
]
