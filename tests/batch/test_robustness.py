"""A batch under faults: Ctrl-C, a full disk, two runs at once, corrupt inputs,
memory limits, and pairs that are not rectified or swapped.

CLI runs use ``--method sgbm`` on tiny pairs so that they test the batch, not the pipeline;
the diagnostics tests run d3stereo on textured synthetic pairs.
"""

from __future__ import annotations

import errno
import json
import os
import signal
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from tests.helpers import textured_pair, write_png

import d3cli.batch.outputs
import d3cli.batch.runner
import d3cli.data.formats.images
from d3cli.batch import LOCK_FILE, OUTPUT_FILES, RESULT_FILE, acquire_lock, release_lock
from d3cli.cli import main
from d3cli.config import Config, load_config
from d3cli.evaluation.diagnostics import suspicious_result
from d3cli.errors import InputError, OutputError
from d3cli.method.pipeline import D3Stereo
from d3cli.batch.resources import check_memory, estimate_peak_bytes
from d3cli.method.memory import D3_BYTES_PER_PIXEL

PER_PAIR = (*OUTPUT_FILES, RESULT_FILE)


def invoke(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def error_lines(output):
    return [line for line in output.splitlines() if line.startswith("Error:")]


def run_json(out):
    return json.loads((out / "run.json").read_text())


def temp_files(folder):
    return [p.name for p in Path(folder).rglob("*") if ".tmp-" in p.name]


def assert_complete(pair_dir):
    """Every output exists and is readable, and result.json parses."""
    for name in OUTPUT_FILES:
        path = pair_dir / name
        assert path.is_file(), path
        if name.endswith(".pfm"):
            d3cli.data.formats.read_pfm(path)
        else:
            d3cli.data.formats.read_image(path)
    json.loads((pair_dir / RESULT_FILE).read_text())


def assert_same_outputs(first, second, names):
    """Byte-identical per-pair files; result.json equal but for the timings."""
    for name in names:
        for f in OUTPUT_FILES:
            assert (first / name / f).read_bytes() == (second / name / f).read_bytes(), (name, f)
        a, b = (json.loads((d / name / RESULT_FILE).read_text()) for d in (first, second))
        a.pop("timings"), b.pop("timings")
        assert a == b, name


@pytest.fixture
def four_pairs(tmp_path, make_pair_folder):
    root = tmp_path / "pairs"
    for i, name in enumerate("abcd"):
        make_pair_folder(root, name, shift=4 + i, seed=i)
    return root


# ----------------------------------------------------------------------------- Ctrl-C
SLOW_RUN = textwrap.dedent("""
    import sys, time
    import d3cli.batch.outputs, d3cli.batch.runner
    real_compute, real_kitti = d3cli.batch.runner.compute_pair, d3cli.batch.outputs.write_kitti_png

    def slow_compute(*args, **kwargs):
        time.sleep(0.2)
        return real_compute(*args, **kwargs)

    def slow_kitti(path, disp):  # disp.pfm of the pair is written; the rest is not
        time.sleep(1.5)
        return real_kitti(path, disp)

    d3cli.batch.runner.compute_pair, d3cli.batch.outputs.write_kitti_png = slow_compute, slow_kitti
    from d3cli.cli import main
    main(sys.argv[1:], prog_name="d3stereo")
""")


def _wait_for(path, proc, timeout=60.0):
    """Wait until ``path`` exists (``path`` may be a glob pattern)."""
    deadline = time.monotonic() + timeout
    while not list(Path(path.anchor).glob(str(path.relative_to(path.anchor)))):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, f"{path} did not appear"
        time.sleep(0.02)


def pair_of(path) -> str:
    """The pair a file being written belongs to: ``OUT/b/x`` or the staging folder's
    ``OUT/.b.partial-XXXX/x`` -> ``b``."""
    folder = Path(path).parent.name
    return folder[1:folder.index(".partial-")] if ".partial-" in folder else folder


def test_sigint_keeps_finished_pairs_and_rerun_is_byte_identical(tmp_path, four_pairs):
    out = tmp_path / "out"
    script = tmp_path / "slow_run.py"
    script.write_text(SLOW_RUN)
    proc = subprocess.Popen([sys.executable, str(script), "run", str(four_pairs), "-o", str(out),
                             "--method", "sgbm", "-q"], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            # SIGINT back to default: background shells start jobs with it ignored
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        _wait_for(out / "a" / RESULT_FILE, proc)
        # A second run into the same folder, while the first one writes: refused.
        second = invoke("run", four_pairs, "-o", out, "--method", "sgbm")
        assert second.exit_code == 1
        assert error_lines(second.output) == [
            f"Error: {out}: another d3stereo run (pid {proc.pid}) is writing here; "
            "wait for it or use another -o folder"]
        _wait_for(out / ".b.partial-*" / "disp.pfm", proc)  # b is half written: Ctrl-C now
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, stderr
    assert stderr.strip().splitlines()[-1] == "Interrupted: 1 of 4 pairs done; rerun the same command to resume"
    assert "Traceback" not in stderr
    assert_complete(out / "a")
    assert not (out / "b").exists(), list((out / "b").iterdir())  # the partial pair left nothing
    assert not (out / "c").exists() and not (out / "d").exists()
    assert temp_files(out) == [] and not (out / LOCK_FILE).exists()
    assert [p.name for p in out.iterdir() if ".partial-" in p.name] == []
    info = run_json(out)
    assert info["interrupted"] is True and info["stopped_at"] == "b"
    assert [p["pair"] for p in info["pairs"]] == ["a"] and info["n_total"] == 4

    resumed = invoke("run", four_pairs, "-o", out, "--method", "sgbm")
    assert resumed.exit_code == 0, resumed.output
    assert [p["status"] for p in run_json(out)["pairs"]] == ["skipped", "ok", "ok", "ok"]
    clean = tmp_path / "clean"
    assert invoke("run", four_pairs, "-o", clean, "--method", "sgbm").exit_code == 0
    assert_same_outputs(out, clean, "abcd")


def test_keyboard_interrupt_in_process_exit_130_and_message(tmp_path, four_pairs, monkeypatch):
    real = d3cli.batch.runner.compute_pair
    calls = []

    def interrupt_third(*args, **kwargs):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(d3cli.batch.runner, "compute_pair", interrupt_third)
    out = tmp_path / "out"
    result = invoke("run", four_pairs, "-o", out, "--method", "sgbm")
    assert result.exit_code == 130
    assert result.output.strip().splitlines()[-1] == (
        "Interrupted: 2 of 4 pairs done; rerun the same command to resume")
    assert not (out / "c").exists() and not (out / LOCK_FILE).exists()
    assert run_json(out)["stop_reason"].startswith("interrupted")


def test_interrupt_while_writing_result_json_leaves_no_half_pair(tmp_path, four_pairs, monkeypatch):
    import d3cli.batch

    real = d3cli.batch.outputs.write_json

    def interrupt_on_b(path, data):
        if pair_of(path) == "b" and Path(path).name == RESULT_FILE:
            def partial(tmp):
                Path(tmp).write_text('{"pair": "b", "half')
                raise KeyboardInterrupt

            return d3cli.data.formats.atomic_write(path, partial)
        return real(path, data)

    monkeypatch.setattr(d3cli.batch.outputs, "write_json", interrupt_on_b)
    out = tmp_path / "out"
    assert invoke("run", four_pairs, "-o", out, "--method", "sgbm").exit_code == 130
    assert_complete(out / "a")
    assert not (out / "b").exists()
    assert temp_files(out) == []


# ----------------------------------------------------------------------------- disk full
def test_disk_full_stops_the_batch_with_one_error_and_keeps_finished_pairs(tmp_path, four_pairs, monkeypatch):
    real = d3cli.data.formats.images.write_encoded

    def full_disk_on_b(path, image):
        if pair_of(path) == "b":
            Path(path).write_bytes(b"\x89PNG\r\n\x1a\n-half")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(path, image)

    monkeypatch.setattr(d3cli.data.formats.images, "write_encoded", full_disk_on_b)
    out = tmp_path / "out"
    result = invoke("run", four_pairs, "-o", out, "--method", "sgbm")
    assert result.exit_code == 1
    assert "Traceback" not in result.output
    assert error_lines(result.output) == [
        f"Error: {out / 'b' / 'disp.png'}: cannot write ({os.strerror(errno.ENOSPC)}); free disk space, "
        "then rerun the same command (finished pairs are kept and skipped)"]
    assert_complete(out / "a")
    assert not (out / "b").exists()  # neither the half PNG nor the disp.pfm written before it
    assert not (out / "c").exists()  # every later pair would fail the same way
    assert temp_files(out) == [] and not (out / LOCK_FILE).exists()
    info = run_json(out)
    assert info["interrupted"] is True and info["stopped_at"] == "b"
    assert [p["status"] for p in info["pairs"]] == ["ok", "failed"]

    monkeypatch.setattr(d3cli.data.formats.images, "write_encoded", real)
    assert invoke("run", four_pairs, "-o", out, "--method", "sgbm").exit_code == 0
    assert [p["status"] for p in run_json(out)["pairs"]] == ["skipped", "ok", "ok", "ok"]


def test_other_write_errors_fail_only_that_pair(tmp_path, four_pairs, monkeypatch):
    real = d3cli.data.formats.images.write_encoded

    def eio_on_c(path, image):
        if pair_of(path) == "c":
            raise OSError(errno.EIO, os.strerror(errno.EIO))
        return real(path, image)

    monkeypatch.setattr(d3cli.data.formats.images, "write_encoded", eio_on_c)
    out = tmp_path / "out"
    result = invoke("run", four_pairs, "-o", out, "--method", "sgbm")
    assert error_lines(result.output) == [f"Error: 1 of 4 pairs failed (see {out / 'run.json'})"]
    assert [p["status"] for p in run_json(out)["pairs"]] == ["ok", "ok", "failed", "ok"]
    assert not (out / "c").exists() and temp_files(out) == []


# ----------------------------------------------------------------------------- lock
BREAK_HINT = ("if no d3stereo run is writing there (e.g. it was killed on another machine), "
              "rerun with --break-lock; else wait for it or use another -o folder")


def test_live_pid_record_refuses_break_lock_takes_over_dead_pid_is_stale(tmp_path, four_pairs):
    out = tmp_path / "out"
    out.mkdir()
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        # A record naming a live pid of this host whose process holds no flock (e.g. a
        # d3stereo before flock, or a pid reused by a process that started at the same time).
        (out / LOCK_FILE).write_text(json.dumps({"pid": sleeper.pid, "host": socket.gethostname()}))
        result = invoke("run", four_pairs, "-o", out, "--method", "sgbm")
        assert result.exit_code == 1
        assert error_lines(result.output) == [
            f"Error: {out}: the folder is locked by a d3stereo run (pid {sleeper.pid}) that may still be "
            f"running; {BREAK_HINT}"]
        assert not (out / "a").exists()
        assert (out / LOCK_FILE).is_file()  # not ours to remove
        broken = invoke("run", four_pairs, "-o", out, "--method", "sgbm", "--break-lock")
        assert broken.exit_code == 0, broken.output
        assert f"--break-lock: taking over the lock of pid {sleeper.pid}" in broken.output
        assert not (out / LOCK_FILE).exists()
    finally:
        sleeper.kill()
        sleeper.wait()
    (out / LOCK_FILE).write_text(json.dumps({"pid": sleeper.pid, "host": socket.gethostname()}))
    result = invoke("run", four_pairs, "-o", out, "--method", "sgbm")  # its pid is gone now
    assert result.exit_code == 0, result.output
    assert "stale lock" in result.output and f"pid {sleeper.pid}" in result.output
    assert not (out / LOCK_FILE).exists()


def test_reused_pid_is_stale(tmp_path):
    """The record's pid runs, but it is another process (started at another time)."""
    out = tmp_path / "out"
    out.mkdir()
    (out / LOCK_FILE).write_text(json.dumps({"pid": os.getpid(), "host": socket.gethostname(),
                                             "pid_start": "1"}))  # we did not start at tick 1
    lock = acquire_lock(out)
    assert json.loads(lock.path.read_text())["pid_start"] not in (None, "1")
    release_lock(lock)
    assert not (out / LOCK_FILE).exists()


def test_lock_of_another_host_is_respected_unless_broken(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / LOCK_FILE).write_text(json.dumps({"pid": 1, "host": "elsewhere.example"}))
    with pytest.raises(OutputError, match=r"locked by a d3stereo run \(pid 1 on elsewhere.example\) that may still "
                                          r"be running; .*rerun with --break-lock"):
        acquire_lock(out)
    lock = acquire_lock(out, break_lock=True)
    assert json.loads(lock.path.read_text())["host"] == socket.gethostname()
    release_lock(lock)


def test_held_lock_is_never_broken(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    lock = acquire_lock(out)
    try:
        for force in (False, True):
            with pytest.raises(OutputError, match=rf"another d3stereo run \(pid {os.getpid()}\) is writing here"):
                acquire_lock(out, break_lock=force)
    finally:
        release_lock(lock)
    assert not (out / LOCK_FILE).exists()


def test_unreadable_lock_nobody_holds_is_taken_over(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / LOCK_FILE).write_text("")  # a run killed between creating and writing it
    lock = acquire_lock(out)
    assert json.loads(lock.path.read_text())["pid"] == os.getpid()
    release_lock(lock)
    assert not (out / LOCK_FILE).exists()


def test_release_leaves_a_lock_taken_over_by_another_run(tmp_path):
    lock = acquire_lock(tmp_path)
    lock.path.write_text(json.dumps({"pid": os.getpid() + 1, "host": socket.gethostname()}))
    release_lock(lock)
    assert lock.path.exists()


# ----------------------------------------------------------------------------- bad inputs
def test_truncated_png_in_the_middle_of_a_batch(tmp_path, four_pairs):
    data = (four_pairs / "b" / "right.png").read_bytes()
    (four_pairs / "b" / "right.png").write_bytes(data[: len(data) // 2])
    out = tmp_path / "out"
    result = invoke("run", four_pairs, "-o", out, "--method", "sgbm")
    assert error_lines(result.output) == [f"Error: 1 of 4 pairs failed (see {out / 'run.json'})"]
    assert "Traceback" not in result.output
    failed = run_json(out)["failed"]
    assert len(failed) == 1 and failed[0]["pair"] == "b" and "right.png" in failed[0]["error"]
    for name in "acd":
        assert_complete(out / name)
    assert not (out / "b").exists()


def test_pair_and_gt_size_mismatches_in_one_batch(tmp_path, four_pairs):
    write_png(four_pairs / "b" / "right.png", np.zeros((48, 90), np.uint8))
    d3cli.data.formats.write_pfm(four_pairs / "c" / "disp_gt.pfm", np.full((40, 96), 5, np.float32))
    out = tmp_path / "out"
    result = invoke("run", four_pairs, "-o", out, "--method", "sgbm", "--eval")
    assert error_lines(result.output) == [f"Error: 2 of 4 pairs failed (see {out / 'run.json'})"]
    errors = {f["pair"]: f["error"] for f in run_json(out)["failed"]}
    assert "48x96" in errors["b"] and "48x90" in errors["b"]
    assert "disp_gt.pfm" in errors["c"] or "ground truth" in errors["c"]
    assert errors["c"].startswith("c: evaluation failed, maps kept: ")
    assert not (out / "b").exists()
    for name in "acd":  # c: a bad ground truth fails the evaluation, not the maps
        assert_complete(out / name)


# ----------------------------------------------------------------------------- memory
def test_estimate_models_volumes_weights_and_maps():
    cfg = Config()
    h, w, dmax = 100, 200, 63
    # the NCC volume (filtered in place by RBF; full range, the worst band), weights, maps
    expected = (dmax + 1) * h * w * 4 + h * w * 9 * 4 + D3_BYTES_PER_PIXEL * h * w
    assert estimate_peak_bytes((h, w), dmax, cfg, method="d3stereo") == int(expected)
    plain = load_config(None, ["aggregation.rbf=false"])  # the plain bilateral filter: one more volume
    assert estimate_peak_bytes((h, w), dmax, plain, method="d3stereo") == int(expected + (dmax + 1) * h * w * 4)
    # SGBM: the full-DP modes hold (H, W, D16) int16 cost and sum buffers, the others a few rows.
    hh = load_config(None, ["sgbm.mode=hh"])
    full = estimate_peak_bytes((h, w), 255, hh, method="sgbm")
    assert full >= 2 * h * w * 256 * 2
    assert estimate_peak_bytes((h, w), 255, cfg, method="sgbm") < full / 4


def test_check_memory_names_the_estimate_and_the_fix():
    cfg = load_config(None, ["run.max_memory_gb=0.5"])
    assert check_memory((100, 200), 63, cfg, method="d3stereo", where="p") < 0.5e9
    with pytest.raises(InputError) as exc:
        check_memory((2000, 3000), 255, cfg, method="d3stereo", where="big")
    message = str(exc.value)
    expected = estimate_peak_bytes((2000, 3000), 255, cfg, method="d3stereo")
    assert expected > 2000 * 3000 * 256 * 4  # a float32 (H, W, D + 1) volume and more
    assert message.startswith(f"big: estimated peak memory {expected / 1e9:.2f} GB")
    assert "GB for 2000x3000 with max disparity 255 (d3stereo) exceeds the limit 0.50 GB (run.max_memory_gb)" in message
    assert "smaller --max-disparity" in message and "run.max_memory_gb" in message.split(";", 1)[1]


def test_default_limit_is_three_quarters_of_ram(monkeypatch):
    import d3cli.batch.resources as resources

    monkeypatch.setattr(resources, "physical_memory_bytes", lambda: 4_000_000_000)
    with pytest.raises(InputError, match=r"exceeds the limit 3.00 GB \(75% of the 4.0 GB of RAM\)"):
        check_memory((2000, 3000), 255, Config(), method="d3stereo")
    monkeypatch.setattr(resources, "physical_memory_bytes", lambda: None)
    assert check_memory((2000, 3000), 255, Config(), method="d3stereo") > 4e9  # unknown RAM: no check


def test_oversize_pair_fails_alone_before_computing(tmp_path, make_pair_folder, monkeypatch):
    root = tmp_path / "pairs"
    make_pair_folder(root, "a", size=(48, 96))
    make_pair_folder(root, "big", size=(96, 192))
    make_pair_folder(root, "c", size=(48, 96))
    cfg = load_config(None, ["sgbm.mode=hh"])
    small = estimate_peak_bytes((48, 96), 20, cfg, method="sgbm")
    big = estimate_peak_bytes((96, 192), 20, cfg, method="sgbm")
    limit_gb = (small + big) / 2 / 1e9
    computed = []
    real = d3cli.batch.runner.compute_pair

    def spy(method, cfg, left, right, *, max_disparity, **kwargs):
        computed.append(left.shape)
        return real(method, cfg, left, right, max_disparity=max_disparity, **kwargs)

    monkeypatch.setattr(d3cli.batch.runner, "compute_pair", spy)
    out = tmp_path / "out"
    result = invoke("run", root, "-o", out, "--method", "sgbm", "--max-disparity", 20,
                    "--set", "sgbm.mode=hh", "--set", f"run.max_memory_gb={limit_gb!r}")
    assert error_lines(result.output) == [f"Error: 1 of 3 pairs failed (see {out / 'run.json'})"]
    (failure,) = run_json(out)["failed"]
    assert failure["pair"] == "big"
    assert failure["error"].startswith(f"big: estimated peak memory {big / 1e9:.2f} GB for 96x192 with max disparity 20")
    assert (96, 192) not in [s[:2] for s in computed]  # refused before allocating
    assert_complete(out / "a")
    assert_complete(out / "c")


# ----------------------------------------------------------------------------- diagnostics
@pytest.fixture(scope="module")
def d3_results():
    """d3stereo on a good, a swapped and a vertically shifted (unrectified) textured pair."""
    left, right, _ = textured_pair(8, (96, 192), seed=3)
    cfg = load_config(None, ["run.backend=cpu"])
    pairs = {"good": (left, right), "swapped": (right, left),
             "unrectified": (left, np.roll(right, 6, axis=0))}
    return {name: D3Stereo(cfg).compute(lt, rt, max_disparity=32) for name, (lt, rt) in pairs.items()}


def test_good_pair_gives_no_warning(d3_results):
    assert suspicious_result(d3_results["good"], 32) == []


@pytest.mark.parametrize("name", ["swapped", "unrectified"])
def test_swapped_or_unrectified_pair_is_flagged(d3_results, name):
    warnings = suspicious_result(d3_results[name], 32)
    assert warnings, d3_results[name].info
    assert any("pixels were decided by matching" in w for w in warnings)
    assert all("check the inputs" in w or "--max-disparity" in w for w in warnings)


def test_sgbm_swapped_pair_is_flagged_good_is_not():
    left, right, _ = textured_pair(8, (96, 192), seed=3)
    good = d3cli.baselines.sgbm_disparity(left, right, max_disparity=32)
    swapped = d3cli.baselines.sgbm_disparity(right, left, max_disparity=32)
    assert suspicious_result(good, 32) == []
    assert suspicious_result(swapped, 32)


def test_disparities_piled_at_the_range_limits_are_flagged():
    from d3cli.method.pipeline import DisparityResult

    disp = np.full((10, 20), 5.0, np.float32)
    disp[:, :8] = 0.0  # 40 % at 0: what a negative true disparity looks like
    result = DisparityResult(disparity=disp, valid=np.ones_like(disp, bool))
    (warning,) = suspicious_result(result, 32)
    assert warning.startswith("40.0 % of the decided disparities sit at the range limits (40.0 % at 0, 0.0 % at 32)")
    assert "swapped" in warning
    disp[:, :8] = 32.0
    (warning,) = suspicious_result(result, 32)
    assert "raise --max-disparity" in warning


def test_few_seeds_are_flagged_and_no_seeds_not_twice():
    from d3cli.method.pipeline import DisparityResult

    disp = np.full((10, 20), 5.0, np.float32)
    info = {"per_level": [{"level": 3, "shape": [40, 50], "seeds": 10}]}
    result = DisparityResult(disparity=disp, valid=np.ones_like(disp, bool), info=info)
    (warning,) = suspicious_result(result, 32)
    assert warning.startswith("almost no decisive seeds at the coarsest level (0.5 % of its pixels")
    info["per_level"][0]["seeds"] = 0  # the pipeline warns about this itself
    assert suspicious_result(result, 32) == []


def test_batch_stores_diagnostics_warnings(tmp_path, make_pair_folder):
    root = tmp_path / "pairs"
    good = make_pair_folder(root, "good", shift=8, size=(96, 192), seed=3)
    swapped = make_pair_folder(root, "swapped", shift=8, size=(96, 192), seed=3)
    (swapped / "left.png").rename(swapped / "tmp.png")
    (swapped / "right.png").rename(swapped / "left.png")
    (swapped / "tmp.png").rename(swapped / "right.png")
    out = tmp_path / "out"
    result = invoke("run", root, "-o", out, "--method", "sgbm", "--max-disparity", 32, "--eval")
    assert result.exit_code == 0, result.output
    assert json.loads((out / "good" / RESULT_FILE).read_text())["warnings"] == []
    stored = json.loads((out / "swapped" / RESULT_FILE).read_text())["warnings"]
    assert stored and "WARNING: swapped: only" in result.output
    assert [p["warnings"] for p in run_json(out)["pairs"]] == [[], stored]
    summary = json.loads((out / "summary.json").read_text())
    assert [w["pair"] for w in summary["warnings"]] == ["swapped"] * len(stored)
    assert "## Warnings" in (out / "summary.md").read_text()
    assert good.is_dir()
