"""The two child processes that run CUDA code under the simulator (the parity suite and the
launch budget), started as soon as pytest has selected their tests.

The simulator runs every CUDA thread as Python on one core for minutes; started at the
beginning of the session, a child runs beside the rest of the suite on the second core
instead of after it, and its test only waits for the result.  Without the hook (a test run
alone), :func:`result` starts the child itself.
"""

from __future__ import annotations

import atexit
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

#: test node id suffix -> (python arguments, extra environment)
CHILDREN: dict[str, tuple[list[str], dict[str, str]]] = {}
_running: dict[str, tuple[subprocess.Popen, object, object]] = {}


def register(test_name: str, args: list[str], env_extra: dict[str, str]) -> None:
    """Declare the child process of the test named ``test_name``."""
    CHILDREN[test_name] = (args, env_extra)


def start(test_name: str) -> None:
    """Start the child of ``test_name`` (once), its output going to temporary files."""
    if test_name in _running:
        return
    args, env_extra = CHILDREN[test_name]
    out, err = tempfile.TemporaryFile("w+"), tempfile.TemporaryFile("w+")
    proc = subprocess.Popen([sys.executable, *args], cwd=ROOT, env={**os.environ, **env_extra},
                            stdout=out, stderr=err, text=True)
    _running[test_name] = (proc, out, err)


def result(test_name: str, timeout: float) -> subprocess.CompletedProcess:
    """Wait for the child of ``test_name`` (starting it now if the session did not)."""
    start(test_name)
    proc, out, err = _running[test_name]
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        raise
    out.seek(0)
    err.seek(0)
    return subprocess.CompletedProcess(proc.args, proc.returncode, out.read(), err.read())


@atexit.register
def _stop_children() -> None:
    for proc, _, _ in _running.values():
        if proc.poll() is None:
            proc.kill()
