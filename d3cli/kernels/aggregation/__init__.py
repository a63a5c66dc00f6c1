"""Cost aggregation (pipeline step 3): RBF weights, the recursive bilateral filter's
passes over banded rows, the plain bilateral filter.  ``pixel.py`` the per-pixel kernel,
``cpu.py`` (with ``cpu_rows.py`` and ``cpu_vector.py``) and ``cuda.py`` the drivers.

May import: the kernels' shared modules (``pixel``, ``volume``, ``compile_cache``, ``intrinsics``,
``cpu_common``, ``cuda_launch``), numba, numpy, llvmlite; no other step package.
"""
