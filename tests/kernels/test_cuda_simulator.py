"""Run the CUDA parity tests (every room's test_cuda.py under tests/kernels) under the CUDA simulator, and check the
backend selection without a GPU.

The simulator must be switched on before numba is imported, so the CUDA tests run in a
separate process with ``NUMBA_ENABLE_CUDASIM=1``; this process keeps the real CPU JIT.
On a machine with a GPU run the same tests on hardware with
``python -m pytest -m cuda tests/kernels``.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from tests.kernels import simulator_children

ROOT = Path(__file__).resolve().parents[2]


def _run(args, *, env_extra, timeout):
    env = {**os.environ, **env_extra}
    return subprocess.run(
        [sys.executable, *args], cwd=ROOT, env=env, capture_output=True, text=True, timeout=timeout
    )


simulator_children.register("test_cuda_kernels_match_cpu_under_the_simulator",
                            ["-m", "pytest", "-q", "-m", "cuda and not slow", "tests/kernels", "-p", "no:cacheprovider"],
                            {"NUMBA_ENABLE_CUDASIM": "1"})


def test_cuda_kernels_match_cpu_under_the_simulator():
    try:
        import numba.cuda  # noqa: F401
    except ImportError as exc:
        pytest.skip(f"numba.cuda cannot be imported ({exc}); install the cuda extra to run the CUDA tests")
    # (the launch budget's own children run inside it, one after the other: minutes more;
    # its 160x96 road, tens of minutes, is marked slow and left out)
    proc = simulator_children.result("test_cuda_kernels_match_cpu_under_the_simulator", timeout=2400)
    output = proc.stdout + proc.stderr
    assert proc.returncode == 0, "CUDA tests under the simulator failed:\n" + output[-6000:]
    summary = output.strip().splitlines()[-1]
    assert " passed" in summary and "skipped" not in summary, summary


# A child process in which numba.cuda (and numba-cuda) cannot be imported, as when the
# cuda extra is not installed: the package must import and the CPU must work.
_WITHOUT_NUMBA_CUDA = textwrap.dedent(
    """
    import importlib.abc, sys

    class Block(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name == "numba.cuda" or name.startswith(("numba.cuda.", "numba_cuda")):
                raise ImportError(f"blocked for the test: {name}")
            return None

    sys.meta_path.insert(0, Block())
    import numpy as np
    from d3cli import BackendUnavailable, D3Stereo, load_config
    from d3cli.kernels import cuda_status, device_description, get_backend

    usable, why = cuda_status()
    assert not usable and "numba.cuda cannot be imported" in why and "d3stereo[cuda]" in why, why
    assert device_description().startswith("none (numba.cuda cannot be imported"), device_description()
    assert get_backend("auto")[1] == "cpu" and get_backend("cpu")[1] == "cpu"
    try:
        get_backend("cuda")
    except BackendUnavailable as exc:
        assert str(exc).startswith("--backend cuda: numba.cuda cannot be imported"), exc
    else:
        raise SystemExit("get_backend('cuda') did not raise")
    rng = np.random.default_rng(0)
    left = rng.uniform(0, 255, (16, 40)).astype(np.float32)
    right = np.roll(left, -3, axis=1)
    result = D3Stereo(load_config(overrides=["run.backend=auto"])).compute(left, right, max_disparity=6)
    assert result.info["backend"] == "cpu"
    assert "numba.cuda" not in sys.modules
    print("OK")
    """
)


def test_package_and_cpu_work_without_numba_cuda():
    proc = _run(["-c", _WITHOUT_NUMBA_CUDA], env_extra={"NUMBA_ENABLE_CUDASIM": "0"}, timeout=300)
    assert proc.returncode == 0 and proc.stdout.strip().endswith("OK"), proc.stdout[-3000:] + proc.stderr[-3000:]


def test_auto_and_info_without_a_gpu(caplog):
    from d3cli.kernels import cuda_status, device_description, get_backend

    usable, why = cuda_status()
    if usable:
        pytest.skip("CUDA is usable here")
    with caplog.at_level("INFO", logger="d3cli.kernels"):
        module, name = get_backend("auto")
    assert name == "cpu"
    assert f"backend auto: using the CPU ({why})" in caplog.text
    assert device_description() == f"none ({why})"
