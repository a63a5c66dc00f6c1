"""The D3Stereo method: the pipeline and one module per step of the algorithm (docs/design.md).

=================  ==========================================================
module             step
=================  ==========================================================
``pyramid``        1. image pyramid, disparity range per level
``cost``           2-3. NCC cost volume and its aggregation (RBF / bilateral)
``decisive``       4, 5, 7. decisive seeds, intra-scale diffusion, inter-scale
                   inheritance
``perspective``    6. perspective transformation for road scenes (PT)
``refinement``     8. sub-pixel refinement, occlusion checks, hole filling,
                   smoothing
``pipeline``       :class:`D3Stereo`: the steps in order, coarsest level first
=================  ==========================================================

May import: :mod:`d3cli.kernels`, :mod:`d3cli.data` (grey conversion),
:mod:`d3cli.config`, :mod:`d3cli.errors`.  Never batch, baselines, evaluation, road or
the CLI.  Per-pixel arithmetic lives in :mod:`d3cli.kernels.pixel`, not here: these
modules turn configuration into scalars and call one kernel per step.
"""

from .pipeline import D3Stereo, DisparityResult

__all__ = ["D3Stereo", "DisparityResult"]
