"""SIGHUP (the terminal or the ssh session closed) ends a batch like SIGTERM: recorded,
unlocked, nothing half-written, exit 129."""

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from d3cli.batch import LOCK_FILE


def _env():
    return {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [os.getcwd(), os.environ.get("PYTHONPATH")]))}


@pytest.mark.parametrize("trial", range(3))
def test_sighup_mid_batch_is_recorded_and_leaves_no_lock_or_staging_folder(tmp_path, make_pair_folder, trial):
    root = tmp_path / "pairs"
    for i in range(30):  # enough pairs that the signal lands while the batch runs
        make_pair_folder(root, f"p{i:02d}", shift=4 + i % 5, size=(240, 400), seed=i)
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "d3cli", "run", str(root), "-o", str(out), "--method", "sgbm"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env())
    try:
        deadline = time.monotonic() + 90
        while len(list(out.glob("*/result.json"))) < 1 + trial:
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline
            time.sleep(0.005)
        proc.send_signal(signal.SIGHUP)
        _, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)
    assert proc.returncode == 129, stderr
    assert stderr.strip().splitlines()[-1].startswith("Terminated (SIGHUP): ")
    assert stderr.strip().splitlines()[-1].endswith(" of 30 pairs done; rerun the same command to resume")
    run = json.loads((out / "run.json").read_text())
    assert run["interrupted"] is True and run["stop_reason"] == "terminated (SIGHUP)"
    assert run["n_failed"] == 0
    assert not (out / LOCK_FILE).exists()
    assert [name for name in os.listdir(out) if name.startswith(".")] == []  # no lock, no staging folder


def test_sighup_after_the_batch_is_recorded_with_129(tmp_path):
    """After run.json recorded the batch complete, SIGHUP is recorded there like SIGTERM."""
    run_json = tmp_path / "run.json"
    run_json.write_text(json.dumps({"interrupted": False}))
    code = ("import os, signal, sys\n"
            "from d3cli.batch.signals import terminate_after_batch\n"
            f"terminate_after_batch({str(run_json)!r}, '2 of 2 pairs done')\n"
            "os.kill(os.getpid(), signal.SIGHUP)\n"
            "signal.pause()\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=_env(), timeout=60)
    assert proc.returncode == 129, proc.stderr
    assert proc.stderr == "Terminated (SIGHUP): 2 of 2 pairs done\n"
    assert json.loads(run_json.read_text()) == {"interrupted": True,
                                                "stop_reason": "terminated (SIGHUP) after the batch had finished"}
