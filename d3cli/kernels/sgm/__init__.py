"""Semi-global smoothing of a banded cost volume (four paths).  ``pixel.py`` one pixel
of one path, ``cpu.py`` and ``cuda.py`` the drivers.

May import: the kernels' shared modules (``pixel``, ``volume``, ``cache``, ``intrinsics``,
``cpu_common``, ``cuda_launch``), numba, numpy, llvmlite; no other step package.
"""
