"""The decisive steps, one set of files each: seeds (PKRN plus left-right check, and the
merge of fresh seeds into the inherited map), diffusion (frontier sweeps, and the least
cost per pixel its gap test reads), inheritance to the finer level.  Each step has its
per-pixel math (``pixel_seeds.py``, ``pixel_diffusion.py``, ``pixel_inheritance.py``),
its CPU driver (``cpu_*.py``) and its CUDA driver (``cuda_*.py``).  The sub-pixel
refinement is a step of its own (``kernels/subpixel/``), counting decided pixels lives
with the counts (``kernels/cpu.py``, ``kernels/device_counts.py``).

May import: the kernels' shared modules (``pixel``, ``volume``, ``compile_cache``, ``intrinsics``,
``cpu_common``, ``cuda_launch``, ``device_counts``), numba, numpy, llvmlite; no other step package.
"""
