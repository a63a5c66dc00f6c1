"""CUDA driver of the decisive diffusion and the least cost per pixel its gap test reads: every sweep of a level in one cooperative kernel,
the frontier built and the change counter read on the device.  The contract:
:mod:`d3cli.kernels.backend`."""

from __future__ import annotations

import logging

import numba
import numpy as np
from numba import config, cuda

from .. import cuda_launch
from ..cuda_launch import as_f64, device_copy, is_device, on_device, ops, per_pixel, unpack_volume
from ..device_counts import DeviceCount, next_slot
from ..pixel import UNDECIDED

_diffuse_at = ops.diffuse_at
_band_min = ops.band_min
log = logging.getLogger(__name__)


# The frontier loop runs as ONE cooperative kernel per level: every sweep's phases (list
# the frontier, evaluate it, apply the changes) are separated by grid-wide barriers, and the
# change counter is read on the device, so a level's diffusion costs one launch and no host
# round trip (a host loop costs three launches and one download per sweep, and a 720p road
# pair runs about two hundred sweeps).  Where a cooperative launch is refused (a toolkit
# without the device runtime library, an old device) the same phases run as one kernel each
# from a host loop that reads the change counter after every sweep.  Counters (one int32 device array): the frontier size
# and the change count of each sweep, in two slots by sweep parity, so that a slot is reset
# one phase before it is filled and never while another thread may still read it.  The
# number of sweeps run goes into a slot of the device counts (read with the level's other
# counts, not here).
_ACTIVE = 0  # + sweep % 2
_CHANGED = 2  # + sweep % 2
_N_COUNTERS = 4


@cuda.jit(device=True)
def _start_phase(disp, stamp, counters, start, stride):
    """Zero the stamps and the counters."""
    h, w = disp.shape
    for p in range(start, h * w, stride):
        stamp[p] = 0
    for c in range(start, _N_COUNTERS, stride):
        counters[c] = 0


@cuda.jit(device=True)
def _collect_phase(disp, counters, changed, start, stride):
    """Sweep 0: every decided pixel has "changed" (listed in slot 0)."""
    h, w = disp.shape
    for p in range(start, h * w, stride):
        if disp[p // w, p % w] != UNDECIDED:
            changed[cuda.atomic.add(counters, _CHANGED, 1)] = p


@cuda.jit(device=True)
def _build_phase(changed, n_changed, stamp, sweep, active, counters, h, w, kappa_d, start, stride):
    """The frontier of ``sweep``: pixels within ``kappa_d`` of a pixel the previous sweep
    changed (the pixel itself excluded), each listed once (``stamp[q]`` holds the last sweep
    that listed q; the atomic max lets exactly one thread list it)."""
    slot = sweep % 2
    if start == 0:
        counters[_CHANGED + slot] = 0  # last read at the start of sweep - 1
    n_pixels = h * w
    for i in range(start, n_changed, stride):
        p = changed[(1 - slot) * n_pixels + i]
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
                    active[cuda.atomic.add(counters, _ACTIVE + slot, 1)] = q


@cuda.jit(device=True)
def _evaluate_phase(cost, index, disp, min_cost, max_gap, tau, kappa_d, adversarial, active, n_active,
                    new_values, start, stride):
    """New state of every frontier pixel, reading the previous map only (Jacobi)."""
    w = disp.shape[1]
    for i in range(start, n_active, stride):
        p = active[i]
        new_values[i] = _diffuse_at(cost, index, disp, min_cost, max_gap, p // w, p % w, tau, kappa_d, adversarial)


@cuda.jit(device=True)
def _apply_phase(disp, active, n_active, new_values, changed, counters, sweep, start, stride):
    """Write the new states; list the pixels that changed (each frontier pixel is unique)."""
    slot = sweep % 2
    if start == 0:
        counters[_ACTIVE + 1 - slot] = 0  # the next sweep's frontier; last read a sweep ago
    h, w = disp.shape
    for i in range(start, n_active, stride):
        p = active[i]
        v = p // w
        u = p % w
        if new_values[i] != disp[v, u]:
            disp[v, u] = new_values[i]
            changed[slot * h * w + cuda.atomic.add(counters, _CHANGED + slot, 1)] = p


@cuda.jit(cache=True)
def _diffuse_level(cost, index, disp, min_cost, max_gap, tau, kappa_d, adversarial, max_sweeps, changed, active,
                   new_values, stamp, counters, counts, count_slot):
    """Paper Algorithm 1 on the device: sweeps until one changes nothing (or max_sweeps).

    Launched cooperatively (``cuda.cg.this_grid().sync()``); every loop is grid-strided, so
    the grid may be smaller than the image.  The frontier set and the Jacobi order are those
    of the CPU driver; only the order of the lists differs, which changes no result (each
    frontier pixel is evaluated against the previous map only).
    """
    grid = cuda.cg.this_grid()
    start = cuda.grid(1)
    stride = cuda.gridsize(1)
    h, w = disp.shape
    _start_phase(disp, stamp, counters, start, stride)
    grid.sync()
    _collect_phase(disp, counters, changed, start, stride)
    grid.sync()
    sweep = 0
    while True:
        n_changed = counters[_CHANGED + sweep % 2]  # every thread reads it after the same barrier
        if n_changed == 0 or sweep >= max_sweeps:
            break
        sweep += 1
        _build_phase(changed, n_changed, stamp, sweep, active, counters, h, w, kappa_d, start, stride)
        grid.sync()
        n_active = counters[_ACTIVE + sweep % 2]
        _evaluate_phase(cost, index, disp, min_cost, max_gap, tau, kappa_d, adversarial, active, n_active,
                        new_values, start, stride)
        grid.sync()
        _apply_phase(disp, active, n_active, new_values, changed, counters, sweep, start, stride)
        grid.sync()
    if start == 0:
        counts[count_slot] = sweep


# The host-loop fallback: one kernel per phase, the counters read on the device.
@cuda.jit(cache=True)
def _start_kernel(disp, stamp, counters):
    _start_phase(disp, stamp, counters, cuda.grid(1), cuda.gridsize(1))


@cuda.jit(cache=True)
def _collect_kernel(disp, counters, changed):
    _collect_phase(disp, counters, changed, cuda.grid(1), cuda.gridsize(1))


@cuda.jit(cache=True)
def _build_kernel(changed, stamp, sweep, active, counters, h, w, kappa_d):
    n_changed = counters[_CHANGED + (sweep - 1) % 2]
    _build_phase(changed, n_changed, stamp, sweep, active, counters, h, w, kappa_d, cuda.grid(1), cuda.gridsize(1))


@cuda.jit(cache=True)
def _evaluate_kernel(cost, index, disp, min_cost, max_gap, tau, kappa_d, adversarial, active, counters,
                     new_values, sweep):
    _evaluate_phase(cost, index, disp, min_cost, max_gap, tau, kappa_d, adversarial, active,
                    counters[_ACTIVE + sweep % 2], new_values, cuda.grid(1), cuda.gridsize(1))


@cuda.jit(cache=True)
def _apply_kernel(disp, active, new_values, changed, counters, sweep):
    _apply_phase(disp, active, counters[_ACTIVE + sweep % 2], new_values, changed, counters, sweep,
                 cuda.grid(1), cuda.gridsize(1))


#: Run a level's sweeps in one cooperative kernel when the device allows it (False: always
#: the host loop; the tests check both).
COOPERATIVE = True
#: Whether this process's cooperative launches work (None: not tried yet).
_cooperative: list = [None]


def _cooperative_grid(kernel, args, threads, wanted):
    """Blocks of a cooperative launch: at most what the device can hold resident at once.

    The simulator runs a cooperative grid as one block only.
    """
    if config.ENABLE_CUDASIM:
        return 1
    argtypes = tuple(kernel.typeof_pyval(a) for a in args)
    resident = kernel.compile(argtypes).max_cooperative_grid_blocks(threads)
    return max(1, min(int(wanted), int(resident)))


def _host_loop(disp, d_cost, d_index, d_min, max_gap, tau, kappa_d, adversarial, max_sweeps, changed, active,
               new_values, stamp, counters, blocks, threads):
    """The fallback: the phases from the host, one copy of the counters per sweep."""
    h, w = disp.shape
    _start_kernel[blocks, threads](disp, stamp, counters)
    _collect_kernel[blocks, threads](disp, counters, changed)
    sweep = 0
    while sweep < max_sweeps and int(counters.copy_to_host()[_CHANGED + sweep % 2]) > 0:
        sweep += 1
        _build_kernel[blocks, threads](changed, stamp, sweep, active, counters, h, w, kappa_d)
        _evaluate_kernel[blocks, threads](d_cost, d_index, disp, d_min, max_gap, tau, kappa_d, adversarial, active,
                                          counters, new_values, sweep)
        _apply_kernel[blocks, threads](disp, active, new_values, changed, counters, sweep)
    return sweep


def diffuse(cost, disp0, min_cost, max_gap, tau, kappa_d, adversarial, max_sweeps):
    """Intra-scale decisive diffusion with a frontier (paper Algorithm 1).

    One cooperative kernel runs every sweep (:func:`_diffuse_level`); the map never leaves
    the device (the fallback: :func:`_host_loop`).  The contract (arguments, shapes,
    results): :meth:`d3cli.kernels.backend.Backend.diffuse`.
    """
    d_cost, d_index, _, _ = unpack_volume(cost)
    disp = device_copy(disp0) if is_device(disp0) else on_device(disp0)  # a new map either way
    if min_cost is None:
        # the gap test reads every frontier pixel's least cost: one pass over the volume
        # (the CPU driver finds it per pixel instead, pixel.band_min)
        d_min = _least_costs(d_cost, d_index) if max_gap >= 0 else cuda.device_array((1, 1), np.float32)
    else:
        d_min = on_device(min_cost)
    h, w = disp.shape
    n_pixels = h * w
    counters = cuda.device_array(_N_COUNTERS, np.int32)
    changed = cuda.device_array(2 * n_pixels, np.int32)
    active = cuda.device_array(n_pixels, np.int32)
    new_values = cuda.device_array(n_pixels, np.int32)
    stamp = cuda.device_array(n_pixels, np.int32)
    pool, slot = next_slot()
    args = (d_cost, d_index, disp, d_min, as_f64(max_gap), int(tau), int(kappa_d), bool(adversarial),
            int(max_sweeps), changed, active, new_values, stamp, counters, pool.array, slot)
    threads = int(cuda_launch.BLOCK_1D)
    wanted = -(-n_pixels // threads)
    if COOPERATIVE and _cooperative[0] is not False:
        try:
            blocks = _cooperative_grid(_diffuse_level, args, threads, wanted)
            _diffuse_level[blocks, threads](*args)
            _cooperative[0] = True
            return disp, DeviceCount(pool, slot)
        except Exception as exc:  # no cooperative launch here: the host loop from now on
            if _cooperative[0]:
                raise  # it worked before: a real failure, not a missing feature
            _cooperative[0] = False
            log.warning("CUDA diffusion: cooperative launch unavailable (%s); one launch per phase instead",
                        str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__)
    sweeps = _host_loop(disp, d_cost, d_index, d_min, as_f64(max_gap), int(tau), int(kappa_d), bool(adversarial),
                        int(max_sweeps), changed, active, new_values, stamp, counters, (wanted,), (threads,))
    return disp, sweeps


# ----------------------------------------------------------------------------- least costs (the gap test's)
@cuda.jit(cache=True)
def _min_cost_kernel(cost, index, out):
    u, v = cuda.grid(2)
    if v < index.shape[0] and u < index.shape[1]:
        # pixel.band_min: the least cost the CPU's diffusion finds for itself
        out[v, u] = _band_min(cost, index, v, u) if index[v, u, 2] > index[v, u, 1] else numba.float32(1.0)


def min_cost(cost):
    """Least cost of every pixel over its band; float32 (H, W) device array (1 if empty)."""
    flat, index, _, _ = unpack_volume(cost)
    return _least_costs(flat, index)


def _least_costs(flat, index):
    """:func:`min_cost` of an unpacked volume (device arrays)."""
    return per_pixel(_min_cost_kernel, index.shape, np.float32, flat, index)
