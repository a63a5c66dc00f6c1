"""The stereo methods ``--method`` names: one declaration per method, read by every room.

A :class:`MethodSpec` says what the rest of the package needs to know of a method: its
name, the function that computes a pair and the one that estimates its peak memory
(``"module:function"``, imported only when they are needed), the configuration it is
handed and, from that, what a stored pair's fingerprint covers, whether it runs the numba
kernels (and so the GPU), and the packages it needs.  The command line's ``--method``
choices, the check of ``run.method``, the dispatch of :func:`d3cli.batch.compute_pair`,
the memory check (:mod:`d3cli.batch.resources`), the warm-up, the ``--backend cuda``
check and the resume fingerprint (:mod:`d3cli.batch.fingerprint`) all read
:data:`METHOD_SPECS`; none of them names a method.

The declarations live here, on the configuration's floor, because ``run.method`` is
checked when a config is loaded, and loading a config imports neither numba nor OpenCV
(``d3cli.config`` may import :mod:`d3cli.errors` only): the code is named by its import
path, and :mod:`d3cli.batch.dispatch` imports it when a pair is computed.
"""

from __future__ import annotations

import importlib
import importlib.util
from dataclasses import dataclass

from ..errors import BackendUnavailable

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
    peak_bytes : str
        ``"module:function"`` of its memory model, called as ``function(shape,
        max_disparity, cfg)`` with the full :class:`~d3cli.config.Config`; it returns the
        estimated peak bytes of one pair (:func:`d3cli.batch.resources.check_memory`
        compares it with the limit before the pair is read).
    kernels : bool
        Whether it runs d3stereo's numba kernels: they are compiled (and warmed up) before
        its first pair, and with ``--backend cuda`` it runs on the GPU (the CUDA backend
        is checked before the batch starts); a method without them runs on the CPU
        whatever the backend, and says so once.
    falls_back : bool
        Whether a pair that is not a road scene is matched again with the settings of
        ``pt.fallback_config`` (:func:`d3cli.method.pipeline.fallback_settings`); the
        warm-up compiles those settings' kernels too.
    extra : str or None
        The pip extra whose packages it needs (``pip install "d3stereo[EXTRA]"``).
    requires : tuple of str
        Modules it imports that are not dependencies of d3stereo; checked before a batch
        starts (:meth:`require`).
    install : str or None
        The command that installs :attr:`requires`, for the message.
    averaging_px : callable or None
        ``function(cfg)`` of the full :class:`~d3cli.config.Config`: how far around a pixel
        the method's map averages, in pixels (half its matching window plus the radius of
        its final smoothing).  The road report flags a defect measured on the stored map
        that is narrower than that (``narrow``, :mod:`d3cli.road.confidence`); None: not
        known, no such flag.
    """

    name: str
    compute: str
    doc: str
    peak_bytes: str
    section: str | None = None
    pair_dir: bool = False
    kernels: bool = False
    falls_back: bool = False
    extra: str | None = None
    requires: tuple[str, ...] = ()
    install: str | None = None
    averaging_px: object = None

    def fingerprinted(self, sections) -> tuple[str, ...]:
        """The config sections, of ``sections`` (every section's name), that a stored
        pair's fingerprint covers: :attr:`section` alone, else all but
        :data:`NOT_READ_BY_MAP`."""
        if self.section is not None:
            return (self.section,)
        return tuple(name for name in sections if name not in NOT_READ_BY_MAP)

    def require(self) -> None:
        """Raise :class:`~d3cli.errors.BackendUnavailable` now when a module of
        :attr:`requires` is not installed: a batch checks this once up front instead of
        failing every pair the same way."""
        missing = [name for name in self.requires if importlib.util.find_spec(name) is None]
        if missing:
            raise BackendUnavailable(f"--method {self.name} needs the package(s) {', '.join(missing)}, "
                                     f"which are not installed; install them with {self.install}")

    def estimate_peak_bytes(self, shape, max_disparity: int, cfg) -> int:
        """Estimated peak bytes of one pair of ``shape`` (``(H, W)`` or ``(H, W, C)``)
        searched up to ``max_disparity`` with the configuration ``cfg``, from the
        method's memory model (:attr:`peak_bytes`)."""
        return int(_imported(self.peak_bytes)(shape, max_disparity, cfg))

    def averaging(self, cfg) -> float | None:
        """How far around a pixel this method's map averages with the configuration ``cfg``
        (:attr:`averaging_px`), pixels; None where the method does not say."""
        return None if self.averaging_px is None else self.averaging_px(cfg)

    def entry_point(self):
        """The function :attr:`compute` names, imported."""
        return _imported(self.compute)


def _imported(path: str):
    """The object ``"module:name"`` names, imported."""
    module, _, name = path.partition(":")
    return getattr(importlib.import_module(module), name)


#: The install commands of the optional peers (pyelas builds from source against numpy's headers).
INSTALL_ELAS = ("CFLAGS=-I$(python -c 'import numpy;print(numpy.get_include())') "
                "pip install --no-build-isolation pyelas")
INSTALL_PANDORA = 'pip install "pandora[sgm]"'


def _d3stereo_averaging(cfg) -> int:
    """d3stereo: half the NCC window plus the radius of the final smoothing."""
    return cfg.cost.window // 2 + cfg.refine.smooth_radius


def _sgbm_averaging(cfg) -> int:
    """SGBM (and PT-SGM): half its block."""
    return cfg.sgbm.block_size // 2


#: Every method, in the order ``--method`` lists them.
METHOD_SPECS = (
    MethodSpec("d3stereo", "d3cli.method.pipeline:d3stereo_disparity", pair_dir=True, kernels=True,
               falls_back=True, peak_bytes="d3cli.method.memory:d3stereo_peak_bytes", averaging_px=_d3stereo_averaging,
               doc="decisive disparity diffusion, the paper's method (d3cli.method)"),
    MethodSpec("sgbm", "d3cli.baselines.sgbm:sgbm_disparity", section="sgbm",
               peak_bytes="d3cli.baselines.sgbm:sgbm_peak_bytes", averaging_px=_sgbm_averaging,
               doc="OpenCV's semi-global block matching"),
    MethodSpec("pt-sgm", "d3cli.baselines.pt_sgm:pt_sgm_disparity", kernels=True,
               peak_bytes="d3cli.baselines.pt_sgm:pt_sgm_peak_bytes", averaging_px=_sgbm_averaging,
               doc="SGBM after PT-D3Stereo's perspective transformation"),
    MethodSpec("elas", "d3cli.baselines.peers:elas_disparity", section="peers", extra="peers",
               peak_bytes="d3cli.baselines.peers:elas_peak_bytes", requires=("elas",), install=INSTALL_ELAS,
               doc="ELAS through pyelas (extra \"peers\")"),
    MethodSpec("pandora-sgm", "d3cli.baselines.peers:pandora_sgm_disparity", section="peers", extra="peers",
               peak_bytes="d3cli.baselines.peers:pandora_sgm_peak_bytes",
               requires=("pandora", "pandora_plugin_libsgm"), install=INSTALL_PANDORA,
               doc="pandora census + SGM (extra \"peers\")"),
)

#: The method names, in :data:`METHOD_SPECS`'s order.
METHODS = tuple(spec.name for spec in METHOD_SPECS)


def method_spec(name: str) -> MethodSpec | None:
    """The :class:`MethodSpec` of the method ``name``, or None when there is none."""
    return next((spec for spec in METHOD_SPECS if spec.name == name), None)
