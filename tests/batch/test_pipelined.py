"""--prefetch: a batch whose reading and writing overlap the computing.

The pipelined executor must give the serial executor's per-pair files and failure rules;
its overlap and its bounds are shown with events and counters, never with timings.
CLI runs use tiny pairs (``--method sgbm`` where the method does not matter).
"""

from __future__ import annotations

import errno
import json
import os
import shutil
import threading
import time
from pathlib import Path
from types import SimpleNamespace

import pytest
from click.testing import CliRunner

import d3cli.batch.executors.pipelined
import d3cli.batch.runner
import d3cli.data.formats.images
import d3cli.data.layouts
import d3cli.kernels
from d3cli.batch import LOCK_FILE, parse_prefetch
from d3cli.batch.executors import PipelinedExecutor, SerialExecutor, make_executor
from d3cli.cli import main
from d3cli.config import load_config
from d3cli.errors import ConfigError

PAIRS = "abcde"
WAIT_S = 30  # generous: a wait that times out fails the test, it never measures anything


def invoke(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def run_json(out):
    return json.loads((out / "run.json").read_text())


def without_timings(value):
    """``value`` (parsed result.json) without the keys that hold seconds."""
    if isinstance(value, dict):
        return {k: without_timings(v) for k, v in value.items()
                if k not in ("timings", "wall") and not k.startswith("time_")}
    if isinstance(value, list):
        return [without_timings(v) for v in value]
    return value


def pair_files(out, names=PAIRS):
    """{relative path: bytes, or result.json without its timings} of every pair's files."""
    files = {}
    for name in names:
        for path in sorted((out / name).rglob("*")):
            rel = str(path.relative_to(out))
            files[rel] = (without_timings(json.loads(path.read_text())) if path.name == "result.json"
                          else path.read_bytes())
    return files


@pytest.fixture
def five_pairs(tmp_path, make_pair_set):
    return make_pair_set(tmp_path / "pairs", PAIRS)


# ----------------------------------------------------------------------------- same files
@pytest.mark.parametrize("method, writers", [("sgbm", 1), ("sgbm", 3), ("d3stereo", 2)])
def test_pipelined_files_are_the_serial_files(tmp_path, five_pairs, monkeypatch, method, writers):
    monkeypatch.setattr(d3cli.batch.executors.pipelined, "default_writers", lambda: writers)
    names = PAIRS if method == "sgbm" else PAIRS[:3]  # d3stereo: 3 pairs keep the test under 5 s
    for name in set(PAIRS) - set(names):
        shutil.rmtree(five_pairs / name)
    args = ["--method", method, "-q", "--eval", "--max-disparity", "16"]
    serial, piped = tmp_path / "serial", tmp_path / "piped"
    assert invoke("run", five_pairs, "-o", serial, *args).exit_code == 0
    assert invoke("run", five_pairs, "-o", piped, *args, "--prefetch", "2").exit_code == 0
    assert run_json(serial)["execution"]["mode"] == "serial"  # auto on the CPU backend
    files = pair_files(piped, names)
    assert len(files) == len(pair_files(serial, names)) >= len(names) * 6
    assert files == pair_files(serial, names)
    run = run_json(piped)
    assert run["execution"] == {"mode": "pipelined", "workers": 1, "prefetch": 2, "writers": writers,
                                "write_behind": max(2, writers)}
    assert [(p["pair"], p["status"]) for p in run["pairs"]] == [(n, "ok") for n in names]


def test_a_rerun_skips_the_pairs_of_a_pipelined_run(tmp_path, five_pairs):
    out = tmp_path / "out"
    assert invoke("run", five_pairs, "-o", out, "--method", "sgbm", "-q", "--prefetch", "1").exit_code == 0
    first = pair_files(out)
    assert invoke("run", five_pairs, "-o", out, "--method", "sgbm", "-q", "--prefetch", "3").exit_code == 0
    assert [p["status"] for p in run_json(out)["pairs"]] == ["skipped"] * 5
    assert pair_files(out) == first


# ----------------------------------------------------------------------------- failures
def test_a_corrupt_image_fails_only_its_pair(tmp_path, five_pairs):
    left = five_pairs / "c" / "left.png"
    left.write_bytes(left.read_bytes()[:100])
    out = tmp_path / "out"
    result = invoke("run", five_pairs, "-o", out, "--method", "sgbm", "-q", "--prefetch", "2")
    assert result.exit_code == 1  # the batch completes and says that a pair failed
    assert result.output.strip().splitlines()[-1] == f"Error: 1 of 5 pairs failed (see {out / 'run.json'})"
    pairs = run_json(out)["pairs"]
    assert [p["status"] for p in pairs] == ["ok", "ok", "failed", "ok", "ok"]
    assert pairs[2]["error"] == (f"{left}: cannot read image (corrupt or not an image); give an 8/16-bit PNG, "
                                 "JPEG, PPM/PGM or TIFF file")
    assert not (out / "c").exists()


def test_a_failing_writer_fails_only_its_pair(tmp_path, five_pairs, monkeypatch):
    real = d3cli.batch.runner.write_panel

    def panel(folder, name, *args, **kwargs):
        if name == "c":
            raise RuntimeError("panel broke")
        return real(folder, name, *args, **kwargs)

    monkeypatch.setattr(d3cli.batch.runner, "write_panel", panel)
    out = tmp_path / "out"
    assert invoke("run", five_pairs, "-o", out, "--method", "sgbm", "-q", "--prefetch", "2").exit_code == 1
    pairs = run_json(out)["pairs"]
    assert [p["status"] for p in pairs] == ["ok", "ok", "failed", "ok", "ok"]
    assert pairs[2]["error"] == "c: internal error in the panel (RuntimeError: panel broke); please report it"
    assert sorted(p.name for p in out.iterdir()) == ["a", "b", "d", "e", "report.html", "run.json"]


def test_a_full_disk_in_the_writer_ends_the_batch_at_that_pair(tmp_path, five_pairs, monkeypatch):
    monkeypatch.setattr(d3cli.batch.executors.pipelined, "default_writers", lambda: 1)  # with more, c may be written beside b
    real = d3cli.data.formats.images.write_encoded

    def full_disk_on_b(path, image):
        if Path(path).parent.name.startswith(".b.partial-"):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(path, image)

    monkeypatch.setattr(d3cli.data.formats.images, "write_encoded", full_disk_on_b)
    out = tmp_path / "out"
    result = invoke("run", five_pairs, "-o", out, "--method", "sgbm", "--prefetch", "2")
    assert result.exit_code == 1
    assert [line for line in result.output.splitlines() if line.startswith("Error:")] == [
        f"Error: {out / 'b' / 'disp.png'}: cannot write ({os.strerror(errno.ENOSPC)}); free disk space, "
        "then rerun the same command (finished pairs are kept and skipped)"]
    info = run_json(out)
    assert info["interrupted"] is True and info["stopped_at"] == "b"
    assert [p["status"] for p in info["pairs"]] == ["ok", "failed"]
    # Pairs after b were read and maybe computed, never written.
    assert sorted(p.name for p in out.iterdir()) == ["a", "run.json"]


# ----------------------------------------------------------------------------- Ctrl-C
def test_ctrl_c_while_computing_writes_the_pairs_computed_before_and_drops_the_rest(tmp_path, five_pairs,
                                                                                    monkeypatch):
    real = d3cli.batch.runner.compute_pair
    out = tmp_path / "out"

    def interrupted_on_c(method, cfg, left, right, **kwargs):
        if Path(kwargs["pair_dir"]).name == "c":
            try:  # what numba raises when SIGINT arrives inside a compiled function
                raise KeyboardInterrupt
            except KeyboardInterrupt:
                raise SystemError("<numba function> returned a result with an exception set")
        return real(method, cfg, left, right, **kwargs)

    monkeypatch.setattr(d3cli.batch.runner, "compute_pair", interrupted_on_c)
    result = invoke("run", five_pairs, "-o", out, "--method", "sgbm", "--prefetch", "2")
    assert result.exit_code == 130, result.output
    assert "Interrupted: 2 of 5 pairs done" in result.output
    run = run_json(out)
    assert run["interrupted"] is True and run["stopped_at"] == "c" and run["n_failed"] == 0
    assert [p["status"] for p in run["pairs"]] == ["ok", "ok"]
    assert sorted(p.name for p in out.iterdir()) == ["a", "b", "run.json"]  # no staging folder, no lock

    monkeypatch.setattr(d3cli.batch.runner, "compute_pair", real)
    assert invoke("run", five_pairs, "-o", out, "--method", "sgbm", "-q", "--prefetch", "2").exit_code == 0
    assert [p["status"] for p in run_json(out)["pairs"]] == ["skipped", "skipped", "ok", "ok", "ok"]
    serial = tmp_path / "serial"
    assert invoke("run", five_pairs, "-o", serial, "--method", "sgbm", "-q").exit_code == 0
    assert pair_files(out) == pair_files(serial)


def test_ctrl_c_in_the_writer_leaves_no_half_pair(tmp_path, five_pairs, monkeypatch):
    def interrupted(folder, stored):
        raise KeyboardInterrupt

    monkeypatch.setattr(d3cli.batch.runner, "write_result", interrupted)
    out = tmp_path / "out"
    result = invoke("run", five_pairs, "-o", out, "--method", "sgbm", "--prefetch", "2")
    assert result.exit_code == 130, result.output
    run = run_json(out)
    assert run["interrupted"] is True and run["pairs"] == [] and run["stopped_at"] == "a"
    assert sorted(p.name for p in out.iterdir()) == ["run.json"]
    assert not (out / LOCK_FILE).exists()


# ----------------------------------------------------------------------------- overlap
def test_the_next_pair_is_read_while_one_computes_and_written_behind(tmp_path, five_pairs, monkeypatch):
    """Compute of a waits for the read of b to start, the write of a for the compute of b
    to start: a serial batch would wait out WAIT_S and fail."""
    events = []
    started = {(stage, name): threading.Event() for stage in ("read", "compute") for name in PAIRS}
    waited = {}
    real_load, real_compute, real_panel = (d3cli.data.layouts.load_pair_images, d3cli.batch.runner.compute_pair,
                                           d3cli.batch.runner.write_panel)

    def load(pair):
        events.append(("read", pair.name))
        started["read", pair.name].set()
        return real_load(pair)

    def compute(method, cfg, left, right, **kwargs):
        name = Path(kwargs["pair_dir"]).name
        events.append(("compute", name))
        started["compute", name].set()
        if name == "a":
            waited["read b"] = started["read", "b"].wait(WAIT_S)
        return real_compute(method, cfg, left, right, **kwargs)

    def panel(folder, name, *args, **kwargs):
        if name == "a":
            waited["compute b"] = started["compute", "b"].wait(WAIT_S)
        events.append(("write", name))
        return real_panel(folder, name, *args, **kwargs)

    monkeypatch.setattr(d3cli.data.layouts, "load_pair_images", load)
    monkeypatch.setattr(d3cli.batch.runner, "compute_pair", compute)
    monkeypatch.setattr(d3cli.batch.runner, "write_panel", panel)
    monkeypatch.setattr(d3cli.batch.executors.pipelined, "default_writers", lambda: 1)  # writes in input order
    out = tmp_path / "out"
    assert invoke("run", five_pairs, "-o", out, "--method", "sgbm", "-q", "--prefetch", "1").exit_code == 0
    assert waited == {"read b": True, "compute b": True}
    assert events.index(("compute", "b")) < events.index(("write", "a"))
    for stage in ("read", "compute", "write"):  # each stage takes the pairs in input order
        assert [name for s, name in events if s == stage] == list(PAIRS)


@pytest.mark.parametrize("prefetch", [1, 3])
def test_never_more_than_prefetch_pairs_read_ahead(tmp_path, make_pair_folder, monkeypatch, prefetch):
    """A counter of pairs read and not yet computed: the one computing plus at most
    ``prefetch``; the first compute waits until the reader has filled its read-ahead."""
    root = tmp_path / "pairs"
    for i in range(8):
        make_pair_folder(root, f"p{i}", shift=3, size=(32, 64), seed=i)
    lock = threading.Lock()
    count = {"now": 0, "max": 0}
    full = threading.Event()
    real_load, real_compute = d3cli.data.layouts.load_pair_images, d3cli.batch.runner.compute_pair

    def load(pair):
        images = real_load(pair)
        with lock:
            count["now"] += 1
            count["max"] = max(count["max"], count["now"])
            if count["now"] == prefetch + 1:
                full.set()
        return images

    def compute(*args, **kwargs):
        if not full.is_set():
            assert full.wait(WAIT_S)
            time.sleep(0.1)  # room for a reader that would overrun its bound to do so
        result = real_compute(*args, **kwargs)
        with lock:
            count["now"] -= 1
        return result

    monkeypatch.setattr(d3cli.data.layouts, "load_pair_images", load)
    monkeypatch.setattr(d3cli.batch.runner, "compute_pair", compute)
    out = tmp_path / "out"
    result = invoke("run", root, "-o", out, "--method", "sgbm", "-q", "--prefetch", prefetch)
    assert result.exit_code == 0, result.output
    assert count == {"now": 0, "max": prefetch + 1}


def test_the_write_queue_is_bounded_and_results_come_in_input_order():
    """The executor alone, with a fake pair task: while the writer is held on p0, p1 and
    p2 queue up (write_behind 2), p3 is computed and waits to be queued, p4 is read (prefetch
    1) and not computed: prefetch + write_behind + 2 = 5 pairs in memory, never more."""
    names = [f"p{i}" for i in range(7)]
    third_computed, gate = threading.Event(), threading.Event()
    log = []
    lock = threading.Lock()
    in_memory = {"now": 0, "max": 0}

    def task(pair, staged=False):
        assert staged

        def stages():
            log.append(("read", pair.name))
            with lock:
                in_memory["now"] += 1
                in_memory["max"] = max(in_memory["max"], in_memory["now"])
            yield "read"
            log.append(("compute", pair.name))
            if pair.name == "p3":
                third_computed.set()
            yield "computed"
            gate.wait(WAIT_S)
            log.append(("write", pair.name))
            with lock:
                in_memory["now"] -= 1
            return pair.name.upper()

        return stages()

    def open_gate():
        third_computed.wait(WAIT_S)
        time.sleep(0.1)  # room for a compute thread that would overrun the bound to do so
        gate.set()

    opener = threading.Thread(target=open_gate)
    opener.start()
    with PipelinedExecutor(1, writers=1, write_behind=2) as executor:
        results = [(pair.name, result) for pair, result in executor.imap(task, [SimpleNamespace(name=n)
                                                                                for n in names])]
    opener.join()
    assert results == [(n, n.upper()) for n in names]
    first_write = log.index(("write", "p0"))
    assert [n for s, n in log[:first_write] if s == "compute"] == ["p0", "p1", "p2", "p3"]
    assert [n for s, n in log[:first_write] if s == "read"] == ["p0", "p1", "p2", "p3", "p4"]
    assert [n for s, n in log if s == "write"] == names
    assert in_memory == {"now": 0, "max": 5}


def test_writers_write_at_once_and_results_still_come_in_input_order():
    """Three writers: the three writes meet at a barrier (so they run at the same time) and
    finish in reverse order; the pairs are yielded in input order all the same."""
    names = ["p0", "p1", "p2", "p3"]
    barrier = threading.Barrier(3, timeout=WAIT_S)
    written = {name: threading.Event() for name in names}
    finished = []

    def task(pair, staged=False):
        def stages():
            yield "read"
            yield "computed"
            if pair.name != "p3":
                barrier.wait()  # BrokenBarrierError after WAIT_S if the writes were one at a time
                later = {"p0": "p1", "p1": "p2"}.get(pair.name)
                if later is not None:
                    assert written[later].wait(WAIT_S)
            finished.append(pair.name)
            written[pair.name].set()
            return pair.name.upper()

        return stages()

    executor = PipelinedExecutor(3, writers=3)
    assert executor.write_behind == 3
    with executor:
        results = [(pair.name, result) for pair, result in executor.imap(task, [SimpleNamespace(name=n)
                                                                                for n in names])]
    assert [n for n in finished if n != "p3"] == ["p2", "p1", "p0"]  # p3 is written once a writer is free
    assert results == [(n, n.upper()) for n in names]


# ----------------------------------------------------------------------------- choice
def test_prefetch_auto_pipelines_on_cuda_only(monkeypatch):
    cfg_cpu = load_config(overrides=["run.backend=cpu"])
    cfg_cuda = load_config(overrides=["run.backend=cuda"])
    assert isinstance(make_executor(1, prefetch=None, cfg=cfg_cpu, method="d3stereo"), SerialExecutor)
    monkeypatch.setattr(d3cli.kernels, "cuda_status", lambda: (True, "CUDA device available (a test kernel ran)"))
    executor = make_executor(1, prefetch=None, cfg=cfg_cuda, method="d3stereo")
    assert isinstance(executor, PipelinedExecutor) and executor.prefetch == 2
    assert isinstance(make_executor(1, prefetch=0, cfg=cfg_cuda, method="d3stereo"), SerialExecutor)
    assert isinstance(make_executor(1, prefetch=None, cfg=cfg_cuda, method="sgbm"), SerialExecutor)
    assert make_executor(3, n_pairs=5, prefetch=2).mode == "local-pool"  # workers take whole pairs


def test_parse_prefetch_and_its_error_line(tmp_path, five_pairs):
    assert parse_prefetch("auto") is None and parse_prefetch("0") == 0 and parse_prefetch(4) == 4
    for bad in ("-1", "65", "two"):
        with pytest.raises(ConfigError, match="--prefetch"):
            parse_prefetch(bad)
    result = invoke("run", five_pairs, "-o", tmp_path / "o", "--prefetch", "-1")
    assert result.exit_code == 1
    assert result.output.strip().splitlines()[-1] == (
        "Error: --prefetch -1: use a number of pairs from 0 (none) to 64, or 'auto' (2 on a GPU, none on the CPU)")


# ----------------------------------------------------------------------------- threads and stderr
def test_two_threads_decoding_at_once_leave_stderr_where_it_was(tmp_path, monkeypatch):
    """The reader and a writer decode images at the same moment (the inputs, the panel's
    tiles).  A decode sends file descriptor 2 to a temporary file for its duration; two
    overlapping decodes restored it crosswise and left the process's stderr in a deleted
    file: the batch's last line ("Interrupted: ...") was lost."""
    import cv2

    from tests.helpers import textured_pair, write_png

    write_png(tmp_path / "img.png", textured_pair(3, (16, 24))[0])
    real = cv2.imdecode
    first_inside, second_inside, first_done = threading.Event(), threading.Event(), threading.Event()

    def decode(data, flags):
        if threading.current_thread().name == "first":
            first_inside.set()
            second_inside.wait(0.5)  # the second decode starts meanwhile, unless decodes take turns
        else:
            second_inside.set()
            first_done.wait(WAIT_S)  # and ends after the first
        return real(data, flags)

    def read(name):
        if name == "second":
            assert first_inside.wait(WAIT_S)
        d3cli.data.formats.images.read_image(tmp_path / "img.png")
        if name == "first":
            first_done.set()

    monkeypatch.setattr(cv2, "imdecode", decode)
    before, saved = os.fstat(2), os.dup(2)
    try:
        threads = [threading.Thread(target=read, args=(name,), name=name) for name in ("first", "second")]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join(WAIT_S)
        after = os.fstat(2)
    finally:
        os.dup2(saved, 2)  # this process's stderr back, whatever the decodes did to it
        os.close(saved)
    assert (after.st_dev, after.st_ino) == (before.st_dev, before.st_ino)


@pytest.mark.parametrize("method, mode", [("d3stereo", "pipelined"), ("pt-sgm", "pipelined"), ("sgbm", "serial"),
                                          ("elas", "serial"), ("pandora-sgm", "serial")])
def test_prefetch_auto_pipelines_only_the_methods_that_compute_on_the_device(monkeypatch, method, mode):
    """``--prefetch auto`` with CUDA chosen: the methods that run our kernels are pipelined;
    sgbm, elas and pandora-sgm compute on the CPU and stay serial (elas and pandora were
    pipelined, their reading threads taking cores from the CPU method)."""
    from d3cli.config import Config

    monkeypatch.setattr(d3cli.kernels, "chosen_backend", lambda name="auto": "cuda")
    executor = make_executor(1, prefetch=None, cfg=Config(), method=method)
    assert executor.describe()["mode"] == mode
