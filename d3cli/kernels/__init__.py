"""Compute kernels, by pipeline step, and the choice of backend.

Each step package (``cost/``, ``aggregation/``, ``sgm/``, ``decisive/``, ``subpixel/``,
``perspective/``) holds the step's per-pixel math (``pixel*.py``: one body compiled for
the CPU with ``numba.njit`` and for CUDA with ``numba.cuda.jit(device=True)``), its CPU
driver and its CUDA driver side by side; ``finishing/`` and ``pyramid/`` hold host-only
kernels that serve both backends.  ``cpu.py`` and ``cuda.py`` are the two backends (thin
facades over the steps, naming exactly the contract), ``backend.py`` their contract;
:func:`get_backend` picks one.  ``host.py`` is the facade of the host-only kernels
(volume layout, band indexes, pyramid, finishing, road-fit solvers, the warp of a host
image): with the backend object, all that :mod:`d3cli.method` and :mod:`d3cli.baselines`
use.  Shared pieces: ``pixel.py`` (per-pixel constants and the helpers of several steps;
imports no step), ``ops.py`` (:func:`~d3cli.kernels.ops.build_ops`, composing every
step's per-pixel functions), ``volume.py`` (banded volume layout), ``compile_cache.py``
(numba's cache kept valid: its folder, stale and damaged entries dropped),
``cache_location.py`` (where the cache lives, the first-run compile notice; standard
library only), ``intrinsics.py`` (LLVM intrinsics), ``cpu_common.py`` / ``cuda_launch.py``
(each target's compiled ops and launch helpers), ``device_counts.py`` (counts left on the
device), ``device_outputs.py`` (the finished map, its validity and the counts in one
download), ``pool.py`` (task pool), ``allocator.py`` (malloc settings, applied on import
below), ``cuda_probe.py`` (the CUDA smoke test) and ``cuda_calls.py`` (launch and copy
counter).
May import: ``errors`` only, numba, numpy and llvmlite (``tests/test_architecture.py``).
"""

from __future__ import annotations

import functools
import logging
import os
import warnings

# Worker threads of numba's OpenMP layer sleep when a parallel loop ends instead of
# spinning (GNU OpenMP's default).  The pipeline runs many short parallel loops with
# serial steps in between; on a busy machine spinning threads take the cores those
# steps (and other processes, and --workers siblings) need (docs/performance.md has the
# measurement).  Must be set before the OpenMP runtime loads (the first parallel kernel
# call); a value the user set is kept.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from ..errors import BackendUnavailable  # noqa: E402
from .allocator import keep_freed_memory  # noqa: E402

# Freed volumes stay in the heap: the next level's and the next pair's arrays are not
# faulted in page by page again (allocator.py has the measurement).
keep_freed_memory()

log = logging.getLogger(__name__)

#: What :func:`cuda_status` and :func:`device_description` say under the simulator.
SIMULATOR = "CUDA simulator (NUMBA_ENABLE_CUDASIM=1)"


def quiet_numba_cuda() -> None:
    """Keep numba's CUDA warnings off the user's terminal.

    numba warns on every launch of a small grid ("Grid size N will likely result in GPU
    under-utilization") and on its deprecated device-array API; neither is the user's to act
    on.  The low-occupancy check is switched off at its source (numba-cuda keeps its config in
    ``numba.cuda.core.config``, numba's bundled target in ``numba.core.config``) and the warning
    classes are ignored.
    """
    import importlib

    for name in ("numba.cuda.core.config", "numba.core.config"):
        try:
            importlib.import_module(name).CUDA_LOW_OCCUPANCY_WARNINGS = 0
        except Exception:  # that numba has no such module
            pass
    for name, cls in (("numba.cuda.core.errors", "NumbaPerformanceWarning"),
                      ("numba.core.errors", "NumbaPerformanceWarning"),
                      ("numba.cuda.core.errors", "NumbaDeprecationWarning"),
                      ("numba.core.errors", "NumbaDeprecationWarning"),
                      ("numba.cuda.testing", "DeprecatedDeviceArrayApiWarning")):
        try:
            category = getattr(importlib.import_module(name), cls)
        except Exception:
            continue
        warnings.filterwarnings("ignore", category=category)
    warnings.filterwarnings("ignore", message=r"Grid size \d+ will likely result in GPU under-utilization")


def _one_line(exc: BaseException) -> str:
    """``Type: first line of the message`` (numba's errors run over many lines)."""
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0] if text else ''}".rstrip(": ")


@functools.lru_cache(maxsize=1)
def _cuda_probe() -> tuple[str | None, str]:
    """``(kind, reason)``: kind is "device", "simulator" or None (not usable); never raises.

    "Usable" means that the CUDA backend imported and one test kernel compiled, ran and
    copied its result back (:mod:`d3cli.kernels.cuda_probe`); the answer is kept for the
    process.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # numba's deprecation and performance chatter
        try:
            from numba import config as numba_config
            from numba import cuda  # numba-cuda provides the target
        except Exception as exc:  # ImportError, or a broken CUDA install
            return None, (f"numba.cuda cannot be imported ({_one_line(exc)}); "
                          "install the cuda extra: pip install 'd3stereo[cuda]'")
        simulator = bool(getattr(numba_config, "ENABLE_CUDASIM", False))
        if not simulator:
            try:
                if not cuda.is_available():
                    return None, "no CUDA driver or device found (numba.cuda.is_available() is False)"
            except Exception as exc:
                return None, f"CUDA initialisation failed ({_one_line(exc)})"
        try:
            quiet_numba_cuda()
            from . import cuda as _cuda_backend  # noqa: F401
        except Exception as exc:  # e.g. numba-cuda 0.30 with numpy 2.5: AttributeError row_stack
            return None, (f"the CUDA backend could not be loaded ({_one_line(exc)}); "
                          "reinstall with pip install 'd3stereo[cuda]' (it pins a numpy that numba-cuda supports)")
        try:
            from .cuda_probe import launch_one

            launch_one()
        except Exception as exc:  # no NVVM/NVRTC, unsupported device, out of memory ...
            return None, f"a test kernel could not run ({_one_line(exc)}); see the GPU section of the docs"
    if simulator:
        return "simulator", SIMULATOR
    return "device", "CUDA device available (a test kernel ran)"


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


def _driver_present() -> bool:
    """Whether an NVIDIA driver library is installed (a GPU machine whose CUDA stack is broken)."""
    import ctypes.util

    return ctypes.util.find_library("cuda") is not None or os.path.exists("/proc/driver/nvidia/version")


def chosen_backend(name: str = "auto") -> str | None:
    """The backend :func:`get_backend` returns for ``name``, without loading or logging it:
    ``"cpu"`` or ``"cuda"``; None when ``name`` is ``"cuda"`` and CUDA cannot be used
    (``get_backend`` raises).  ``auto`` takes CUDA on a usable device only, never the
    simulator."""
    if name == "cpu":
        return "cpu"
    usable, reason = cuda_status()
    if name == "cuda":
        return "cuda" if usable else None
    return "cuda" if usable and reason != SIMULATOR else "cpu"


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
    choice = chosen_backend(name)
    if name == "cuda":
        if choice is None:
            origin = getattr(name, "origin", "")  # run.backend of a config file (config.checks.value_origin)
            raise BackendUnavailable(f"{origin}: cuda cannot be used ({reason}); set it to cpu or auto there, "
                                     "or pass --backend cpu"
                                     if origin else f"--backend cuda: {reason}; use --backend cpu or auto")
        from . import cuda as cuda_backend

        if kind == "simulator":
            log.warning("backend cuda: running on the %s; this is for tests and very slow", SIMULATOR)
        return cuda_backend, "cuda"
    if choice == "cuda":
        from . import cuda as cuda_backend

        log.info("backend auto: using CUDA (%s)", device_description())
        return cuda_backend, "cuda"
    from . import cpu

    if kind == "simulator":
        reason = f"only the {SIMULATOR} is available, too slow for auto; pass --backend cuda to use it"
    if kind is None and _driver_present():
        log.warning("backend auto: a CUDA driver is installed but CUDA cannot be used, running on the CPU: %s", reason)
    else:
        log.info("backend auto: using the CPU (%s)", reason)
    return cpu, "cpu"
