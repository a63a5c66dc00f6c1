"""The smallest real use of the CUDA target: compile one kernel, launch it, copy its result back.

``numba.cuda.is_available()`` only says that a driver answers; a CUDA install can still fail
where d3stereo needs it (no NVVM or NVRTC library to compile with, a numba-cuda that does not
import with this numpy, a device the toolkit cannot target).  :func:`launch_one` exercises
compile, launch and copy, so ``cuda_status()`` says "usable" only when a kernel really ran.
"""

from __future__ import annotations

import numpy as np
from numba import cuda


@cuda.jit(cache=True)
def _write_answer(out):
    if cuda.grid(1) == 0:
        out[0] = 42


def launch_one() -> None:
    """Compile and run a one-thread kernel; raise when anything on the way fails."""
    out = cuda.to_device(np.zeros(1, np.int32))
    _write_answer[1, 1](out)
    got = int(out.copy_to_host()[0])
    if got != 42:
        raise RuntimeError(f"a test kernel wrote {got} instead of 42")
