"""Compute kernels.  ``pixel.py`` holds the per-pixel math; ``cpu.py`` and ``cuda.py``
compile it for their target and drive it.  :func:`get_backend` picks one."""

from __future__ import annotations

import logging

from ..errors import BackendUnavailable

log = logging.getLogger(__name__)


def cuda_status() -> tuple[bool, str]:
    """Whether CUDA is usable here, and why not (never raises)."""
    try:
        from numba import cuda  # noqa: F401  (numba-cuda provides the target)
    except Exception as exc:  # ImportError, or a broken CUDA install
        return False, f"numba.cuda cannot be imported ({exc}); install the cuda extra: pip install 'd3stereo[cuda]'"
    try:
        if not cuda.is_available():
            return False, "no CUDA driver or device found (numba.cuda.is_available() is False)"
    except Exception as exc:
        return False, f"CUDA initialisation failed ({exc})"
    try:
        from . import cuda as _cuda_backend  # noqa: F401
    except ImportError as exc:
        return False, f"the CUDA backend could not be loaded ({exc})"
    return True, "CUDA device available"


def get_backend(name: str = "auto"):
    """Return ``(module, name)`` of the kernel backend to use.

    Parameters
    ----------
    name : {"auto", "cpu", "cuda"}
        ``auto`` picks CUDA when a device is usable, else the CPU, and logs which and why.

    Raises
    ------
    BackendUnavailable
        ``cuda`` was requested but cannot be used; the message says why.
    """
    if name == "cpu":
        from . import cpu

        return cpu, "cpu"
    ok, reason = cuda_status()
    if name == "cuda":
        if not ok:
            raise BackendUnavailable(f"--backend cuda: {reason}; use --backend cpu or auto")
        from . import cuda as cuda_backend

        return cuda_backend, "cuda"
    if ok:
        from . import cuda as cuda_backend

        log.info("backend auto: using CUDA (%s)", reason)
        return cuda_backend, "cuda"
    from . import cpu

    log.info("backend auto: using the CPU (%s)", reason)
    return cpu, "cpu"
