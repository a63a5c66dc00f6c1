"""How busy the GPU was during a batch: run.json's ``device`` record.

A GPU pair is fast when the device never waits for the host; in a batch the reading,
decoding and writing of the pairs around the one computing should hide behind its kernels
(:mod:`d3cli.batch.executors.pipelined`).  Whether they do is one number: the time the
device spent in kernels over the batch's wall time.  On a CUDA batch run in this process
(serial or pipelined), every launch is bracketed by two CUDA events on the stream, which
costs the host a few microseconds a launch and never stops the device
(:func:`d3cli.kernels.cuda_calls.count_cuda_calls` with ``device_time``); their times are
collected after each pair, when the device is idle anyway.  Launches and copies (with
their bytes) are counted too, so run.json says what a pair cost the bus.

Under the CUDA simulator the counts are recorded and the times are not (``kernel_s`` and
``busy`` are null).  CPU batches, and CUDA batches run by worker processes (each with its
own device context), record ``device: null``.
"""

from __future__ import annotations

import contextlib
import time
from typing import Iterator

from ..config import method_spec


class DeviceActivity:
    """The launches, copies and kernel time of the pairs computed so far."""

    def __init__(self, calls) -> None:
        self._calls = calls
        self._started = time.perf_counter()
        self._pairs = 0

    def pair_done(self) -> None:
        """Collect the kernel time of the pair just computed (its download waited for it)."""
        self._pairs += 1
        self._calls.collect_kernel_seconds()

    def record(self) -> dict:
        """run.json's ``device``: ``kernel_s``, ``wall_s`` (since the first pair began),
        ``busy`` (``kernel_s / wall_s``), and per pair the launches, the copies each way and
        their bytes (means over the pairs done)."""
        calls = self._calls
        calls.collect_kernel_seconds()
        wall = time.perf_counter() - self._started
        kernel = calls.kernel_seconds
        n = max(self._pairs, 1)
        return {
            "kernel_s": None if kernel is None else round(kernel, 4),
            "wall_s": round(wall, 4),
            "busy": None if kernel is None or wall <= 0 else round(min(kernel / wall, 1.0), 4),
            "pairs": self._pairs,
            "per_pair": {"launches": round(calls.launches / n, 1),
                         "device_to_host": round(calls.device_to_host / n, 1),
                         "device_to_host_bytes": round(calls.device_to_host_bytes / n),
                         "host_to_device": round(calls.host_to_device / n, 1),
                         "host_to_device_bytes": round(calls.host_to_device_bytes / n)},
        }


def records_device(cfg, method: str, execution: dict) -> bool:
    """Whether this batch's device activity can be recorded here: ``method`` runs
    d3stereo's kernels, the backend is CUDA, and the pairs compute in this process."""
    from ..kernels import chosen_backend

    spec = method_spec(method)
    if spec is None or not spec.kernels or execution.get("workers", 1) != 1:
        return False
    if execution.get("mode") not in ("serial", "pipelined"):
        return False
    return chosen_backend(cfg.run.backend) == "cuda"


@contextlib.contextmanager
def device_activity(cfg, method: str, execution: dict) -> Iterator[DeviceActivity | None]:
    """A :class:`DeviceActivity` for the pairs computed inside the block, or None where
    :func:`records_device` says no."""
    if not records_device(cfg, method, execution):
        yield None
        return
    from ..kernels.cuda_calls import count_cuda_calls

    with count_cuda_calls(device_time=True) as calls:
        yield DeviceActivity(calls)
