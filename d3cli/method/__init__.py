"""The D3Stereo method: the pipeline and one module per step of the algorithm (docs/design.md).

=================  ==========================================================
module             step (section of docs/design.md)
=================  ==========================================================
``pyramid``        1. image pyramid, disparity range per level ('Pyramid and
                   bands')
``cost``           2-3. cost volume and its aggregation ('Cost volumes',
                   'Aggregation', 'Semi-global smoothing')
``features``       deep-feature cost pyramids ('Cost volumes')
``decisive``       4, 5, 7. decisive seeds, intra-scale diffusion, inter-scale
                   inheritance ('Decisive seeds', 'Diffusion', 'Inheritance')
``perspective``    6. perspective transformation for road scenes ('Perspective
                   transformation')
``refinement``     8. sub-pixel refinement, occlusion checks, hole filling,
                   smoothing ('Finishing')
``pipeline``       :class:`D3Stereo`: the steps in order, coarsest level first
=================  ==========================================================

May import: of :mod:`d3cli.kernels` the package (:func:`~d3cli.kernels.get_backend`),
the contract :mod:`d3cli.kernels.backend` and the host facade :mod:`d3cli.kernels.host`
only (``tests/test_architecture.py``); :mod:`d3cli.data` (grey conversion),
:mod:`d3cli.config`, :mod:`d3cli.errors`.  Never batch, baselines, evaluation, road or
the CLI.  Per-pixel arithmetic lives in the kernels' step packages, not here: these
modules turn configuration into scalars and call one kernel per step, on the backend
object (``backend: Backend``) or on the host facade.  The band of disparities a finer
level searches ('Pyramid and bands') is built by the backend (``backend.band_indexes``).
"""

from .pipeline import D3Stereo, DisparityResult

__all__ = ["D3Stereo", "DisparityResult"]
