"""The perspective transformation: the warp of the right image by the road model, the
restore of full-range disparities, and the RANSAC scoring of the road fit
(``road_fit.py``, host side).  ``pixel.py`` the per-pixel math, ``cpu.py`` and ``cuda.py``
the drivers.

May import: the kernels' shared modules (``pixel``, ``volume``, ``compile_cache``, ``intrinsics``,
``cpu_common``, ``cuda_launch``), numba, numpy, llvmlite; no other step package.
"""
