"""Compute kernels.  ``pixel.py`` holds the per-pixel math; ``cpu.py`` and ``cuda.py``
compile it for their target and drive it.  :func:`get_backend` picks one.
``volume.py`` is the banded volume layout, ``finishing.py`` and ``range_box.py`` the
host-side step-8 kernels, ``road_fit.py`` the RANSAC scoring of step 6, ``allocator.py``
the process's malloc settings (applied on import, below).  May import: ``errors`` only (``tests/test_architecture.py``)."""

from __future__ import annotations

import logging
import os

# Worker threads of numba's OpenMP layer sleep when a parallel loop ends instead of
# spinning (GNU OpenMP's default).  The pipeline runs many short parallel loops with
# serial steps in between; on a busy 2-core machine the spinning threads took the cores
# those steps (and other processes, and --workers siblings) needed: PT-D3Stereo on a
# 1280x720 road pair went from 6.2x to 4.0x SGBM's time, Middlebury-Q from 15.7x to 8.8x
# (scripts/bench_speed.py, one loaded run each way).  Must be set before the OpenMP
# runtime loads (the first parallel kernel call); a value the user set is kept.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from ..errors import BackendUnavailable  # noqa: E402
from .allocator import keep_freed_memory  # noqa: E402

# Freed volumes stay in the heap: the next level's and the next pair's arrays are not
# faulted in page by page again (allocator.py has the measurement).
keep_freed_memory()

log = logging.getLogger(__name__)

#: What :func:`cuda_status` and :func:`device_description` say under the simulator.
SIMULATOR = "CUDA simulator (NUMBA_ENABLE_CUDASIM=1)"


def _cuda_probe() -> tuple[str | None, str]:
    """``(kind, reason)``: kind is "device", "simulator" or None (not usable); never raises."""
    try:
        from numba import config as numba_config
        from numba import cuda  # numba-cuda provides the target
    except Exception as exc:  # ImportError, or a broken CUDA install
        return None, f"numba.cuda cannot be imported ({exc}); install the cuda extra: pip install 'd3stereo[cuda]'"
    simulator = bool(getattr(numba_config, "ENABLE_CUDASIM", False))
    if not simulator:
        try:
            if not cuda.is_available():
                return None, "no CUDA driver or device found (numba.cuda.is_available() is False)"
        except Exception as exc:
            return None, f"CUDA initialisation failed ({exc})"
    try:
        from . import cuda as _cuda_backend  # noqa: F401
    except ImportError as exc:
        return None, f"the CUDA backend could not be loaded ({exc})"
    if simulator:
        return "simulator", SIMULATOR
    return "device", "CUDA device available"


def cuda_status() -> tuple[bool, str]:
    """Whether the CUDA backend can run here, and why (not); never raises.

    The CUDA simulator (``NUMBA_ENABLE_CUDASIM=1``) counts as usable, with the reason
    :data:`SIMULATOR`, so that ``--backend cuda`` and the tests run under it; ``auto``
    never picks it (see :func:`get_backend`).
    """
    kind, reason = _cuda_probe()
    return kind is not None, reason


def device_description() -> str:
    """One line naming the CUDA device: name, compute capability and memory.

    Under the simulator :data:`SIMULATOR`; without a usable device ``"none (<why>)"``.
    Never raises.
    """
    kind, reason = _cuda_probe()
    if kind is None:
        return f"none ({reason})"
    if kind == "simulator":
        return SIMULATOR
    try:
        from numba import cuda

        dev = cuda.get_current_device()
        name = dev.name.decode() if isinstance(dev.name, bytes) else str(dev.name)
        major, minor = dev.compute_capability
        _free, total = cuda.current_context().get_memory_info()
    except Exception as exc:  # a device that is listed but cannot be opened
        return f"CUDA device (details unavailable: {exc})"
    return f"{name}, compute capability {major}.{minor}, {total / 2**30:.1f} GiB"


def get_backend(name: str = "auto"):
    """Return ``(module, name)`` of the kernel backend to use.

    Parameters
    ----------
    name : {"auto", "cpu", "cuda"}
        ``auto`` picks CUDA when a real device is usable, else the CPU, and logs which
        and why (the CUDA simulator is far too slow to be picked automatically).
        ``cuda`` also accepts the simulator.

    Raises
    ------
    BackendUnavailable
        ``cuda`` was requested but cannot be used; the message says why.
    """
    if name == "cpu":
        from . import cpu

        return cpu, "cpu"
    kind, reason = _cuda_probe()
    if name == "cuda":
        if kind is None:
            raise BackendUnavailable(f"--backend cuda: {reason}; use --backend cpu or auto")
        from . import cuda as cuda_backend

        if kind == "simulator":
            log.warning("backend cuda: running on the %s; this is for tests and very slow", SIMULATOR)
        return cuda_backend, "cuda"
    if kind == "device":
        from . import cuda as cuda_backend

        log.info("backend auto: using CUDA (%s)", device_description())
        return cuda_backend, "cuda"
    from . import cpu

    if kind == "simulator":
        reason = f"only the {SIMULATOR} is available, too slow for auto; pass --backend cuda to use it"
    log.info("backend auto: using the CPU (%s)", reason)
    return cpu, "cpu"
