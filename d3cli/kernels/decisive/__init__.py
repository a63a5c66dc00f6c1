"""The decisive steps: seeds (PKRN plus left-right check), diffusion (frontier sweeps),
inheritance to the finer level, least costs, sub-pixel refinement, merging and counting
maps.  ``pixel_*.py`` the per-pixel math, ``cpu_*.py`` the CPU drivers, ``cuda.py`` and
``cuda_diffusion.py`` (its own module: the CUDA diffusion is rewritten apart) the CUDA
drivers.

May import: the kernels' shared modules (``pixel``, ``volume``, ``cache``, ``intrinsics``,
``cpu_common``, ``cuda_launch``), numba, numpy, llvmlite; no other step package.
"""
