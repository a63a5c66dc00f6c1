"""The sub-pixel refinement (pipeline step 8, docs/design.md, 'Finishing'): a parabola, or
two lines of equal slope, through the costs around each decided disparity.  It reads the
cost volume, so it runs on the backend, unlike the rest of the finishing (host-only,
``finishing/``).  ``pixel.py`` the per-pixel math, ``cpu.py`` and ``cuda.py`` the drivers.

May import: the kernels' shared modules (``pixel``, ``volume``, ``compile_cache``,
``intrinsics``, ``cpu_common``, ``cuda_launch``), numba, numpy, llvmlite; no other step package.
"""
