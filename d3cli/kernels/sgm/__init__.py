"""Semi-global smoothing of a banded cost volume (four paths).  ``cpu.py`` and ``cuda.py``
the drivers (the CPU's two sweeps of two paths each, on the task pool), each with the path
step in its own vector form (the recurrence:
:meth:`d3cli.kernels.backend.Backend.sgm_smooth`).

May import: the kernels' shared modules (``pixel``, ``volume``, ``compile_cache``, ``intrinsics``,
``cpu_common``, ``cuda_launch``, ``pool``), numba, numpy, llvmlite; no other step package.
"""
