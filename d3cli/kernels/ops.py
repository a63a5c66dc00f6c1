"""Every per-pixel function of D3Stereo in one namespace: the steps' per-pixel modules
composed (:func:`build_ops`) and compiled with one ``jit``.

The CPU compiles them with ``numba.njit`` (:data:`d3cli.kernels.cpu_common.ops`), CUDA
with ``numba.cuda.jit(device=True)`` (:data:`d3cli.kernels.cuda_launch.ops`).  The steps'
per-pixel modules import :mod:`d3cli.kernels.pixel` (constants and shared helpers), never
this module: it is the one place that imports them all, and the road model's per-pixel
functions (:mod:`d3cli.kernels.road_model`) beside them.
"""

from __future__ import annotations

from types import SimpleNamespace

from .aggregation import pixel as aggregation
from .cost import pixel as cost
from .decisive import pixel_diffusion, pixel_inheritance, pixel_seeds
from .perspective import pixel as perspective
from .pixel import build_shared
from .road_model import build as build_road_model
from .subpixel import pixel as subpixel


def build_ops(jit):
    """Compile every per-pixel function with ``jit`` and return them in one namespace.

    Parameters
    ----------
    jit : callable
        A decorator such as ``numba.njit(cache=True)`` or ``numba.cuda.jit(device=True)``.

    Returns
    -------
    types.SimpleNamespace
        The shared helpers of :func:`d3cli.kernels.pixel.build_shared` and every step's functions:
        ``ncc_cost, cosine_cost, box_sum, cost_or_inf, right_cost_or_inf, rbf_weight, seed_at,
        diffuse_at, inherit_quad, inherit_patch_into, subpixel_at, bilinear_at``, the road
        model's ``pt_shift, pt_restore_at, in_right_image, restore_drops``
        (:mod:`d3cli.kernels.road_model`) and the helpers they use.  The drivers inherit with
        ``inherit_quad`` (one 2x2 patch, each cell read once); the per-pixel form that states eq. 6-8
        literally is a test reference (``tests/reference/inheritance.py``), held to it.

    Notes
    -----
    The protocol of the steps' factories: each step's ``pixel*.py`` has
    ``build(jit, shared) -> SimpleNamespace`` that defines its per-pixel functions, decorated
    with ``jit``, inside one closure, where they may call each other and ``shared`` (the
    namespace of :func:`~d3cli.kernels.pixel.build_shared`, compiled with the same ``jit``).  One closure scope is
    what lets the same source compile for the CPU and for CUDA (calling an ``@njit`` function
    from a CUDA kernel fails in the simulator), which is also why a factory is as long as
    the functions it holds (over 80 lines by design).
    """
    shared = build_shared(jit)
    found = dict(vars(shared)) | vars(build_road_model(jit))
    for step in (cost, aggregation, pixel_seeds, pixel_diffusion, pixel_inheritance, subpixel, perspective):
        found.update(vars(step.build(jit, shared)))
    return SimpleNamespace(**found)
