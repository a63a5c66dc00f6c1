"""Count (and on a GPU, time) the CUDA kernel launches and host/device copies of a block of code.

A GPU program is fast when the device does the work without waiting on the host: every
launch costs tens of microseconds of driver time, every device-to-host copy a full
synchronisation.  :func:`count_cuda_calls` makes both visible, on a GPU and under the CUDA
simulator (``NUMBA_ENABLE_CUDASIM=1``), so that a budget can be asserted by a test on a
machine without a GPU::

    with count_cuda_calls() as calls:
        D3Stereo(config).compute(left, right)
    calls.launches, calls.device_to_host, calls.by_kernel.most_common(5)

How it counts (numba-cuda's and numba's bundled CUDA target, and the simulator):

* a launch is a call of a configured kernel, ``kernel[grid, block](...)``:
  ``CUDADispatcher.call`` on a GPU, ``FakeCUDAKernel.__call__`` in the simulator (device
  functions called from kernels are not launches);
* a device-to-host copy is a call of the driver's ``device_to_host`` on a GPU, and of
  ``FakeCUDAArray.copy_to_host`` in the simulator: explicit ``copy_to_host`` calls and the
  implicit copy back of a NumPy array passed to a kernel both go through them;
* host-to-device copies likewise (``host_to_device``; ``FakeCUDAArray.copy_to_device`` in the
  simulator, which misses some uploads: a figure to read on a GPU).

``timing=True`` synchronises the device around every launch and records its wall time per
kernel name (meaningful on a GPU only; it serialises the stream, so a timed run is slower
than an untimed one).  The hooks are installed on entry and removed on exit; counting
blocks do not nest.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections import Counter, defaultdict
from dataclasses import dataclass, field

_lock = threading.Lock()
_active: list[CudaCalls] = []


@dataclass
class CudaCalls:
    """What happened inside one :func:`count_cuda_calls` block."""

    launches: int = 0
    device_to_host: int = 0
    host_to_device: int = 0
    #: Kernel name -> launches.
    by_kernel: Counter = field(default_factory=Counter)
    #: Kernel name -> seconds (``timing=True`` only), each launch synchronised.
    seconds: defaultdict = field(default_factory=lambda: defaultdict(float))
    timing: bool = False


def _kernel_name(kernel) -> str:
    fn = getattr(kernel, "py_func", None) or getattr(kernel, "fn", None) or kernel
    return getattr(fn, "__name__", type(kernel).__name__)


def _record_launch(name: str, seconds: float | None) -> None:
    for calls in _active:
        calls.launches += 1
        calls.by_kernel[name] += 1
        if seconds is not None:
            calls.seconds[name] += seconds


def _count(attr: str) -> None:
    for calls in _active:
        setattr(calls, attr, getattr(calls, attr) + 1)


def _hooks(simulator: bool):
    """[(owner, attribute, wrapper factory)] for this CUDA target."""
    def launch_wrapper(original):
        def wrapped(*a, **k):
            kernel = a[0]
            if simulator and getattr(kernel, "_device", False):
                return original(*a, **k)  # a device function called from a kernel
            timed = any(c.timing for c in _active) and not simulator
            if timed:
                from numba import cuda

                cuda.synchronize()
                start = time.perf_counter()
                result = original(*a, **k)
                cuda.synchronize()
                _record_launch(_kernel_name(kernel), time.perf_counter() - start)
                return result
            _record_launch(_kernel_name(kernel), None)
            return original(*a, **k)

        return wrapped

    def counting_wrapper(original, attr):
        def wrapped(*a, **k):
            _count(attr)
            return original(*a, **k)

        return wrapped

    if simulator:
        from numba.cuda.simulator import kernel as sim_kernel
        from numba.cuda.simulator.cudadrv import devicearray as sim_array

        return [
            (sim_kernel.FakeCUDAKernel, "__call__", launch_wrapper),
            (sim_array.FakeCUDAArray, "copy_to_host", lambda f: counting_wrapper(f, "device_to_host")),
            (sim_array.FakeCUDAArray, "copy_to_device", lambda f: counting_wrapper(f, "host_to_device")),
        ]
    from numba.cuda import dispatcher
    from numba.cuda.cudadrv import driver

    return [
        (dispatcher.CUDADispatcher, "call", launch_wrapper),
        (driver, "device_to_host", lambda f: counting_wrapper(f, "device_to_host")),
        (driver, "host_to_device", lambda f: counting_wrapper(f, "host_to_device")),
    ]


@contextlib.contextmanager
def count_cuda_calls(*, timing: bool = False):
    """Count the CUDA launches and copies made inside the block.

    Parameters
    ----------
    timing : bool
        Synchronise around every launch and add its wall time to
        :attr:`CudaCalls.seconds` (on a GPU; ignored in the simulator).

    Yields
    ------
    CudaCalls
        Filled in while the block runs.
    """
    from numba import config as numba_config

    calls = CudaCalls(timing=timing)
    with _lock:
        if _active:
            raise RuntimeError("count_cuda_calls blocks do not nest")
        installed = []
        for owner, attr, make in _hooks(bool(getattr(numba_config, "ENABLE_CUDASIM", False))):
            original = getattr(owner, attr)
            setattr(owner, attr, make(original))
            installed.append((owner, attr, original))
        _active.append(calls)
    try:
        yield calls
    finally:
        with _lock:
            _active.clear()
            for owner, attr, original in reversed(installed):
                setattr(owner, attr, original)
