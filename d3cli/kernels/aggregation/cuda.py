"""CUDA drivers of the cost aggregation: RBF weights, the recursive filter's passes
(one thread per line), the plain bilateral filter.  The contract: :mod:`d3cli.kernels.backend`."""

from __future__ import annotations

import numba
import numpy as np
from numba import cuda

from ..cuda_launch import as_f64, device_copy, grid_2d, on_device, ops, pack_volume, unpack_volume


_rbf_weight = ops.rbf_weight


# ----------------------------------------------------------------------------- aggregation (step 3)
@cuda.jit(cache=True)
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

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.rbf_weights`.
    """
    d_img = on_device(img)
    h, w = d_img.shape
    weights = cuda.device_array((h, w, 9), np.float32)
    blocks, threads = grid_2d(w, h)
    inv_ss2 = 1.0 / (sigma_space * sigma_space)
    inv_sc2 = 1.0 / (sigma_color * sigma_color)
    _rbf_weights_kernel[blocks, threads](d_img, as_f64(inv_ss2), as_f64(inv_sc2), weights)
    return weights


@cuda.jit(cache=True)
def _rbf_pass(src, dst, index, weights):
    """One pass of eq. 2; one thread per pixel, float32 accumulation in slot order as on
    the CPU; a neighbour whose band lacks the disparity contributes the pixel's own cell
    (``cpu.rbf_passes``)."""
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

    Ping-pong passes over two volumes; ``overwrite_input`` uses ``cost`` as the second
    buffer (two volumes at the peak, not three), which it then clobbers.

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.rbf_filter`.
    """
    flat, index, n_disp, dense_shape = unpack_volume(cost)
    d_weights = on_device(weights)
    if t_max == 0:
        return pack_volume(flat if overwrite_input else device_copy(flat), index, n_disp, dense_shape)
    h, w = index.shape[0], index.shape[1]
    blocks, threads = grid_2d(w, h)
    src = cuda.device_array(flat.shape, flat.dtype)
    _rbf_pass[blocks, threads](flat, src, index, d_weights)
    if t_max > 1:
        dst = flat if overwrite_input else cuda.device_array(flat.shape, flat.dtype)
        for _ in range(t_max - 1):
            _rbf_pass[blocks, threads](src, dst, index, d_weights)
            src, dst = dst, src
    return pack_volume(src, index, n_disp, dense_shape)


@cuda.jit(cache=True)
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

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.bilateral_filter`.
    """
    flat, index, n_disp, dense_shape = unpack_volume(cost)
    d_img = on_device(img)
    h, w = index.shape[0], index.shape[1]
    out = cuda.device_array(flat.shape, flat.dtype)
    inv_ss2 = 1.0 / (sigma_space * sigma_space)
    inv_sc2 = 1.0 / (sigma_color * sigma_color)
    blocks, threads = grid_2d(w, h)
    _bilateral_kernel[blocks, threads](flat, index, d_img, int(radius), as_f64(inv_ss2), as_f64(inv_sc2), out)
    return pack_volume(out, index, n_disp, dense_shape)
