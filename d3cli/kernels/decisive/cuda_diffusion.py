"""CUDA driver of the decisive diffusion: Jacobi sweeps over a frontier built on the
device; only the change counter comes back per sweep.  The contract:
:mod:`d3cli.kernels.backend`."""

from __future__ import annotations

import numpy as np
from numba import cuda

from ..cuda_launch import _copy, _dev, _f64, _grid_1d, _grid_2d, _is_device, _unpack, _zeros, ops
from .cuda import _least_costs, min_cost
from ..pixel import UNDECIDED


_diffuse_at = ops.diffuse_at


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

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.diffuse`.
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
