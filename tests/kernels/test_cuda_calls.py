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


def _simulated(code: str) -> subprocess.CompletedProcess:
    """``code`` run in a child process with the CUDA simulator on; it must succeed."""
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env={**os.environ, "NUMBA_ENABLE_CUDASIM": "1"},
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return proc


def test_launches_and_copies_are_counted_under_the_simulator():
    proc = _simulated(_TOY)
    first, second = proc.stdout.strip().splitlines()
    assert first == "4 3 {'double': 3, 'add_one': 1}"
    assert second == "1 4"  # a new block starts from zero; the hooks of the first are gone


_BYTES = textwrap.dedent(
    """
    import numpy as np
    from numba import cuda
    from d3cli.kernels.cuda_calls import count_cuda_calls

    @cuda.jit
    def add_one(a):
        i = cuda.grid(1)
        if i < a.shape[0]:
            a[i] += 1

    host = np.arange(100, dtype=np.float64)
    with count_cuda_calls() as calls:
        d = cuda.to_device(np.zeros(10, np.int32))          # 40 bytes up
        add_one[1, 128](host)                                # a host array: 800 up, 800 down
        add_one[1, 16](d)                                    # a device array: no copy
        d.copy_to_host()                                     # 40 down
        e = cuda.device_array(10, np.int32)
        e.copy_to_device(d)                                  # device to device: not counted
        e.copy_to_device(np.ones(10, np.int32))              # 40 up
        add_one[1, 16](cuda.In(np.zeros(4, np.int64)))       # 32 up only
    print(calls.launches, calls.host_to_device, calls.host_to_device_bytes,
          calls.device_to_host, calls.device_to_host_bytes)
    print(sorted((k[0], v[1]) for k, v in calls.by_site.items()))
    """
)


def test_bytes_are_counted_under_the_simulator():
    proc = _simulated(_BYTES)
    first, sites = proc.stdout.strip().splitlines()
    assert first == "3 4 912 2 840"
    assert sites == "[('d2h', 40), ('d2h', 800), ('h2d', 32), ('h2d', 40), ('h2d', 40), ('h2d', 800)]"
