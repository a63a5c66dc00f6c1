"""Counts that stay on the device until the pipeline asks for all of them at once.

A level of the pipeline counts its seeds, inherited and decided pixels and its diffusion
sweeps; on a GPU each count read at once would be a device-to-host copy (a synchronisation)
in the middle of the level.  A kernel writes the count into a slot of a small int64 device
array instead (:class:`CountPool`) and the driver returns a :class:`DeviceCount`;
:func:`counts_to_host` resolves any number of them with one copy per pool.  ``int()`` of a
single count works too (it downloads its pool, once).  The CUDA backend's
:func:`count_decided` lives here: a count of decided pixels left on the device.
"""

from __future__ import annotations

import threading

import numpy as np
from numba import cuda

from .cuda_launch import device_zeros, grid_2d, is_device

#: Slots of one pool; a pipeline run uses a few per level.
POOL_SLOTS = 64

_local = threading.local()


class CountPool:
    """An int64 device array of zeroed slots, handed out one by one, read back once."""

    def __init__(self, slots: int = POOL_SLOTS):
        self.array = device_zeros(int(slots), np.int64)  # zeroed on the device, for the atomic counts
        self.used = 0
        self.values: np.ndarray | None = None

    def full(self) -> bool:
        return self.values is not None or self.used >= self.array.shape[0]

    def take(self) -> int:
        slot = self.used
        self.used += 1
        return slot

    def read(self) -> np.ndarray:
        """Every slot, downloaded on the first call (the pool takes no more slots after it)."""
        if self.values is None:
            self.values = self.array.copy_to_host()
        return self.values


def next_slot() -> tuple[CountPool, int]:
    """A fresh slot of this thread's current pool (a new pool when it is full or was read)."""
    pool = getattr(_local, "pool", None)
    if pool is None or pool.full():
        pool = _local.pool = CountPool()
    return pool, pool.take()


class DeviceCount:
    """A count a kernel wrote (or will write) into ``pool.array[slot]``."""

    __slots__ = ("pool", "slot")

    def __init__(self, pool: CountPool, slot: int):
        self.pool = pool
        self.slot = slot

    def __int__(self) -> int:
        return int(self.pool.read()[self.slot])

    __index__ = __int__

    def __float__(self) -> float:
        return float(int(self))

    def __eq__(self, other) -> bool:
        return int(self) == other

    def __hash__(self) -> int:
        return hash(int(self))

    def __repr__(self) -> str:
        return f"DeviceCount({int(self)})" if self.pool.values is not None else f"DeviceCount(slot {self.slot})"


def counts_to_host(values) -> list[int]:
    """Plain ints of ``values`` (ints or :class:`DeviceCount`), one download per pool."""
    for value in values:
        if isinstance(value, DeviceCount):
            value.pool.read()
    return [int(v) for v in values]


@cuda.jit(cache=True)
def _count_kernel(disp, counts, slot):
    u, v = cuda.grid(2)
    if v < disp.shape[0] and u < disp.shape[1] and disp[v, u] >= 0:
        cuda.atomic.add(counts, slot, 1)


def count_decided(disparity):
    """Number of decided pixels (>= 0) of an integer disparity map, left on the device.

    Returns a :class:`~d3cli.kernels.device_counts.DeviceCount` (``int()`` of it, or
    :func:`counts_to_host` of many, downloads); a host map is counted on the host.
    """
    if not is_device(disparity):
        return int(np.count_nonzero(np.asarray(disparity) >= 0))
    h, w = disparity.shape
    pool, slot = next_slot()
    blocks, threads = grid_2d(w, h)
    _count_kernel[blocks, threads](disparity, pool.array, slot)
    return DeviceCount(pool, slot)
