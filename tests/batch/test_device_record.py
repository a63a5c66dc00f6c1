"""run.json's ``device`` record: how busy the GPU was during a batch (d3cli/batch/device.py)
and the kernel time collected from CUDA events (d3cli/kernels/cuda_calls.py).

The arithmetic is checked with events of known elapsed times; a CPU batch records null.
On a GPU (marker ``cuda``, run by ``scripts/gpu_check.sh``; skipped without one: under the
simulator a batch takes minutes) a CUDA batch records 0 < busy <= 1 and its counts."""

from __future__ import annotations

import json

import pytest

from d3cli.batch import device
from d3cli.batch.runner import run_batch
from d3cli.config import load_config
from d3cli.data.layouts import discover
from d3cli.kernels.cuda_calls import CudaCalls


class _Event:
    """A CUDA event whose elapsed time to ``end`` is known (milliseconds)."""

    def __init__(self, ms: float = 0.0):
        self.ms = ms
        self.synchronized = 0

    def elapsed_time(self, end: "_Event") -> float:
        return end.ms - self.ms

    def synchronize(self) -> None:
        self.synchronized += 1


def _pairs(*spans_ms):
    return [(_Event(a), _Event(b)) for a, b in spans_ms]


def test_kernel_seconds_are_the_sum_of_the_event_spans_and_accumulate():
    calls = CudaCalls(device_time=True)
    assert calls.kernel_seconds is None  # nothing collected yet (and never in the simulator)
    calls.events = _pairs((0.0, 1.5), (2.0, 2.25), (3.0, 7.0))
    last_end = calls.events[-1][1]
    assert calls.collect_kernel_seconds() == pytest.approx(0.00575)
    assert last_end.synchronized == 1  # waited for the last launch only
    assert calls.events == [] and calls.kernel_seconds == pytest.approx(0.00575)
    assert calls.collect_kernel_seconds() == 0.0  # nothing new: nothing waited for
    calls.events = _pairs((10.0, 12.0))
    calls.collect_kernel_seconds()
    assert calls.kernel_seconds == pytest.approx(0.00775)


def test_the_record_divides_kernel_time_by_wall_time_and_averages_per_pair(monkeypatch):
    clock = iter([100.0, 104.0])
    monkeypatch.setattr(device.time, "perf_counter", lambda: next(clock))
    calls = CudaCalls(device_time=True, launches=150, device_to_host=4, host_to_device=4,
                      device_to_host_bytes=2000, host_to_device_bytes=8192)
    activity = device.DeviceActivity(calls)  # started at 100 s
    calls.events = _pairs((0.0, 500.0))
    activity.pair_done()
    calls.events = _pairs((0.0, 250.0), (300.0, 550.0))
    activity.pair_done()
    record = activity.record()  # at 104 s
    assert record == {"kernel_s": 1.0, "wall_s": 4.0, "busy": 0.25, "pairs": 2,
                      "per_pair": {"launches": 75.0, "device_to_host": 2.0, "device_to_host_bytes": 1000,
                                   "host_to_device": 2.0, "host_to_device_bytes": 4096}}


def test_the_simulator_records_counts_and_no_time(monkeypatch):
    clock = iter([0.0, 2.0])
    monkeypatch.setattr(device.time, "perf_counter", lambda: next(clock))
    calls = CudaCalls(device_time=True, launches=76, device_to_host=3)  # no events: the simulator's
    activity = device.DeviceActivity(calls)
    activity.pair_done()
    record = activity.record()
    assert record["kernel_s"] is None and record["busy"] is None and record["wall_s"] == 2.0
    assert record["per_pair"]["launches"] == 76.0 and record["per_pair"]["device_to_host"] == 3.0


def test_only_a_cuda_batch_of_our_kernels_in_this_process_is_recorded(monkeypatch):
    cfg = load_config("default")
    serial, pipelined = {"mode": "serial", "workers": 1}, {"mode": "pipelined", "workers": 1}
    assert not device.records_device(cfg, "d3stereo", serial)  # the CPU backend here (no GPU)
    import d3cli.kernels as kernels

    monkeypatch.setattr(kernels, "chosen_backend", lambda name: "cuda")
    assert device.records_device(cfg, "d3stereo", serial) and device.records_device(cfg, "pt-sgm", pipelined)
    assert not device.records_device(cfg, "sgbm", serial)  # OpenCV's matcher: no kernels of ours
    assert not device.records_device(cfg, "d3stereo", {"mode": "local-pool", "workers": 2})  # other processes
    assert not device.records_device(cfg, "d3stereo", {"mode": "dask", "workers": 1})


def test_a_cpu_batch_records_device_null(tmp_path, make_pair_folder):
    make_pair_folder(tmp_path / "pairs", "a", shift=4)
    run_batch(discover([tmp_path / "pairs"]), tmp_path / "out", method="d3stereo",
              cfg=load_config("default", overrides=["run.backend=cpu"]), max_disparity=8, progress=False)
    run = json.loads((tmp_path / "out" / "run.json").read_text())
    assert "device" in run and run["device"] is None


@pytest.mark.cuda
def test_a_cuda_batch_on_a_gpu_records_how_busy_the_device_was(tmp_path, make_pair_folder):
    from d3cli.kernels import chosen_backend

    if chosen_backend("auto") != "cuda":  # the simulator is never chosen by auto
        pytest.skip("needs a GPU (under the simulator a batch takes minutes)")
    for name in "ab":
        make_pair_folder(tmp_path / "pairs", name, shift=4, size=(96, 160))
    for prefetch in (0, None):  # serial, then pipelined
        out = tmp_path / f"out-{prefetch}"
        run_batch(discover([tmp_path / "pairs"]), out, method="d3stereo", prefetch=prefetch,
                  cfg=load_config("default", overrides=["run.backend=cuda"]), max_disparity=16, progress=False)
        record = json.loads((out / "run.json").read_text())["device"]
        assert record["pairs"] == 2 and 0 < record["kernel_s"] <= record["wall_s"]
        assert 0 < record["busy"] <= 1
        assert record["per_pair"]["launches"] > 0 and 1 <= record["per_pair"]["device_to_host"] <= 3
        assert record["per_pair"]["host_to_device_bytes"] <= 2 * 96 * 160 + 16 * 1024
