"""Numba kernel of the image pyramid (pipeline step 1; docs/design.md, 'Pyramid and bands').

Each backend builds the pyramid where it computes: the CPU with ``halve.py``, CUDA on the
device from the image uploaded once in its own dtype (``cuda.py``).  ``d3cli.method.pyramid``
calls them through the backend; its docstrings say what a level means.

- ``pixel.py``: the per-pixel 2x2 average, compiled for both targets;
- ``halve.py``: the CPU kernel that halves an image, the bytes of a NumPy expression
  (``tests/kernels/test_pyramid.py`` holds it to that expression), and ``cpu.py`` the
  backend's driver;
- ``cuda.py``: the CUDA driver (conversion of a uint8 image and halving on the device).

May import: ``d3cli.kernels.pool``, ``d3cli.kernels.compile_cache`` (the numba cache folder, chosen on
import), ``d3cli.kernels.cuda_launch`` (``cuda.py``), numba and numpy; no other kernel step.
"""

from __future__ import annotations

# compile_cache.py chooses the numba cache folder before this package's decorators read it
from .. import compile_cache as _compile_cache  # noqa: F401,E402  (import for its side effect)
from . import halve  # noqa: E402
from .halve import halve_area  # noqa: E402

#: The compiled kernels of the package (nogil, cached on disk), run by
#: :func:`d3cli.kernels.pool.run_tasks`.
KERNELS = halve.KERNELS

__all__ = ["KERNELS", "halve_area"]
