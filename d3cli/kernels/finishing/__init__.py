"""Numba kernels of the finishing of the disparity map (docs/design.md, 'Finishing').

The CPU kernels serve the CPU pipeline and the host part of the CUDA pipeline
(``D3Stereo._finish`` says which steps run on the device); ``d3cli.method.refinement``
calls them; its docstrings say what each step means.  The steps that also run on
the device have their row, column and pixel bodies written once, in a factory taking the
``jit`` decorator (``pixel_occlusion.py``, ``pixel_fill.py``, ``pixel_fill_inside.py``,
``pixel_speckle.py``, ``pixel_smoothing.py``), compiled with ``numba.njit`` for the CPU
tasks here and with ``numba.cuda.jit(device=True)`` for the kernels of ``cuda.py`` (a
thread per row), ``cuda_fill_inside.py`` (a thread per column or row), ``cuda_speckle.py``
(the speckle filter's union-find, a thread per pixel) and ``cuda_smoothing.py``; those are
not imported by this package: the CUDA backend's facade does.  By concern:

- ``occlusion.py``: the uniqueness and left-border tests, fused with the masking, and the
  road model's rules over a map (:mod:`d3cli.kernels.road_model`): the validity after the
  restore of the perspective transformation and the right-image mask;
- ``speckle.py``: OpenCV's 1/16 px fixed point around ``cv2.filterSpeckles``, the dropping
  of the pixels it marked, and the same filter by a union-find (the CPU backend's);
- ``fill.py``: the hole filling (row-wise, median of four directions, empty rows);
- ``exp.py``: NumPy's float32 ``exp``, bit for bit, for the range weights;
- ``smoothing.py``: the Gaussian range smoothing (piecewise-linear bilateral filter), the
  road plane map (the road model's shift) and the clamp of negative values;
- ``range_box.py``: the box range-kernel smoothing;
- ``smooth.py``: the Gaussian smoothing's driver and the backends' smoothing of a finished
  map (``smooth_map``: the road plane from its coefficients, either range kernel).

Every kernel gives exactly the values of a NumPy/OpenCV formulation of the same step (the
reference in ``tests/reference/finishing.py``): the same float32/float64
operations in the same order, bit for bit.  The kernels release the GIL (``nogil``) and run
as tasks over blocks of rows (or groups of range levels) on :mod:`d3cli.kernels.pool`; tasks
write disjoint cells, so the results do not depend on the thread count.  This package
re-exports the public kernels of its modules: ``finishing.fill_inside(...)`` and
``finishing.fill.fill_inside(...)`` are the same function.

May import: ``d3cli.kernels.pool``, ``d3cli.kernels.road_model`` (the road model's per-pixel
rules), ``d3cli.kernels.compile_cache`` (the numba cache folder, chosen on import),
``d3cli.kernels.cuda_launch`` and ``d3cli.kernels.device_counts`` (the ``cuda*.py`` modules only), numba,
numpy and llvmlite; no other kernel step.
"""

from __future__ import annotations

# compile_cache.py chooses a writable numba cache folder (NUMBA_CACHE_DIR) for a read-only install
# and drops stale cached functions when it is imported; the decorators of this package's
# modules read that setting, so it must run first (a package's __init__ runs before any of
# its modules).
from .. import compile_cache as _compile_cache  # noqa: F401,E402  (import for its side effect)
from . import exp, fill, occlusion, range_box, smooth, smoothing, speckle  # noqa: E402
from .exp import numpy_exp, numpy_expf  # noqa: E402
from .fill import (copy_nearest_rows, fill_inside, fill_inside_holes, fill_rows_smaller_side,  # noqa: E402
                   keep_valid, nearest_along_columns, usable)
from .occlusion import (drop_occluded, out_of_view_mask, restored_validity, right_image_mask,  # noqa: E402
                        uniqueness_occluded)
from .range_box import box_range_smooth, box_smooth_disparity  # noqa: E402
from .smooth import gaussian_smooth, range_kernel_smooth, smooth_map, unsmoothed  # noqa: E402
from .smoothing import (at_least_zero, clamp_negative, combine_shares, range_levels,  # noqa: E402
                        residual_and_range, shift_plane_f32, smooth_groups)
from .speckle import drop_marked, drop_speckles, filter_speckles, fixed_point_16, fixed_point_16_finite  # noqa: E402

#: The compiled kernels of the package (nogil, cached on disk), run by
#: :func:`d3cli.kernels.pool.run_tasks`.
KERNELS = occlusion.KERNELS + speckle.KERNELS + fill.KERNELS + exp.KERNELS + smoothing.KERNELS + range_box.KERNELS

__all__ = [
    "KERNELS", "at_least_zero", "box_range_smooth", "box_smooth_disparity", "clamp_negative", "combine_shares",
    "copy_nearest_rows", "drop_marked", "drop_occluded", "drop_speckles", "exp", "fill", "fill_inside",
    "fill_inside_holes", "fill_rows_smaller_side", "filter_speckles", "fixed_point_16", "fixed_point_16_finite",
    "gaussian_smooth", "keep_valid", "nearest_along_columns", "numpy_exp", "numpy_expf",
    "occlusion", "out_of_view_mask", "range_box", "range_kernel_smooth", "range_levels", "residual_and_range", "restored_validity",
    "right_image_mask", "shift_plane_f32", "smooth", "smooth_groups", "smooth_map", "smoothing", "speckle",
    "uniqueness_occluded", "unsmoothed", "usable",
]
