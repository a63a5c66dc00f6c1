"""Numba kernel of the image pyramid (pipeline step 1; docs/design.md, 'Pyramid and bands').

Host only: both backends build their pyramids on the host (the CUDA backend uploads the
levels), so one kernel serves both.  ``d3cli.method.pyramid`` calls it; its docstrings say
what a level means.

- ``halve.py``: the 2x2 area average that halves an image, the bytes of a NumPy
  expression (``tests/kernels/test_pyramid.py`` holds it to that expression).

May import: ``d3cli.kernels.pool``, ``d3cli.kernels.compile_cache`` (the numba cache folder, chosen on
import), numba and numpy; no other kernel step.
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
