"""Configuration: YAML -> frozen dataclasses, with every default and every check here.

A configuration is built in three layers, later ones winning:

1. the defaults written in the dataclasses below,
2. a YAML file (``-c FILE``; ``configs/default.yaml`` documents every key),
3. ``--set section.key=value`` overrides (values parsed as YAML scalars).

Unknown sections or keys, wrong types and out-of-range values raise
:class:`~d3cli.errors.ConfigError` naming the file, the dotted key, what was expected
and the valid keys.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
import stat
import types
import typing
from dataclasses import dataclass, field, fields, replace
from typing import Any, Mapping

import yaml

from .errors import ConfigError

METHODS = ("d3stereo", "sgbm", "pt-sgm", "elas", "pandora-sgm")

#: Largest config or manifest file read (bytes): a YAML file bigger than this is a mistake.
MAX_YAML_BYTES = 1_000_000
#: Largest YAML document, counted in nodes after expanding every alias: a few hundred
#: bytes of nested aliases ("billion laughs") would otherwise expand to gigabytes.
MAX_YAML_NODES = 100_000
#: Deepest nesting of lists/mappings in a config or manifest (a config needs 3 levels;
#: thousands of "[" would otherwise end in a RecursionError traceback).
MAX_YAML_DEPTH = 100
#: Integers in a config are bounded: the kernels take 32-bit scalars.
MAX_CONFIG_INT = 2**31 - 1
#: How much of an offending value an error message quotes.
QUOTE_CHARS = 60
BACKENDS = ("auto", "cpu", "cuda")


@dataclass(frozen=True)
class RunConfig:
    """What to run: the method, the backend and the disparity range."""

    method: str = "d3stereo"
    backend: str = "auto"
    max_disparity: int | None = None  # None: from the dataset layout, else width // 4
    max_memory_gb: float | None = None  # refuse pairs whose estimated peak exceeds this; None: 75 % of RAM
    color_range: tuple[float, ...] = ()  # [min, max] px of disp_color.png for a whole batch; []: per-pair percentiles


@dataclass(frozen=True)
class PyramidConfig:
    """Image/cost pyramid and hierarchy (paper section III, Fig. 1)."""

    levels: int = 4  # k: number of scales; level 1 is full resolution
    ars: bool = True  # alternating inheritance/diffusion; False: DFM linear hierarchy (diffusion at level 1 only, no fresh seeds)
    band: bool = True  # levels below the coarsest search a band around the coarser level's map (issue 10)
    band_margin: int = 2  # the band: 2 d_coarse +- this many disparities, hull over a tile and its neighbours
    band_tile: int = 32  # tile size (pixels of the level); a tile searches the hull over itself and its 8 neighbours


@dataclass(frozen=True)
class CostConfig:
    """Matching cost (DESIGN step 2): NCC, or the cosine of deep features."""

    window: int = 5  # odd NCC window size at every level ...
    level_windows: tuple[int, ...] = ()  # ... unless given per level, finest first
    min_variance: float = 1e-2  # grey-level variance (0-255 scale) below which a window is flat
    kind: str = "ncc"  # ncc | features (the features section; levels without a feature map use NCC)


@dataclass(frozen=True)
class FeaturesConfig:
    """Deep-feature cost pyramid from an ONNX backbone (``cost.kind: features``)."""

    model: str | None = None  # ONNX file (run with onnxruntime, extra "features")
    outputs: tuple[str, ...] = ()  # output names, finest first; each one pyramid level (stride 2^level)
    channel_order: str = "rgb"  # order of the colour channels the model expects: rgb | bgr
    scale: float = 1.0 / 255.0  # pixel values (0-255) are multiplied by this ...
    mean: tuple[float, ...] = (0.485, 0.456, 0.406)  # ... then (x - mean) / std per channel (ImageNet)
    std: tuple[float, ...] = (0.229, 0.224, 0.225)
    # precomputed feature maps instead of the model: an .npz with left_0, right_0, left_1,
    # ... (level i: (H / 2^i, W / 2^i, C)); relative to the pair's folder when the caller
    # gives it (D3Stereo.compute(pair_dir=...)), else to the working directory
    npz: str | None = None


@dataclass(frozen=True)
class AggregationConfig:
    """Cost aggregation: recursive bilateral filtering, paper eq. 2-3."""

    rbf: bool = True  # False: one-pass plain bilateral filter of radius kappa_a (ablation)
    t_max: int = 4  # RBF passes of the 3x3 kernel
    sigma_space: float = 1.5  # sigma_1 in eq. 3, pixels
    sigma_color: float = 12.0  # sigma_2 in eq. 3, grey levels (0-255)
    kappa_a: int = 4  # radius of the plain bilateral filter used when rbf is False
    # sigma_1 of that plain filter; None: sigma_space * kappa_a, the 3x3 kernel of eq. 3
    # stretched to the (2 kappa_a + 1)^2 window (same receptive field as RBF, Fig. 4)
    bf_sigma_space: float | None = None
    # Issue 16: semi-global smoothing of the full-resolution aggregated cost: the mean of
    # four path costs (left, right, down, up) with penalties P1 (one-disparity step) and
    # P2 (larger jump) in cost units ((1 - NCC) / 2); sgm_p2 0: off (the paper's method)
    sgm_p1: float = 0.0
    sgm_p2: float = 0.0


@dataclass(frozen=True)
class SeedConfig:
    """Decisive seeds at the coarsest level (DESIGN step 4)."""

    pkrn_min: float = 2.0  # keep a WTA disparity when (c2 + eps) / (c1 + eps) >= this
    epsilon: float = 1e-3  # eps in the PKRN ratio
    lr_tolerance: int = 1  # max |d_left - d_right| for the left-right check
    pkrn_exclusion: int = 0  # 0: naive PKRN; r > 0: c2 ignores disparities within r of d*
    every_level: bool = True  # also add fresh seeds below the coarsest level where nothing was inherited (ars only)


@dataclass(frozen=True)
class DiffusionConfig:
    """Intra-scale decisive diffusion, paper eq. 5-6 and Algorithm 1."""

    tau: int = 1  # disparity search tolerance r in [-tau, tau]
    kappa_d: int = 1  # neighbourhood radius
    adversarial: bool = True  # decided pixels may switch to a better candidate (eq. 6)
    max_sweeps: int = 100000  # safeguard; diffusion normally stops when nothing changes
    max_gap: float = 0.05  # accepted states cost <= the pixel's least cost + this; -1: off (paper)


@dataclass(frozen=True)
class InheritanceConfig:
    """Inter-scale decisive inheritance, paper eq. 7-9 and Algorithm 2."""

    prc: bool = True  # patch reliability constraint; False: DFM-style PKRN test in the patch
    dfm_pkrn_min: float = 1.05  # PKRN threshold of the DFM-style test (prc False)
    # symmetric: {2dc-1, 2dc, 2dc+1} in the patch, {2dc-2, 2dc+2} outside, every pixel;
    # paper: eq. 6-7 read literally, the co-row partners of each pixel (two per pixel)
    candidates: str = "symmetric"


@dataclass(frozen=True)
class PTConfig:
    """Perspective transformation for road scenes (DESIGN step 6)."""

    enabled: bool = False
    margin: int = 8  # delta: full-resolution disparity margin around the road model
    slack: int = 2  # extra disparities added to the narrow range [0, 2 delta + slack]
    min_inlier_share: float = 0.5  # below this the scene is not road-like: full range
    inlier_threshold: float = 1.0  # |residual| in coarse-level pixels counted as inlier
    iterations: int = 10  # iteratively re-weighted least-squares rounds

    @property
    def narrow_range(self) -> int:
        """Largest disparity searched after the transformation: ``2 margin + slack``."""
        return 2 * self.margin + self.slack


@dataclass(frozen=True)
class RefineConfig:
    """Sub-pixel refinement and hole filling (DESIGN step 8)."""

    subpixel: bool = True  # parabola through C(d-1), C(d), C(d+1), clamped to +-0.5
    occlusion_check: bool = True  # uniqueness + left-border tests: estimates with no possible true match become holes
    # connected regions of decided pixels (neighbours within speckle_range px) with at most
    # speckle_size pixels become holes before filling (issue 16); 0: off
    speckle_size: int = 0
    speckle_range: float = 1.0
    fill: bool = True  # False: undecided pixels stay inf in disp.pfm
    fill_inside: bool = False  # non-occluded holes take the median of 4 directions, not the background side
    smooth_filled: bool = True  # 5x5 median over the filled pixels only
    smooth_radius: int = 0  # edge-preserving smoothing of the result, box radius in pixels; 0: off
    smooth_sigma: float = 1.0  # range sigma of that smoothing, disparity pixels (residual to the road model with PT)
    smooth_kernel: str = "gaussian"  # its range kernel: gaussian | box (mean of neighbours within smooth_sigma; faster)


@dataclass(frozen=True)
class SGBMConfig:
    """OpenCV StereoSGBM baseline (``--method sgbm`` / ``pt-sgm``)."""

    block_size: int = 5  # odd; P1 = 8 * block_size**2, P2 = 32 * block_size**2
    mode: str = "3way"  # sgbm | hh | 3way | hh4
    uniqueness_ratio: int = 10
    speckle_window: int = 100
    speckle_range: int = 2
    disp12_max_diff: int = 1
    fill: bool = True  # fill invalid pixels like d3stereo (row-wise, background side)


@dataclass(frozen=True)
class PeersConfig:
    """Optional peers for comparison tables (``--method elas`` / ``pandora-sgm``)."""

    fill: bool = True  # fill their holes row-wise (background side) like SGBM, for a dense comparison
    elas_preset: str = "middlebury"  # libelas preset: middlebury (indoor scenes) | robotics (KITTI-like)
    pandora_p1: float = 8.0  # SGM penalty for disparity changes of 1 (census costs)
    pandora_p2: float = 32.0  # SGM penalty for larger changes


@dataclass(frozen=True)
class CameraConfig:
    """Camera for point clouds when the pair has no calib.txt (``--pointcloud``)."""

    f: float | None = None  # focal length, pixels
    baseline: float | None = None  # metres
    cx: float | None = None  # principal point, pixels; None: image centre
    cy: float | None = None
    # Depth range of cloud.ply points, metres (issue 12 item 4: near-zero disparities gave
    # points at 1e33 m).  100 m: KITTI's useful range is about 80 m; road scenes are closer.
    min_depth_m: float = 0.0
    max_depth_m: float = 100.0


@dataclass(frozen=True)
class RoadConfig:
    """Road inspection outputs (``--road-report``): height above the road plane, defects."""

    report: bool = False  # write height.pfm, height_color.png, defects.json/.png per pair
    min_depth_mm: float = 10.0  # a pothole is deeper than this below the surrounding surface
    min_height_mm: float = 20.0  # a bump is higher than this above the surrounding surface
    min_area_m2: float = 0.005  # smallest defect, area on the road plane
    sigma_disparity: float = 0.25  # disparity noise assumed by the robust plane fit, pixels
    ring_px: int = 12  # width of the surrounding ring that gives a defect's reference height
    min_decided_share: float = 0.5  # below this decided share a defect is low confidence
    colour_range_mm: float = 50.0  # height_color.png saturates at +- this
    # Splitting joined potholes (d3cli.road.defects._split): a depth saddle this deep, or a
    # neck at most split_neck x the smaller lobe's inscribed radius, separates two defects
    # whose parts are each at least split_min_area_m2.
    split_prominence_mm: float = 6.0
    split_neck: float = 0.9
    split_min_area_m2: float = 0.01
    # A region with a smaller share of decided pixels is not reported (its depth is the hole
    # filling's extrapolation), unless the whole map is below min_decided_share.
    min_region_decided_share: float = 0.25


@dataclass(frozen=True)
class Config:
    """The whole resolved configuration of one run."""

    run: RunConfig = field(default_factory=RunConfig)
    pyramid: PyramidConfig = field(default_factory=PyramidConfig)
    cost: CostConfig = field(default_factory=CostConfig)
    features: FeaturesConfig = field(default_factory=FeaturesConfig)
    aggregation: AggregationConfig = field(default_factory=AggregationConfig)
    seeds: SeedConfig = field(default_factory=SeedConfig)
    diffusion: DiffusionConfig = field(default_factory=DiffusionConfig)
    inheritance: InheritanceConfig = field(default_factory=InheritanceConfig)
    pt: PTConfig = field(default_factory=PTConfig)
    refine: RefineConfig = field(default_factory=RefineConfig)
    sgbm: SGBMConfig = field(default_factory=SGBMConfig)
    peers: PeersConfig = field(default_factory=PeersConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    road: RoadConfig = field(default_factory=RoadConfig)

    def to_dict(self) -> dict:
        """Plain nested dict (tuples as lists), e.g. for run.json."""
        out = {}
        for f in fields(self):
            sec = dataclasses.asdict(getattr(self, f.name))
            out[f.name] = {k: list(v) if isinstance(v, tuple) else v for k, v in sec.items()}
        return out

    def level_window(self, level: int) -> int:
        """NCC window size at ``level`` (0 = full resolution)."""
        lw = self.cost.level_windows
        if lw:
            return lw[min(level, len(lw) - 1)]
        return self.cost.window


# ----------------------------------------------------------------------------- checks
# Range checks: (predicate, text of what is expected).  Keys absent here take any
# value of the right type.
_RANGES: dict[str, tuple[typing.Callable[[Any], bool], str]] = {
    "run.method": (lambda v: v in METHODS, "one of " + ", ".join(METHODS)),
    "run.backend": (lambda v: v in BACKENDS, "one of " + ", ".join(BACKENDS)),
    "run.max_disparity": (lambda v: v is None or v > 0, "a positive integer or null"),
    "run.max_memory_gb": (lambda v: v is None or v > 0, "a positive number (GB) or null"),
    "run.color_range": (lambda v: len(v) == 0 or (len(v) == 2 and 0 <= v[0] < v[1]),
                        "[] or [min, max] with 0 <= min < max (pixels)"),
    "pyramid.levels": (lambda v: 1 <= v <= 8, "an integer in [1, 8]"),
    "pyramid.band_margin": (lambda v: 2 <= v <= 64, "an integer in [2, 64]"),
    "pyramid.band_tile": (lambda v: 4 <= v <= 256, "an integer in [4, 256]"),
    "cost.window": (lambda v: v >= 1 and v % 2 == 1 and v <= 31, "an odd integer in [1, 31]"),
    "cost.level_windows": (
        lambda v: all(w >= 1 and w % 2 == 1 and w <= 31 for w in v),
        "a list of odd integers in [1, 31]",
    ),
    "cost.min_variance": (lambda v: v >= 0, "a number >= 0"),
    "cost.kind": (lambda v: v in ("ncc", "features"), "one of ncc, features"),
    "features.channel_order": (lambda v: v in ("rgb", "bgr"), "one of rgb, bgr"),
    "features.scale": (lambda v: v > 0, "a number > 0"),
    "features.mean": (lambda v: len(v) in (1, 3), "a list of 1 or 3 numbers"),
    "features.std": (lambda v: len(v) in (1, 3) and all(s > 0 for s in v), "a list of 1 or 3 numbers > 0"),
    "aggregation.t_max": (lambda v: 0 <= v <= 64, "an integer in [0, 64]"),
    "aggregation.sigma_space": (lambda v: v > 0, "a number > 0"),
    "aggregation.sigma_color": (lambda v: v > 0, "a number > 0"),
    "aggregation.kappa_a": (lambda v: 0 <= v <= 32, "an integer in [0, 32]"),
    "aggregation.bf_sigma_space": (lambda v: v is None or v > 0, "a number > 0 (pixels) or null"),
    "aggregation.sgm_p1": (lambda v: v >= 0, "a number >= 0"),
    "aggregation.sgm_p2": (lambda v: v >= 0, "a number >= 0 (0: off)"),
    "seeds.pkrn_min": (lambda v: v >= 1.0, "a number >= 1"),
    "seeds.epsilon": (lambda v: v >= 0, "a number >= 0"),
    "seeds.lr_tolerance": (lambda v: v >= 0, "an integer >= 0"),
    "seeds.pkrn_exclusion": (lambda v: v >= 0, "an integer >= 0"),
    "diffusion.tau": (lambda v: 0 <= v <= 16, "an integer in [0, 16]"),
    "diffusion.kappa_d": (lambda v: 1 <= v <= 8, "an integer in [1, 8]"),
    "diffusion.max_sweeps": (lambda v: v >= 1, "an integer >= 1"),
    "diffusion.max_gap": (lambda v: v >= 0 or v == -1, "a number >= 0, or -1 for off"),
    "inheritance.dfm_pkrn_min": (lambda v: v >= 1.0, "a number >= 1"),
    "inheritance.candidates": (lambda v: v in ("symmetric", "paper"), "one of symmetric, paper"),
    "pt.margin": (lambda v: 1 <= v <= 256, "an integer in [1, 256]"),
    "pt.slack": (lambda v: 0 <= v <= 64, "an integer in [0, 64]"),
    "pt.min_inlier_share": (lambda v: 0 <= v <= 1, "a number in [0, 1]"),
    "pt.inlier_threshold": (lambda v: v > 0, "a number > 0"),
    "pt.iterations": (lambda v: 1 <= v <= 100, "an integer in [1, 100]"),
    "refine.smooth_kernel": (lambda v: v in ("gaussian", "box"), "one of gaussian, box"),
    "refine.speckle_size": (lambda v: 0 <= v <= 100000, "an integer in [0, 100000]"),
    "refine.speckle_range": (lambda v: 0 < v <= 64, "a number in (0, 64]"),
    "refine.smooth_radius": (lambda v: 0 <= v <= 64, "an integer in [0, 64]"),
    "refine.smooth_sigma": (lambda v: v > 0, "a number > 0 (pixels)"),
    "camera.f": (lambda v: v is None or v > 0, "a positive number (pixels) or null"),
    "camera.baseline": (lambda v: v is None or v > 0, "a positive number (metres) or null"),
    "camera.min_depth_m": (lambda v: v >= 0, "a number >= 0 (metres)"),
    "camera.max_depth_m": (lambda v: v > 0, "a number > 0 (metres)"),
    "peers.elas_preset": (lambda v: v in ("middlebury", "robotics"), "one of middlebury, robotics"),
    "peers.pandora_p1": (lambda v: v >= 0, "a number >= 0"),
    "peers.pandora_p2": (lambda v: v >= 0, "a number >= 0"),
    "road.min_depth_mm": (lambda v: v > 0, "a number > 0 (mm)"),
    "road.min_height_mm": (lambda v: v > 0, "a number > 0 (mm)"),
    "road.min_area_m2": (lambda v: v >= 0, "a number >= 0 (m^2)"),
    "road.sigma_disparity": (lambda v: v > 0, "a number > 0 (pixels)"),
    "road.ring_px": (lambda v: 2 <= v <= 100, "an integer in [2, 100]"),
    "road.min_decided_share": (lambda v: 0 <= v <= 1, "a number in [0, 1]"),
    "road.colour_range_mm": (lambda v: v > 0, "a number > 0 (mm)"),
    "road.split_prominence_mm": (lambda v: v > 0, "a number > 0 (mm)"),
    "road.split_neck": (lambda v: 0 < v <= 1, "a number in (0, 1] (1: no split at necks)"),
    "road.split_min_area_m2": (lambda v: v >= 0, "a number >= 0 (m^2)"),
    "road.min_region_decided_share": (lambda v: 0 <= v <= 1, "a number in [0, 1]"),
    "sgbm.block_size": (lambda v: v >= 1 and v % 2 == 1 and v <= 31, "an odd integer in [1, 31]"),
    "sgbm.mode": (lambda v: v in ("sgbm", "hh", "3way", "hh4"), "one of sgbm, hh, 3way, hh4"),
    # 100 kills the process: OpenCV's 3-way SGBM divides by (100 - uniquenessRatio) (SIGFPE).
    "sgbm.uniqueness_ratio": (lambda v: 0 <= v <= 99, "an integer in [0, 99]"),
    "sgbm.speckle_window": (lambda v: v >= 0, "an integer >= 0"),
    "sgbm.speckle_range": (lambda v: v >= 0, "an integer >= 0"),
    "sgbm.disp12_max_diff": (lambda v: v >= -1, "an integer >= -1"),
}


def _type_name(tp) -> str:
    names = {int: "an integer", float: "a number", bool: "true or false", str: "a string"}
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        return _type_name(args[0]) + " or null"
    if origin is tuple:
        return "a list of " + _type_name(typing.get_args(tp)[0])[2:] + "s"
    return names.get(tp, str(tp))


def quote(value: Any, limit: int = QUOTE_CHARS) -> str:
    """``repr(value)`` cut to ``limit`` characters, for error messages.

    A long or deeply nested value is quoted by its start, so that an error about it stays
    one readable line (and cannot itself exhaust memory).
    """
    if isinstance(value, (list, tuple, dict, set)) and len(value) > limit:
        return f"<{type(value).__name__} of {len(value)} items>"
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _coerce(value: Any, tp, where: str, key: str):
    """Check ``value`` against the annotation ``tp``; return it in canonical form."""
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        inner = [a for a in args if a is not type(None)][0]
        return _coerce(value, inner, where, key)
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            _bad_type(value, tp, where, key)
        inner = typing.get_args(tp)[0]
        return tuple(_coerce(v, inner, where, key) for v in value)
    if tp is bool:
        if not isinstance(value, bool):
            _bad_type(value, tp, where, key)
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            if isinstance(value, float) and value.is_integer():
                value = int(value)
            else:
                _bad_type(value, tp, where, key)
        if abs(value) > MAX_CONFIG_INT:
            raise ConfigError(
                f"{where}: {key} must be an integer of at most {MAX_CONFIG_INT} in size, got {quote(value)}; "
                f"fix the value of {key} (see configs/default.yaml)"
            )
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            _bad_type(value, tp, where, key)
        if not math.isfinite(float(value)):
            _bad_type(value, tp, where, key)
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            _bad_type(value, tp, where, key)
        return value
    raise TypeError(f"unsupported config annotation {tp!r}")  # programming error


def _bad_type(value, tp, where, key):
    raise ConfigError(
        f"{where}: {key} must be {_type_name(tp)}, got {quote(value)}; "
        f"fix the value of {key} (see configs/default.yaml)"
    )


_HINTS_CACHE: dict[type, dict] = {}


def _hints(cls) -> dict:
    if cls not in _HINTS_CACHE:
        _HINTS_CACHE[cls] = typing.get_type_hints(cls)
    return _HINTS_CACHE[cls]


def _section_classes() -> dict[str, type]:
    hints = _hints(Config)
    return {f.name: hints[f.name] for f in fields(Config)}


def _at(where: str, lines: Mapping | None, *keys) -> str:
    """``where:line`` when the line of the (section, key) path is known, else ``where``."""
    line = (lines or {}).get(tuple(keys))
    return f"{where}:{line}" if line is not None else where


def _apply(cfg: Config, data: Mapping, where: str, lines: Mapping | None = None) -> Config:
    """Return ``cfg`` updated with the nested mapping ``data`` (all checks applied).

    ``lines`` maps ``()``, ``(section,)`` and ``(section, key)`` to 1-based line numbers
    of the YAML file (see :func:`read_yaml_lines`), so messages can name the line.
    """
    if data is None:
        return cfg
    if not isinstance(data, Mapping):
        raise ConfigError(
            f"{_at(where, lines)}: the top level must be a mapping of sections, got {type(data).__name__}; "
            f"valid sections: {', '.join(_section_classes())}"
        )
    sections = _section_classes()
    new_sections = {}
    for sec_name, sec_data in data.items():
        if sec_name not in sections:
            raise ConfigError(
                f"{_at(where, lines, sec_name)}: unknown section {quote(sec_name)}; valid sections: {', '.join(sections)}"
            )
        if sec_data is None:
            continue
        sec_cls = sections[sec_name]
        if not isinstance(sec_data, Mapping):
            raise ConfigError(
                f"{_at(where, lines, sec_name)}: section {sec_name} must be a mapping of keys, got {quote(sec_data)}; "
                f"valid keys: {', '.join(f.name for f in fields(sec_cls))}"
            )
        hints = _hints(sec_cls)
        changes = {}
        for key, value in sec_data.items():
            dotted = f"{sec_name}.{key}"
            at = _at(where, lines, sec_name, key)
            if key not in hints:
                raise ConfigError(
                    f"{at}: unknown key {quote(dotted)}; valid keys of {sec_name}: "
                    f"{', '.join(f.name for f in fields(sec_cls))}"
                )
            value = _coerce(value, hints[key], at, dotted)
            check = _RANGES.get(dotted)
            if check is not None and not check[0](value):
                raise ConfigError(
                    f"{at}: {dotted} must be {check[1]}, got {quote(value)}; "
                    f"fix the value of {dotted}"
                )
            changes[key] = value
        new_sections[sec_name] = replace(new_sections.get(sec_name, getattr(cfg, sec_name)), **changes)
    return replace(cfg, **new_sections)


class _UniqueKeyLoader(yaml.SafeLoader):
    """SafeLoader that rejects duplicate and non-scalar keys (a silent override or an
    unhashable key is a user error) and reads YAML 1.2 numbers such as ``1e-3``.

    PyYAML implements YAML 1.1, where a float needs a dot (``1.0e-3``): ``1e-3`` would
    be the string "1e-3" and fail as "must be a number".
    """


_UniqueKeyLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$"),
    list("-+0123456789."),
)


def _construct_mapping(loader, node, deep=False):
    seen = {}
    for key_node, _ in node.value:
        if not isinstance(key_node, yaml.ScalarNode):
            kind = "list" if isinstance(key_node, yaml.SequenceNode) else "mapping"
            raise ConfigError(
                f"{loader.name}:{key_node.start_mark.line + 1}: a {kind} used as a key; "
                "keys must be plain names (e.g. tau:)"
            )
        key = loader.construct_object(key_node, deep=deep)
        if key in seen:
            raise ConfigError(
                f"{loader.name}:{key_node.start_mark.line + 1}: duplicate key {quote(key)} "
                f"(first at line {seen[key]}); keep only one"
            )
        seen[key] = key_node.start_mark.line + 1
    return yaml.SafeLoader.construct_mapping(loader, node, deep=deep)


_UniqueKeyLoader.add_constructor(
    yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping
)


def read_yaml(path: str | os.PathLike) -> Any:
    """Parse a YAML file, raising ConfigError with file and line on any problem."""
    return read_yaml_lines(path)[0]


def _key_lines(node, loader) -> dict[tuple, int]:
    """1-based lines of the top two levels of mapping keys of a composed YAML node."""
    lines: dict[tuple, int] = {(): node.start_mark.line + 1}
    if not isinstance(node, yaml.MappingNode):
        return lines
    for key_node, value_node in node.value:
        if not isinstance(key_node, yaml.ScalarNode):
            continue
        section = loader.construct_object(key_node)
        lines[(section,)] = key_node.start_mark.line + 1
        if isinstance(value_node, yaml.MappingNode):
            for sub_key, _ in value_node.value:
                if isinstance(sub_key, yaml.ScalarNode):
                    lines[(section, loader.construct_object(sub_key))] = sub_key.start_mark.line + 1
    return lines


def read_yaml_lines(path: str | os.PathLike) -> tuple[Any, dict[tuple, int]]:
    """Parse a YAML file; return the data and the line of every section and key.

    Returns
    -------
    data : Any
        The parsed document (None for an empty file).
    lines : dict
        ``()`` -> line of the document, ``(section,)`` and ``(section, key)`` -> the
        1-based line where that key is written.

    Raises
    ------
    ConfigError
        Missing or unreadable file, not UTF-8, invalid YAML or duplicate keys, naming the
        file and the line.
    """
    path = os.fspath(path)
    raw = read_bounded(path, what="config file", missing_fix="check the path given to -c", error=ConfigError)
    return parse_yaml(raw, path, what="config file", error=ConfigError)


def read_bounded(path: str, *, what: str, missing_fix: str, error: type = ConfigError) -> bytes:
    """The bytes of a small regular file, refusing FIFOs, devices and huge files.

    ``-c`` on a FIFO would block forever and ``-c /dev/zero`` would read without end:
    only regular files of at most :data:`MAX_YAML_BYTES` are read.
    """
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise error(f"{path}: {what} not found; {missing_fix}") from None
    except OSError as exc:
        raise error(f"{path}: cannot read {what} ({exc.strerror or exc}); give a readable UTF-8 YAML file") from None
    if not stat.S_ISREG(info.st_mode):
        kind = "a folder" if stat.S_ISDIR(info.st_mode) else "not a regular file (a FIFO, socket or device)"
        raise error(f"{path}: cannot read {what}: {kind}; give a YAML file")
    if info.st_size > MAX_YAML_BYTES:
        raise error(
            f"{path}: {what} of {info.st_size} bytes is larger than {MAX_YAML_BYTES} bytes; "
            "give the YAML file itself (is this the right file?)"
        )
    try:
        with open(path, "rb") as fh:
            return fh.read(MAX_YAML_BYTES + 1)
    except OSError as exc:
        raise error(f"{path}: cannot read {what} ({exc.strerror or exc}); give a readable UTF-8 YAML file") from None


def _expanded_nodes(node, seen: dict, stack: set, name: str, error: type) -> int:
    """Number of nodes of ``node`` with every alias expanded (memoised, cycle-checked,
    at most :data:`MAX_YAML_DEPTH` levels deep)."""
    key = id(node)
    if key in seen:
        return seen[key]
    if key in stack:
        raise error(f"{name}:{node.start_mark.line + 1}: a recursive YAML alias; write the value out instead")
    if len(stack) >= MAX_YAML_DEPTH:
        raise _too_deep(name, error, node.start_mark.line + 1)
    stack.add(key)
    if isinstance(node, yaml.SequenceNode):
        children = node.value
    elif isinstance(node, yaml.MappingNode):
        children = [n for pair in node.value for n in pair]
    else:
        children = []
    total = 1
    for child in children:
        total += _expanded_nodes(child, seen, stack, name, error)
        if total > MAX_YAML_NODES:
            break
    stack.discard(key)
    seen[key] = total
    return total


def _too_deep(name: str, error: type, line: int | None = None):
    where = f"{name}:{line}" if line is not None else name
    return error(f"{where}: YAML nested more than {MAX_YAML_DEPTH} levels deep; "
                 "write a flat config or manifest (a config needs 3 levels)")


def parse_yaml(raw: bytes, path: str, *, what: str = "config file", error: type = ConfigError):
    """Parse YAML bytes safely; return ``(data, lines)`` as :func:`read_yaml_lines` does.

    Refuses non-UTF-8 text, NUL bytes, invalid YAML, duplicate or non-scalar keys,
    recursive aliases and documents that expand beyond :data:`MAX_YAML_NODES` nodes,
    each with ``error`` naming the file and the line.
    """
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        raise error(
            f"{path}:{line}: cannot read {what} (not UTF-8 text: byte 0x{raw[exc.start]:02x} at offset "
            f"{exc.start}; is it a YAML file?); give a readable UTF-8 YAML file"
        ) from None
    if "\x00" in text:
        line = text.count("\n", 0, text.index("\x00")) + 1
        raise error(
            f"{path}:{line}: cannot read {what} (a NUL byte: binary data, not YAML); "
            "give a readable UTF-8 YAML file"
        )
    try:
        loader = _UniqueKeyLoader(text)
        loader.name = path
        try:
            node = loader.get_single_node()
            if node is None:
                return None, {}
            if _expanded_nodes(node, {}, set(), path, error) > MAX_YAML_NODES:
                raise error(
                    f"{path}: YAML aliases expand to more than {MAX_YAML_NODES} values (an alias bomb?); "
                    "write the values out instead of nesting aliases"
                )
            data = loader.construct_document(node)
            lines = _key_lines(node, loader)
        finally:
            loader.dispose()
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = f":{mark.line + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise error(f"{path}{line}: not valid YAML ({problem}); fix the syntax") from None
    except ConfigError as exc:  # the loader's key checks raise ConfigError
        if isinstance(exc, error):
            raise
        raise error(str(exc)) from None
    except RecursionError:  # PyYAML's composer recurses once per level, before our depth check
        raise _too_deep(path, error) from None
    return data, lines


def parse_override(text: str) -> tuple[str, str, Any]:
    """Split ``section.key=value`` into (section, key, YAML-parsed value)."""
    if "=" not in text or "." not in text.split("=", 1)[0]:
        raise ConfigError(
            f"--set {text}: expected section.key=value (e.g. diffusion.tau=2); fix the option"
        )
    dotted, raw = text.split("=", 1)
    section, key = dotted.strip().split(".", 1)
    try:
        value = yaml.load(raw, Loader=_UniqueKeyLoader) if raw.strip() else None
    except yaml.YAMLError:
        value = raw
    except RecursionError:
        raise _too_deep(f"--set {text[:60]}", ConfigError) from None
    return section, key, value


def load_config(path: str | os.PathLike | None = None, overrides: typing.Iterable[str] = ()) -> Config:
    """Build a :class:`Config` from defaults, an optional YAML file and overrides.

    Parameters
    ----------
    path : path-like or None
        YAML file with sections as in ``configs/default.yaml``.
    overrides : iterable of str
        ``section.key=value`` strings applied after the file.

    Returns
    -------
    Config
        The frozen, validated configuration.

    Raises
    ------
    ConfigError
        Unknown sections/keys, wrong types, out-of-range values, bad YAML.
    """
    cfg = Config()
    overrides = list(overrides)
    if path is not None:
        data, lines = read_yaml_lines(path)
        cfg = _apply(cfg, data, os.fspath(path), lines)
    for text in overrides:
        section, key, value = parse_override(text)
        cfg = _apply(cfg, {section: {key: value}}, f"--set {text}")
    where = " and ".join(filter(None, [os.fspath(path) if path is not None else "", "--set" if overrides else ""]))
    _check_depth_range(cfg, where or "defaults")
    return cfg


def _check_depth_range(cfg: Config, where: str) -> None:
    """camera.min_depth_m < camera.max_depth_m, checked once all values are in (file and --set)."""
    cam = cfg.camera
    if cam.min_depth_m >= cam.max_depth_m:
        raise ConfigError(
            f"{where}: camera.min_depth_m ({cam.min_depth_m:g}) must be smaller than camera.max_depth_m "
            f"({cam.max_depth_m:g}); fix the depth range of the point clouds"
        )


def config_from_dict(data: Mapping | None, where: str = "<dict>") -> Config:
    """Build a validated :class:`Config` from a nested mapping (e.g. run.json)."""
    cfg = _apply(Config(), data or {}, where)
    _check_depth_range(cfg, where)
    return cfg
