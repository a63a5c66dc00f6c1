"""The stereo methods ``--method`` names: one declaration per method, read by every room.

A :class:`MethodSpec` says what the rest of the package needs to know of a method: its
name, the function that computes a pair (``"module:function"``, imported only when the
method runs), the configuration it is handed and, from that, what a stored pair's
fingerprint covers.  The command line's ``--method`` choices, the check of
``run.method``, the dispatch of :func:`d3cli.batch.compute_pair` and the resume
fingerprint (:mod:`d3cli.batch.fingerprint`) all read :data:`METHOD_SPECS`.

The declarations live here, on the configuration's floor, because ``run.method`` is
checked when a config is loaded, and loading a config imports neither numba nor OpenCV
(``d3cli.config`` may import :mod:`d3cli.errors` only): the code is named by its import
path, and :mod:`d3cli.batch.methods` imports it when a pair is computed.
"""

from __future__ import annotations

from dataclasses import dataclass

#: Sections that no method's map depends on: a method handed the whole configuration
#: reads neither the run settings (``run``), nor the point-cloud camera, nor the road
#: report's settings when it computes a map.
NOT_READ_BY_MAP = ("run", "camera", "road")


@dataclass(frozen=True)
class MethodSpec:
    """One stereo method of ``--method``.

    Attributes
    ----------
    name : str
        The ``--method`` / ``run.method`` name.
    compute : str
        ``"module:function"`` of its entry point, called as ``function(left, right,
        max_disparity=..., cfg=...)`` (and ``pair_dir=...`` when :attr:`pair_dir`); it
        lies in :mod:`d3cli.method` or :mod:`d3cli.baselines` and returns a
        :class:`d3cli.method.DisparityResult`.
    doc : str
        One line: what the method is.
    section : str or None
        The one config section the entry point is handed (``cfg=config.<section>``), and
        all that a stored pair's fingerprint covers of the configuration; None: it is
        handed the whole :class:`~d3cli.config.Config` and the fingerprint covers every
        section but :data:`NOT_READ_BY_MAP`.
    pair_dir : bool
        Whether the entry point is handed the pair's folder (``pair_dir=``), where it
        reads per-pair files (``features.npz``); their identity is then part of the
        fingerprint (:func:`d3cli.batch.fingerprint.feature_files`).
    kernels : bool
        Whether it runs d3stereo's numba kernels: they are compiled (and warmed up) before
        its first pair, and with ``--backend cuda`` it runs on the GPU.
    extra : str or None
        The pip extra whose packages it needs (``pip install "d3stereo[EXTRA]"``); checked
        before a batch starts.
    """

    name: str
    compute: str
    doc: str
    section: str | None = None
    pair_dir: bool = False
    kernels: bool = False
    extra: str | None = None

    def fingerprinted(self, sections) -> tuple[str, ...]:
        """The config sections, of ``sections`` (every section's name), that a stored
        pair's fingerprint covers: :attr:`section` alone, else all but
        :data:`NOT_READ_BY_MAP`."""
        if self.section is not None:
            return (self.section,)
        return tuple(name for name in sections if name not in NOT_READ_BY_MAP)


#: Every method, in the order ``--method`` lists them.
METHOD_SPECS = (
    MethodSpec("d3stereo", "d3cli.method.pipeline:d3stereo_disparity", pair_dir=True, kernels=True,
               doc="decisive disparity diffusion, the paper's method (d3cli.method)"),
    MethodSpec("sgbm", "d3cli.baselines.sgbm:sgbm_disparity", section="sgbm",
               doc="OpenCV's semi-global block matching"),
    MethodSpec("pt-sgm", "d3cli.baselines.pt_sgm:pt_sgm_disparity", kernels=True,
               doc="SGBM after PT-D3Stereo's perspective transformation"),
    MethodSpec("elas", "d3cli.baselines.peers:elas_disparity", section="peers", extra="peers",
               doc="ELAS through pyelas (extra \"peers\")"),
    MethodSpec("pandora-sgm", "d3cli.baselines.peers:pandora_sgm_disparity", section="peers", extra="peers",
               doc="pandora census + SGM (extra \"peers\")"),
)

#: The method names, in :data:`METHOD_SPECS`'s order.
METHODS = tuple(spec.name for spec in METHOD_SPECS)


def method_spec(name: str) -> MethodSpec | None:
    """The :class:`MethodSpec` of the method ``name``, or None when there is none."""
    return next((spec for spec in METHOD_SPECS if spec.name == name), None)
