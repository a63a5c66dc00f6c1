"""Two processes take over the same stale lock at the same moment.

Before flock, both saw the lock as stale, both removed it and both created their own:
two runs wrote into one folder.  ``os.kill`` (the liveness probe of the stale check) is
slowed down in both processes to widen that window to 0.3 s, so the race is not left to
luck.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path

from d3cli.batch import LOCK_FILE

TAKER = textwrap.dedent("""
    import json, os, sys, time
    from pathlib import Path

    out, go = Path(sys.argv[1]), Path(sys.argv[2])
    real_kill = os.kill

    def slow_kill(pid, sig):  # the window between "is its run gone?" and taking the lock
        time.sleep(0.3)
        return real_kill(pid, sig)

    os.kill = slow_kill
    from d3cli.batch import acquire_lock, release_lock
    from d3cli.errors import OutputError

    print("ready", flush=True)
    while not go.exists():
        time.sleep(0.001)
    try:
        lock = acquire_lock(out)
    except OutputError as exc:
        print("refused", exc, flush=True)
        sys.exit(3)
    time.sleep(1.0)  # hold it while the other one tries
    still_mine = json.loads(Path(lock).read_text())["pid"] == os.getpid() and Path(lock).exists()
    print("took", "still-holder" if still_mine else "lost-it", flush=True)
    release_lock(lock)
""")


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_two_processes_taking_over_a_stale_lock_one_wins(tmp_path):
    script = tmp_path / "taker.py"
    script.write_text(TAKER)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(__file__).resolve().parents[2]),
                                                        os.environ.get("PYTHONPATH", "")])}
    for round_ in range(3):
        out = tmp_path / f"out{round_}"
        out.mkdir()
        (out / LOCK_FILE).write_text(json.dumps({"pid": _dead_pid(), "host": socket.gethostname()}))
        go = tmp_path / f"go{round_}"
        procs = [subprocess.Popen([sys.executable, str(script), str(out), str(go)], stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, text=True, env=env) for _ in range(2)]
        try:
            for proc in procs:
                assert proc.stdout.readline().strip() == "ready", proc.communicate()
            go.touch()
            outputs = [proc.communicate(timeout=60) for proc in procs]
        finally:
            for proc in procs:
                if proc.poll() is None:
                    proc.kill()
        lines = [stdout.strip() for stdout, _ in outputs]
        took = [line for line in lines if line.startswith("took")]
        refused = [line for line in lines if line.startswith("refused")]
        assert len(took) == 1 and len(refused) == 1, (lines, [err[-2000:] for _, err in outputs])
        assert took == ["took still-holder"]
        assert "another d3stereo run" in refused[0] and "is writing here" in refused[0]
        assert sorted(p.returncode for p in procs) == [0, 3]
        assert not (out / LOCK_FILE).exists()  # the winner released it
        time.sleep(0.05)
