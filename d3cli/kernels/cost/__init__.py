"""Matching cost (pipeline step 2): NCC and cosine (deep-feature) cost volumes, integral
images, the banded index of finer levels, out-of-view invalidation.  ``pixel.py`` the
per-pixel math, ``cpu.py`` and ``cuda.py`` the drivers, ``band.py`` the host-side index.

May import: the kernels' shared modules (``pixel``, ``volume``, ``compile_cache``, ``intrinsics``,
``cpu_common``, ``cuda_launch``), numba, numpy, llvmlite; no other step package.
"""
