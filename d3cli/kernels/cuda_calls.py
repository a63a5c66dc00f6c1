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
* host-to-device copies likewise (the driver's ``host_to_device`` on a GPU; in the simulator
  ``cuda.to_device``, the simulator's ``to_device`` that kernels use for host arguments, and
  ``FakeCUDAArray.copy_to_device`` from a host array);
* bytes: :attr:`CudaCalls.host_to_device_bytes` and :attr:`CudaCalls.device_to_host_bytes`
  (the driver's ``size`` on a GPU, the array's ``nbytes`` in the simulator), and per call
  site (:attr:`CudaCalls.by_site`: the first frame of the caller outside numba, this
  module and the transfer helpers of :mod:`d3cli.kernels.cuda_launch`).  A NumPy array passed straight to a kernel is one upload and one download of
  its bytes (the simulator's launch wrapper counts it so, as the driver does on a GPU);
  device-to-device copies are not counted.

:attr:`CudaCalls.spans` holds the wall-clock span of every launch and copy, so that a
step's time splits into time inside them and host time outside them
(:meth:`CudaCalls.seconds_in_calls`; ``scripts/profile_cuda.py`` prints it per step).

``timing=True`` synchronises the device around every launch and records its wall time per
kernel name (meaningful on a GPU only; it serialises the stream, so a timed run is slower
than an untimed one).  ``device_time=True`` times the kernels without stopping the host: a
pair of CUDA events is recorded on the stream around every launch, and
:meth:`CudaCalls.collect_kernel_seconds` (called where the device is idle anyway, after a
pair's download) adds their elapsed times to :attr:`CudaCalls.kernel_seconds`: the time the
device spent in kernels, which a batch divides by its wall time (run.json's ``device``).
The simulator records no time (its events are empty): ``kernel_seconds`` stays None there.
The hooks are installed on entry and removed on exit; counting blocks do not nest.
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading
import time
from collections import Counter, defaultdict
from dataclasses import dataclass, field

_lock = threading.Lock()
_active: list[CudaCalls] = []
_inside = threading.local()  # simulator: inside a launch, whose host arguments are counted once
_HERE = os.path.abspath(__file__)
#: Frames skipped to name a copy's call site: this module and the transfer helpers.
_SKIPPED = {_HERE, os.path.join(os.path.dirname(_HERE), "cuda_launch.py")}


@dataclass
class CudaCalls:
    """What happened inside one :func:`count_cuda_calls` block."""

    launches: int = 0
    device_to_host: int = 0
    host_to_device: int = 0
    #: Bytes copied from the host to the device.
    host_to_device_bytes: int = 0
    #: Bytes copied from the device to the host.
    device_to_host_bytes: int = 0
    #: ``("h2d" or "d2h", "file:line function")`` -> [copies, bytes]; the site is the first
    #: frame outside numba, this module and ``cuda_launch.py``.
    by_site: dict = field(default_factory=dict)
    #: ``(start, end)`` perf_counter seconds of every launch and copy, in order (launches
    #: and copies may overlap: a launch's own copies of host arguments on a GPU).
    spans: list = field(default_factory=list)
    #: Kernel name -> launches.
    by_kernel: Counter = field(default_factory=Counter)
    #: Kernel name -> seconds (``timing=True`` only), each launch synchronised.
    seconds: defaultdict = field(default_factory=lambda: defaultdict(float))
    timing: bool = False
    #: Record a pair of CUDA events around every launch (on a GPU; ``device_time=True``).
    device_time: bool = False
    #: Seconds the device spent in kernels, summed by :meth:`collect_kernel_seconds`; None
    #: until a GPU's events were collected (always None in the simulator).
    kernel_seconds: float | None = None
    #: The (start, end) events of the launches not collected yet.
    events: list = field(default_factory=list)

    def collect_kernel_seconds(self) -> float:
        """Add the elapsed time between each recorded pair of events to
        :attr:`kernel_seconds` and forget them; returns the seconds added.  Waits for the
        last event, so call it where the host waits for the device anyway (after a
        download).  Launches on one stream do not overlap, so the sum is the device's time
        in kernels."""
        events, self.events = self.events, []
        if not events:
            return 0.0
        events[-1][1].synchronize()
        added = sum(start.elapsed_time(end) for start, end in events) / 1000.0  # ms -> s
        self.kernel_seconds = (self.kernel_seconds or 0.0) + added
        return added

    def seconds_in_calls(self, start: float = float("-inf"), end: float = float("inf")) -> float:
        """Wall seconds spent inside launches and copies between ``start`` and ``end``
        (perf_counter times; overlapping spans counted once).  In the simulator this is
        the kernels' own run time: what is left of a step's time is the host's."""
        total, reach = 0.0, float("-inf")
        for s0, s1 in sorted(self.spans):
            s0, s1 = max(s0, start, reach), min(s1, end)
            if s1 > s0:
                total += s1 - s0
                reach = s1
        return total


def _kernel_name(kernel) -> str:
    fn = getattr(kernel, "py_func", None) or getattr(kernel, "fn", None) or kernel
    return getattr(fn, "__name__", type(kernel).__name__)


def _record_span(start: float) -> None:
    end = time.perf_counter()
    for calls in _active:
        calls.spans.append((start, end))


def _spanned(call, *a, **k):
    """``call(*a, **k)``, its wall time recorded as a span of calls (:func:`_record_span`)."""
    start = time.perf_counter()
    try:
        return call(*a, **k)
    finally:
        _record_span(start)


def _record_launch(name: str, seconds: float | None) -> None:
    for calls in _active:
        calls.launches += 1
        calls.by_kernel[name] += 1
        if seconds is not None:
            calls.seconds[name] += seconds


def _site() -> str:
    frame = sys._getframe(2)
    while frame is not None:
        name = frame.f_code.co_filename
        if os.path.abspath(name) not in _SKIPPED and f"{os.sep}numba{os.sep}" not in name:
            return f"{os.path.basename(name)}:{frame.f_lineno} {frame.f_code.co_name}"
        frame = frame.f_back
    return "?"


def _count(attr: str, nbytes: int = 0) -> None:
    direction = "h2d" if attr == "host_to_device" else "d2h"
    site = _site() if _active else "?"
    for calls in _active:
        setattr(calls, attr, getattr(calls, attr) + 1)
        setattr(calls, attr + "_bytes", getattr(calls, attr + "_bytes") + int(nbytes))
        entry = calls.by_site.setdefault((direction, site), [0, 0])
        entry[0] += 1
        entry[1] += int(nbytes)


def _host_arguments(args):
    """[(uploaded, downloaded bytes)] of the host arrays among a kernel's arguments, as
    the launch copies them (``numba.cuda.args``: a bare array is ``InOut``)."""
    import numpy as np
    from numba.cuda.args import In, InOut, Out

    copies = []
    for arg in args:
        if isinstance(arg, np.ndarray) and arg.ndim > 0:
            copies.append((arg.nbytes, arg.nbytes))
        elif isinstance(arg, (In, Out, InOut)) and isinstance(arg.value, np.ndarray):
            n = arg.value.nbytes
            copies.append((0 if isinstance(arg, Out) else n, 0 if isinstance(arg, In) else n))
    return copies


def _nbytes(array) -> int:
    return int(getattr(array, "nbytes", 0) or 0)


def _hooks(simulator: bool):
    """[(owner, attribute, wrapper factory)] for this CUDA target."""
    def launch_wrapper(original):
        def wrapped(*a, **k):
            kernel = a[0]
            if simulator and getattr(kernel, "_device", False):
                return original(*a, **k)  # a device function called from a kernel
            if simulator:
                copies = _host_arguments(a[1:])
                for up, _ in copies:
                    if up:
                        _count("host_to_device", up)
                _record_launch(_kernel_name(kernel), None)
                _inside.depth = getattr(_inside, "depth", 0) + 1
                start = time.perf_counter()
                try:
                    return original(*a, **k)
                finally:
                    _record_span(start)
                    _inside.depth -= 1
                    for _, down in copies:
                        if down:
                            _count("device_to_host", down)
            timed = any(c.timing for c in _active) and not simulator
            if timed:
                from numba import cuda

                cuda.synchronize()
                start = time.perf_counter()
                result = original(*a, **k)
                cuda.synchronize()
                _record_launch(_kernel_name(kernel), time.perf_counter() - start)
                _record_span(start)
                return result
            _record_launch(_kernel_name(kernel), None)
            timers = [c for c in _active if c.device_time]
            if timers:
                from numba import cuda

                start, end = cuda.event(), cuda.event()
                start.record()
                result = _spanned(original, *a, **k)
                end.record()
                for calls in timers:
                    calls.events.append((start, end))
                return result
            return _spanned(original, *a, **k)

        return wrapped

    def driver_wrapper(original, attr):
        # driver.host_to_device(dst, src, size, stream=0) / device_to_host(dst, src, size, ...)
        def wrapped(*a, **k):
            _count(attr, k.get("size", a[2] if len(a) > 2 else 0))
            return _spanned(original, *a, **k)

        return wrapped

    def quiet():
        return getattr(_inside, "depth", 0) > 0  # a launch's own copies: counted by the launch

    def sim_to_host(original):
        def wrapped(self, *a, **k):
            if quiet():
                return original(self, *a, **k)
            _count("device_to_host", _nbytes(self))
            start = time.perf_counter()
            try:
                return original(self, *a, **k)
            finally:
                _record_span(start)

        return wrapped

    def sim_copy_to_device(original):
        def wrapped(self, ary, *a, **k):
            import numpy as np

            if quiet() or hasattr(ary, "copy_to_host"):  # device to device: no copy to count
                return original(self, ary, *a, **k)
            _count("host_to_device", np.asarray(ary).nbytes)
            start = time.perf_counter()
            try:
                return original(self, ary, *a, **k)
            finally:
                _record_span(start)

        return wrapped

    def sim_to_device(original):
        def wrapped(ary, *a, **k):
            import numpy as np

            start = time.perf_counter()
            result = original(ary, *a, **k)
            to = k.get("to", a[2] if len(a) > 2 else None)
            if not quiet() and to is None:  # with ``to``: copy_to_device counts it
                _count("host_to_device", np.asarray(ary).nbytes)
                _record_span(start)
            return result

        return wrapped

    if simulator:
        from numba.cuda.simulator import kernel as sim_kernel
        from numba.cuda.simulator.cudadrv import devicearray as sim_array

        import numba.cuda as numba_cuda

        return [
            (sim_kernel.FakeCUDAKernel, "__call__", launch_wrapper),
            (sim_array.FakeCUDAArray, "copy_to_host", sim_to_host),
            (sim_array.FakeCUDAArray, "copy_to_device", sim_copy_to_device),
            (sim_array, "to_device", sim_to_device),  # auto_device: host arrays given to kernels
            (numba_cuda, "to_device", sim_to_device),  # cuda.to_device
        ]
    from numba.cuda import dispatcher
    from numba.cuda.cudadrv import driver

    return [
        (dispatcher.CUDADispatcher, "call", launch_wrapper),
        (driver, "device_to_host", lambda f: driver_wrapper(f, "device_to_host")),
        (driver, "host_to_device", lambda f: driver_wrapper(f, "host_to_device")),
    ]


@contextlib.contextmanager
def count_cuda_calls(*, timing: bool = False, device_time: bool = False):
    """Count the CUDA launches and copies made inside the block.

    Parameters
    ----------
    timing : bool
        Synchronise around every launch and add its wall time to
        :attr:`CudaCalls.seconds` (on a GPU; ignored in the simulator).
    device_time : bool
        Record CUDA events around every launch, without synchronising, for
        :meth:`CudaCalls.collect_kernel_seconds` (on a GPU; ignored in the simulator).

    Yields
    ------
    CudaCalls
        Filled in while the block runs.
    """
    from numba import config as numba_config

    calls = CudaCalls(timing=timing, device_time=device_time)
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
