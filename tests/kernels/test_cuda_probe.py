"""The CUDA probe says "usable" only when a kernel really ran, and a broken CUDA install is one
clear line everywhere: ``d3stereo info``, ``--backend cuda`` and ``auto``.

The broken install is faked in a child process under the CUDA simulator: the import of
d3stereo's CUDA backend raises what numba-cuda 0.30.4 raised with numpy 2.5 on a real GPU
machine (``AttributeError: module 'numpy' has no attribute 'row_stack'``).
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

# Installed before anything of d3cli is imported: the CUDA backend module fails to import.
_BREAK_CUDA_BACKEND = textwrap.dedent(
    """
    import importlib.abc, sys

    class Broken(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name == "d3cli.kernels.cuda":
                raise AttributeError("module 'numpy' has no attribute 'row_stack'")
            return None

    sys.meta_path.insert(0, Broken())
    """
)


def _child(code: str, *args: str, timeout: int = 300) -> subprocess.CompletedProcess:
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1"}
    return subprocess.run([sys.executable, "-c", _BREAK_CUDA_BACKEND + code, *args], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=timeout)


def test_a_backend_that_cannot_import_is_not_usable_and_says_why_in_one_line():
    proc = _child(textwrap.dedent(
        """
        import logging
        logging.basicConfig(level=logging.INFO, format="%(levelname)s %(message)s")
        from d3cli import BackendUnavailable
        from d3cli.kernels import cuda_status, device_description, get_backend
        usable, why = cuda_status()
        print("STATUS", usable, why)
        print("DEVICE", device_description())
        print("AUTO", get_backend("auto")[1])
        try:
            get_backend("cuda")
        except BackendUnavailable as exc:
            print("CUDA", exc)
        """))
    assert proc.returncode == 0, proc.stderr[-3000:]
    lines = dict(line.split(" ", 1) for line in proc.stdout.splitlines())
    why = ("the CUDA backend could not be loaded (AttributeError: module 'numpy' has no attribute 'row_stack'); "
           "reinstall with pip install 'd3stereo[cuda]' (it pins a numpy that numba-cuda supports)")
    assert lines["STATUS"] == f"False {why}"
    assert lines["DEVICE"] == f"none ({why})"
    assert lines["AUTO"] == "cpu"
    assert lines["CUDA"] == f"--backend cuda: {why}; use --backend cpu or auto"
    assert f"backend auto: using the CPU ({why})" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_cli_info_and_run_with_a_broken_cuda_backend(tmp_path):
    code = "import sys; from d3cli.__main__ import entry; sys.argv = ['d3stereo', *sys.argv[1:]]; entry()"
    info = _child(code, "info")
    assert info.returncode == 0, info.stderr[-3000:]
    line = [x for x in info.stdout.splitlines() if x.startswith("cuda not usable: ")]
    assert line == ["cuda not usable: the CUDA backend could not be loaded (AttributeError: module 'numpy' has no "
                    "attribute 'row_stack'); reinstall with pip install 'd3stereo[cuda]' (it pins a numpy that "
                    "numba-cuda supports)"]
    run = _child(code, "run", "--backend", "cuda", "-o", str(tmp_path / "out"))
    assert run.returncode != 0
    assert "Traceback" not in run.stderr
    errors = [x for x in run.stderr.splitlines() if x.startswith("Error:")]
    assert errors == ["Error: --backend cuda: the CUDA backend could not be loaded (AttributeError: module 'numpy' "
                      "has no attribute 'row_stack'); reinstall with pip install 'd3stereo[cuda]' (it pins a numpy "
                      "that numba-cuda supports); use --backend cpu or auto"], run.stderr


def test_the_simulator_probe_runs_a_kernel():
    proc = subprocess.run(
        [sys.executable, "-c", "from d3cli.kernels import cuda_status; print(cuda_status())"],
        cwd=ROOT, env={**os.environ, "NUMBA_ENABLE_CUDASIM": "1"}, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert proc.stdout.strip() == "(True, 'CUDA simulator (NUMBA_ENABLE_CUDASIM=1)')"
