"""count_cuda_calls counts launches and copies under the CUDA simulator (a child process: the
simulator must be on before numba is imported), as it does on a GPU."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

_TOY = textwrap.dedent(
    """
    import numpy as np
    from numba import cuda
    from d3cli.kernels.cuda_calls import count_cuda_calls

    @cuda.jit(device=True)
    def twice(x):
        return 2 * x

    @cuda.jit
    def double(a):
        i = cuda.grid(1)
        if i < a.shape[0]:
            a[i] = twice(a[i])

    @cuda.jit
    def add_one(a):
        i = cuda.grid(1)
        if i < a.shape[0]:
            a[i] += 1

    host = np.arange(8, dtype=np.int32)
    d = cuda.to_device(host)
    with count_cuda_calls() as calls:
        for _ in range(3):
            double[1, 8](d)        # three launches; the device function is no launch
        add_one[1, 8](host)        # a host array: copied there and back
        d.copy_to_host()
        d.copy_to_host()
    assert (d.copy_to_host() == np.arange(8) * 8).all() and (host == np.arange(8) + 1).all()
    print(calls.launches, calls.device_to_host, dict(calls.by_kernel))
    with count_cuda_calls() as again:
        double[1, 8](d)
    print(again.launches, calls.launches)
    """
)


def test_launches_and_copies_are_counted_under_the_simulator():
    proc = subprocess.run([sys.executable, "-c", _TOY], cwd=ROOT, env={**os.environ, "NUMBA_ENABLE_CUDASIM": "1"},
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    first, second = proc.stdout.strip().splitlines()
    assert first == "4 3 {'double': 3, 'add_one': 1}"
    assert second == "1 4"  # a new block starts from zero; the hooks of the first are gone
