"""The configuration's sections: one frozen dataclass per YAML section, every key a :func:`setting`.

Each key is declared once, with its default, its one-line meaning (``doc``: the comment of
its line in ``configs/default.yaml``, and its row of docs/configuration.md) and, where
its type alone does not bound it, its range check (``check``, ``expected``: the text of
the error message and of the reference).  :mod:`d3cli.config.checks` applies the checks;
:mod:`d3cli.config.load` builds a :class:`Config` from a file and ``--set``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field, fields
from typing import Any, Callable

from .bundled import bundled_configs
from .methods import METHODS


def setting(default: Any, doc: str, check: Callable[[Any], bool] | None = None, expected: str = ""):
    """A config key: a dataclass field with its ``default``, its one-line meaning ``doc``
    and, optionally, the range ``check`` of a value of the right type with the text of
    what it accepts, ``expected`` (``"an integer in [1, 8]"``), both in ``metadata``.

    Parameters
    ----------
    default : Any
        The default value (immutable: a tuple for a list).
    doc : str
        One line: what the key does (the comment of its line in ``configs/default.yaml``).
    check : callable, optional
        Predicate a value, already of the annotated type, must pass.
    expected : str, optional
        What ``check`` accepts, as error messages and the reference say it.

    Returns
    -------
    dataclasses.Field
    """
    return field(default=default, metadata={"doc": doc, "check": check, "expected": expected})


def _bundled_names() -> list[str]:
    """Names of the bundled configs."""
    return list(bundled_configs())


BACKENDS = ("auto", "cpu", "cuda")
#: What ``run.outputs`` (``--outputs``) may name, comma-separated: ``all`` (every file), ``survey``
#: (only the files every run writes: disp.pfm, valid.png, result.json, and defects.json with
#: the road report) and the groups added to it: ``kitti`` (disp.png), ``pictures`` (every
#: PNG picture of the pair) and ``height`` (height.pfm of the road report).
OUTPUT_GROUPS = ("kitti", "pictures", "height")
OUTPUT_CHOICES = ("all", "survey", *OUTPUT_GROUPS)


def output_groups(text: str) -> frozenset[str] | None:
    """The optional file groups (:data:`OUTPUT_GROUPS`) that ``run.outputs`` asks for, or
    None when ``text`` is not a comma-separated list of :data:`OUTPUT_CHOICES`."""
    words = [word.strip() for word in str(text).split(",")]
    if not words or any(word not in OUTPUT_CHOICES for word in words):
        return None
    return frozenset(OUTPUT_GROUPS) if "all" in words else frozenset(w for w in words if w in OUTPUT_GROUPS)


@dataclass(frozen=True)
class RunConfig:
    """What to run: the method, the backend and the disparity range."""

    method: str = setting(
        "d3stereo",
        'stereo method: d3stereo | sgbm | pt-sgm | elas | pandora-sgm (the last two: extra "peers")',
        lambda v: v in METHODS, "one of " + ", ".join(METHODS))
    backend: str = setting(
        "auto",
        "compute backend: auto (CUDA when usable, else CPU) | cpu | cuda",
        lambda v: v in BACKENDS, "one of " + ", ".join(BACKENDS))
    max_disparity: int | None = setting(
        None,
        "largest disparity in pixels; null: from the dataset layout, else width // 4",
        lambda v: v is None or v > 0, "a positive integer or null")
    max_memory_gb: float | None = setting(
        None,
        "refuse a pair whose estimated peak memory exceeds this (GB); null: 75 % of RAM",
        lambda v: v is None or v > 0, "a positive number (GB) or null")
    color_range: tuple[float, ...] = setting(
        (),
        "[min, max] disparity (px) of disp_color.png for every pair; []: each pair's 1st-99th percentile",
        lambda v: len(v) == 0 or (len(v) == 2 and 0 <= v[0] < v[1]), "[] or [min, max] with 0 <= min < max (pixels)")
    outputs: str = setting(
        "all",
        "per-pair files: all, or survey (disp.pfm, valid.png, result.json, defects.json) plus any of kitti, pictures, height",
        lambda v: output_groups(v) is not None, "a comma-separated list of " + ", ".join(OUTPUT_CHOICES) + " (e.g. survey,pictures)")


@dataclass(frozen=True)
class PyramidConfig:
    """Image/cost pyramid and hierarchy (paper section III, Fig. 1)."""

    levels: int = setting(
        4,
        "k: number of scales; level 1 is full resolution",
        lambda v: 1 <= v <= 8, "an integer in [1, 8]")
    ars: bool = setting(
        True,
        "alternating inheritance/diffusion; false: DFM linear hierarchy (seeds at the coarsest level only, diffusion at the finest only)")
    band: bool = setting(
        True,
        "finer levels search only a band around the coarser level's disparities (false: full range, as the paper)")
    band_margin: int = setting(
        2,
        "that band: 2 d_coarse +- margin, hull over a tile and its 8 neighbour tiles; full range where the coarser level left nothing",
        lambda v: 2 <= v <= 64, "an integer in [2, 64]")
    band_tile: int = setting(
        32,
        "tile size in pixels of the level (Middlebury EPE, margin 2: tile 16 1.593, 32 1.566, 64 1.547; full range 1.583)",
        lambda v: 4 <= v <= 256, "an integer in [4, 256]")
    # The tile at full resolution (level 1); None: band_tile.  16 by default: on the 22
    # Middlebury pairs the same maps to 0.01 EPE as 32 (EPE / PEP0.5 / PEP1 / PEP2 1.351 /
    # 20.09 / 12.53 / 8.89 against 1.350 / 20.09 / 12.51 / 8.85; 8: EPE 1.386) in about
    # 7 % less time on Middlebury-Q (the finest level's bands are its NCC, smoothing,
    # inheritance and diffusion cells); tiles of 16 at every level lose (1.395: a coarse
    # band too narrow is not made good below).  kitti.yaml takes 24.  docs/performance.md
    finest_band_tile: int | None = setting(
        16,
        "the tile at full resolution; null: band_tile (Middlebury the same to 0.01 EPE as 32, about 7 % faster; docs/performance.md)",
        lambda v: v is None or 4 <= v <= 256, "an integer in [4, 256] or null")


@dataclass(frozen=True)
class CostConfig:
    """Matching cost (docs/design.md, 'Cost volumes'): NCC, or the cosine of deep features."""

    window: int = setting(
        5,
        "odd NCC window size, used at every level unless level_windows is given",
        lambda v: v >= 1 and v % 2 == 1 and v <= 31, "an odd integer in [1, 31]")
    level_windows: tuple[int, ...] = setting(
        (),
        "odd NCC window per level, finest first; [] uses window everywhere",
        lambda v: all(w >= 1 and w % 2 == 1 and w <= 31 for w in v), "a list of odd integers in [1, 31]")
    min_variance: float = setting(
        1e-2,
        "grey-level variance (0-255 scale) below which a window is flat (cost 1)",
        lambda v: v >= 0, "a number >= 0")
    kind: str = setting(
        "ncc",
        "ncc | features: cosine of deep features (section features; levels without a map use NCC)",
        lambda v: v in ("ncc", "features"), "one of ncc, features")


@dataclass(frozen=True)
class FeaturesConfig:
    """Deep-feature cost pyramid from an ONNX backbone (``cost.kind: features``)."""

    model: str | None = setting(
        None,
        "ONNX file of the backbone (scripts/export_backbone.py writes VGG16/ResNet/MobileNetV3 taps)")
    outputs: tuple[str, ...] = setting((), "output names, finest first; a map of stride 2^i is pyramid level i")
    channel_order: str = setting(
        "rgb",
        "colour order the model expects: rgb | bgr",
        lambda v: v in ("rgb", "bgr"), "one of rgb, bgr")
    scale: float = setting(
        1.0 / 255.0,
        "pixel values (0-255) times this (1/255) ...",
        lambda v: v > 0, "a number > 0")
    mean: tuple[float, ...] = setting(
        (0.485, 0.456, 0.406),
        "... minus mean, divided by std, per channel (ImageNet defaults)",
        lambda v: len(v) in (1, 3), "a list of 1 or 3 numbers")
    std: tuple[float, ...] = setting(
        (0.229, 0.224, 0.225),
        "... the divisor per channel after the mean (ImageNet defaults)",
        lambda v: len(v) in (1, 3) and all(s > 0 for s in v), "a list of 1 or 3 numbers > 0")
    # precomputed feature maps instead of the model: an .npz with left_0, right_0, left_1,
    # ... (level i: (H / 2^i, W / 2^i, C)); relative to the pair's folder when the caller
    # gives it (D3Stereo.compute(pair_dir=...)), else to the working directory
    npz: str | None = setting(
        None,
        "precomputed maps instead of the model: .npz with left_0, right_0, left_1, ... ((H/2^i, W/2^i, C) per level i)")


@dataclass(frozen=True)
class AggregationConfig:
    """Cost aggregation: recursive bilateral filtering, paper eq. 2-3."""

    rbf: bool = setting(True, "recursive bilateral filtering (eq. 2-3); false: one-pass plain bilateral filter")
    t_max: int = setting(
        4,
        "RBF passes of the 3x3 kernel below full resolution",
        lambda v: 0 <= v <= 64, "an integer in [0, 64]")
    # RBF passes at full resolution (level 1); None: t_max.  0 by default: there the
    # semi-global smoothing of the cost (below) follows, and the raw NCC under it measures
    # better than 4 passes on the Middlebury and KITTI pairs (EPE and PEP1) at a third less
    # time per pair (the filter and its weights take a quarter of it); below full
    # resolution, where no smoothing runs, the filter keeps the coarse maps and with them
    # the bands narrow (0 there too doubles the decisions' and the diffusion's time).
    # docs/performance.md, 'Default settings'; paper.yaml: None (the paper's RBF everywhere)
    finest_t_max: int | None = setting(
        0,
        "RBF passes at full resolution, where the semi-global smoothing follows; null: t_max (measured: docs/performance.md)",
        lambda v: v is None or 0 <= v <= 64, "an integer in [0, 64] or null")
    # RBF passes per level, finest first (the last value for every coarser level); () uses
    # finest_t_max and t_max.  No shipped config sets it: (0, 4, 0) for road.yaml keeps the
    # maps and saves 1-4 % of the time but doubles the road check's false defects (docs/road.md)
    level_t_max: tuple[int, ...] = setting(
        (),
        "RBF passes per level, finest first (the last one for every coarser level); [] uses the two above",
        lambda v: all(0 <= t <= 64 for t in v), "a list of integers in [0, 64]")
    sigma_space: float = setting(1.5, "sigma_1 of eq. 3, pixels", lambda v: v > 0, "a number > 0")
    sigma_color: float = setting(12.0, "sigma_2 of eq. 3, grey levels (0-255)", lambda v: v > 0, "a number > 0")
    kappa_a: int = setting(
        4,
        "radius of the plain bilateral filter used when rbf is false",
        lambda v: 0 <= v <= 32, "an integer in [0, 32]")
    # sigma_1 of that plain filter; None: sigma_space * kappa_a, the 3x3 kernel of eq. 3
    # stretched to the (2 kappa_a + 1)^2 window (same receptive field as RBF, Fig. 4)
    bf_sigma_space: float | None = setting(
        None,
        "sigma_1 of that plain filter; null: sigma_space * kappa_a (3x3 kernel stretched to the same receptive field as RBF)",
        lambda v: v is None or v > 0, "a number > 0 (pixels) or null")
    # Semi-global smoothing of the full-resolution aggregated cost (docs/design.md,
    # 'Semi-global smoothing'): the mean of four path costs (left, down, right, up) with
    # penalties P1 (one-disparity step) and P2 (larger jump) in cost units
    # ((1 - NCC) / 2); sgm_p2 0: off (the paper's method, configs/paper.yaml).  On
    # by default: with finest_t_max 0, P1 0.1 / P2 1.2 chosen on the Middlebury pairs and
    # checked leave-one-out (docs/performance.md, 'Default settings');
    # configs/kitti.yaml uses 0.6 / 1.2
    sgm_p1: float = setting(
        0.1,
        "semi-global smoothing of the full-resolution cost (mean of 4 path costs), one-step penalty",
        lambda v: v >= 0, "a number >= 0")
    sgm_p2: float = setting(
        1.2,
        "its jump penalty (cost units, (1 - NCC) / 2); 0: off (the paper's method). Chosen on Middlebury, checked leave-one-out (docs/performance.md)",
        lambda v: v >= 0, "a number >= 0 (0: off)")


@dataclass(frozen=True)
class SeedConfig:
    """Decisive seeds at the coarsest level (docs/design.md, 'Decisive seeds')."""

    pkrn_min: float = setting(
        2.0,
        "keep a WTA disparity when (c2 + eps) / (c1 + eps) >= this (tuned: scripts/tune.py)",
        lambda v: v >= 1.0, "a number >= 1")
    epsilon: float = setting(1e-3, "eps of the PKRN ratio", lambda v: v >= 0, "a number >= 0")
    lr_tolerance: int = setting(
        1,
        "largest |d_left - d_right| passing the left-right check",
        lambda v: v >= 0, "an integer >= 0")
    pkrn_exclusion: int = setting(
        0,
        "0: naive PKRN; r > 0: c2 ignores disparities within r of the winner",
        lambda v: v >= 0, "an integer >= 0")
    every_level: bool = setting(
        True,
        "also add fresh seeds below the coarsest level where nothing was inherited (addition, tuned; only with ars: true)")


@dataclass(frozen=True)
class DiffusionConfig:
    """Intra-scale decisive diffusion, paper eq. 4-5 and Algorithm 1."""

    tau: int = setting(
        1,
        "candidate tolerance r in [-tau, tau] (eq. 4)",
        lambda v: 0 <= v <= 16, "an integer in [0, 16]")
    kappa_d: int = setting(1, "neighbourhood radius of the frontier", lambda v: 1 <= v <= 8, "an integer in [1, 8]")
    adversarial: bool = setting(True, "decided pixels may switch to a better candidate (eq. 5)")
    max_sweeps: int = setting(
        100000,
        "safeguard; diffusion normally stops when a sweep changes nothing",
        lambda v: v >= 1, "an integer >= 1")
    max_gap: float = setting(
        0.0,
        "accepted states cost at most the pixel's least cost + this (0: only a pixel's least-cost state); -1: off (as in the paper; addition, chosen leave-one-out)",
        lambda v: v >= 0 or v == -1, "a number >= 0, or -1 for off")


@dataclass(frozen=True)
class InheritanceConfig:
    """Inter-scale decisive inheritance, paper eq. 6-8 and Algorithm 2."""

    prc: bool = setting(True, "patch reliability constraint (eq. 6-8); false: DFM-style PKRN test in the patch")
    dfm_pkrn_min: float = setting(
        1.05,
        "PKRN threshold of the DFM-style test (used when prc is false)",
        lambda v: v >= 1.0, "a number >= 1")
    # symmetric: {2dc-1, 2dc, 2dc+1} in the patch, {2dc-2, 2dc+2} outside, every pixel;
    # paper: eq. 6-7 read literally, the co-row partners of each pixel (two per pixel)
    candidates: str = setting(
        "symmetric",
        "symmetric: {2dc-1, 2dc, 2dc+1} in the patch, {2dc+-2} outside | paper: eq. 6-7 literally (two co-row partners per pixel)",
        lambda v: v in ("symmetric", "paper"), "one of symmetric, paper")


@dataclass(frozen=True)
class PTConfig:
    """Perspective transformation for road scenes (docs/design.md, 'Perspective transformation')."""

    enabled: bool = setting(False, "perspective transformation for road scenes (DESIGN step 6)")
    margin: int = setting(
        8,
        "delta: full-resolution disparity margin around the road model, pixels",
        lambda v: 1 <= v <= 256, "an integer in [1, 256]")
    slack: int = setting(
        2,
        "extra disparities added to the narrow range [0, 2 * margin + slack]",
        lambda v: 0 <= v <= 64, "an integer in [0, 64]")
    min_inlier_share: float = setting(
        0.5,
        "below this share of inliers the scene is not road-like: full range search",
        lambda v: 0 <= v <= 1, "a number in [0, 1]")
    inlier_threshold: float = setting(
        1.0,
        "|residual| in coarse-level pixels counted as an inlier",
        lambda v: v > 0, "a number > 0")
    iterations: int = setting(
        10,
        "iteratively re-weighted least-squares rounds of the road fit",
        lambda v: 1 <= v <= 100, "an integer in [1, 100]")
    max_band_end_share: float = setting(
        0.03,
        "above this share of pixels at the narrow range's ends (half: plane refitted to the band first): not a road, full range",
        lambda v: 0 <= v <= 1, "a number in [0, 1]")
    fallback_config: str = setting(
        "",
        'bundled config (e.g. default) whose settings match a pair that is not a road; "": this config\'s',
        lambda v: v == "" or v in _bundled_names(), "\"\" or the name of a bundled config")

    @property
    def narrow_range(self) -> int:
        """Largest disparity searched after the transformation: ``2 margin + slack``."""
        return 2 * self.margin + self.slack


@dataclass(frozen=True)
class RefineConfig:
    """Sub-pixel refinement and hole filling (docs/design.md, 'Finishing')."""

    subpixel: bool = setting(True, "sub-pixel fit through C(d-1), C(d), C(d+1), offset clamped to +-0.5")
    # the fit: parabola (the paper's) | equiangular (two lines of equal slope: a V-shaped
    # minimum) | auto: equiangular on the semi-global smoothing's cost, else parabola
    subpixel_fit: str = setting(
        "auto",
        "parabola (the paper's) | equiangular (two lines of equal slope) | auto: equiangular after the semi-global smoothing (its V-shaped minimum), else parabola",
        lambda v: v in ("auto", "parabola", "equiangular"), "one of auto, parabola, equiangular")
    occlusion_check: bool = setting(
        True,
        "uniqueness + left-border test: estimates without a possible true match become holes (addition, measured)")
    # connected regions of decided pixels (neighbours within speckle_range px) with at most
    # speckle_size pixels become holes before filling; 0: off
    speckle_size: int = setting(
        0,
        "decided regions (4-connected, neighbours within speckle_range) of at most this many pixels become holes; 0: off",
        lambda v: 0 <= v <= 100000, "an integer in [0, 100000]")
    speckle_range: float = setting(
        1.0,
        "largest disparity step (px) between neighbours of one region",
        lambda v: 0 < v <= 64, "a number in (0, 64]")
    fill: bool = setting(True, "fill undecided pixels row-wise (background side); false: they stay inf")
    fill_inside: bool = setting(
        False,
        "non-occluded holes take the median of the nearest valid values in 4 directions")
    smooth_filled: bool = setting(True, "5x5 median over the filled pixels only")
    smooth_radius: int = setting(
        3,
        "edge-preserving smoothing of the final map: box radius (pixels); 0: off (chosen leave-one-out, docs/results.md)",
        lambda v: 0 <= v <= 64, "an integer in [0, 64]")
    smooth_sigma: float = setting(
        2.0,
        "its range sigma in disparity pixels (on the residual to the road model when PT is on)",
        lambda v: v > 0, "a number > 0 (pixels)")
    smooth_kernel: str = setting(
        "box",
        "its range kernel: gaussian | box (plain mean of the neighbours within smooth_sigma: a tenth of the Gaussian's time)",
        lambda v: v in ("gaussian", "box"), "one of gaussian, box")


@dataclass(frozen=True)
class SGBMConfig:
    """OpenCV StereoSGBM baseline (``--method sgbm`` / ``pt-sgm``)."""

    block_size: int = setting(
        5,
        "odd SGBM block size; P1 = 8 * block_size^2, P2 = 32 * block_size^2",
        lambda v: v >= 1 and v % 2 == 1 and v <= 31, "an odd integer in [1, 31]")
    mode: str = setting(
        "3way",
        "OpenCV mode: sgbm | hh | 3way | hh4",
        lambda v: v in ("sgbm", "hh", "3way", "hh4"), "one of sgbm, hh, 3way, hh4")
    # at most 99: OpenCV's 3-way SGBM divides by (100 - uniquenessRatio), and 100 kills
    # the process (SIGFPE)
    uniqueness_ratio: int = setting(
        10,
        "margin in percent by which the best cost must win",
        lambda v: 0 <= v <= 99, "an integer in [0, 99]")
    speckle_window: int = setting(
        100,
        "largest speckle area (pixels) removed; 0 disables speckle filtering",
        lambda v: v >= 0, "an integer >= 0")
    speckle_range: int = setting(
        2,
        "disparity variation within a connected speckle component",
        lambda v: v >= 0, "an integer >= 0")
    disp12_max_diff: int = setting(
        1,
        "left-right check tolerance in pixels; -1 disables it",
        lambda v: v >= -1, "an integer >= -1")
    fill: bool = setting(True, "fill invalid pixels like d3stereo (row-wise, background side)")


@dataclass(frozen=True)
class PeersConfig:
    """Optional peers for comparison tables (``--method elas`` / ``pandora-sgm``)."""

    fill: bool = setting(True, "fill their holes row-wise (background side) like SGBM, for a dense comparison")
    elas_preset: str = setting(
        "middlebury",
        "libelas preset: middlebury (indoor scenes) | robotics (KITTI-like street scenes)",
        lambda v: v in ("middlebury", "robotics"), "one of middlebury, robotics")
    pandora_p1: float = setting(
        8.0,
        "pandora census + SGM: penalty for disparity changes of 1",
        lambda v: v >= 0, "a number >= 0")
    pandora_p2: float = setting(32.0, "... and for larger changes (constant)", lambda v: v >= 0, "a number >= 0")


@dataclass(frozen=True)
class CameraConfig:
    """Camera for point clouds when the pair has no calib.txt (``--pointcloud``)."""

    f: float | None = setting(
        None,
        "focal length, pixels",
        lambda v: v is None or v > 0, "a positive number (pixels) or null")
    baseline: float | None = setting(
        None,
        "stereo baseline, metres",
        lambda v: v is None or v > 0, "a positive number (metres) or null")
    cx: float | None = setting(None, "principal point column, pixels; null: image centre")
    cy: float | None = setting(None, "principal point row, pixels; null: image centre")
    # Depth range of cloud.ply points, metres (near-zero disparities give points at 1e33 m).  100 m: KITTI's useful range is about 80 m; road scenes are closer.
    min_depth_m: float = setting(
        0.0,
        "cloud.ply keeps points with min_depth_m <= depth <= max_depth_m, metres",
        lambda v: v >= 0, "a number >= 0 (metres)")
    max_depth_m: float = setting(
        100.0,
        "(near-zero disparities would give points hundreds of km away)",
        lambda v: v > 0, "a number > 0 (metres)")


#: The command that installs the optional GIS libraries (pyproj, shapely): the GPS track of
#: ``synth --drive`` and the survey map of ``run --track`` need them.
INSTALL_GIS = 'pip install "d3stereo[gis]"'


@dataclass(frozen=True)
class RoadConfig:
    """Road inspection outputs (``--road-report``): height above the road plane, defects."""

    report: bool = setting(
        False,
        "true: height.pfm, height_color.png, defects.json, defects.png per pair, OUT/defects.csv")
    min_depth_mm: float = setting(
        10.0,
        "a pothole is deeper than this below its surrounding road surface, mm",
        lambda v: v > 0, "a number > 0 (mm)")
    min_height_mm: float = setting(
        20.0,
        "a bump is higher than this above its surrounding road surface, mm",
        lambda v: v > 0, "a number > 0 (mm)")
    min_area_m2: float = setting(
        0.005,
        "smallest reported defect, area on the road plane, m^2",
        lambda v: v >= 0, "a number >= 0 (m^2)")
    sigma_disparity: float = setting(
        0.25,
        "disparity noise assumed by the robust (RANSAC + IRLS) plane fit, pixels",
        lambda v: v > 0, "a number > 0 (pixels)")
    ring_px: int = setting(
        12,
        "width of the ring of surrounding road giving a defect's reference height, pixels",
        lambda v: 2 <= v <= 100, "an integer in [2, 100]")
    min_decided_share: float = setting(
        0.5,
        "a defect with a smaller share of decided (not filled) pixels is low confidence",
        lambda v: 0 <= v <= 1, "a number in [0, 1]")
    colour_range_mm: float = setting(
        50.0,
        "height_color.png saturates at +- this, mm",
        lambda v: v > 0, "a number > 0 (mm)")
    # Splitting joined potholes (d3cli.road.splitting.split_parts): a depth saddle this deep, or a
    # neck at most split_neck x the smaller lobe's inscribed radius, separates two defects
    # whose parts are each at least split_min_area_m2.
    split_prominence_mm: float = setting(
        6.0,
        "joined potholes are two where both deepest points stand this far below the saddle between them, mm",
        lambda v: v > 0, "a number > 0 (mm)")
    split_neck: float = setting(
        0.9,
        "... or where the neck between two lobes is at most this x the smaller lobe's inscribed radius (1: never)",
        lambda v: 0 < v <= 1, "a number in (0, 1] (1: no split at necks)")
    split_min_area_m2: float = setting(
        0.01,
        "... and each part is at least this large (plane area), m^2",
        lambda v: v >= 0, "a number >= 0 (m^2)")
    # A region with a smaller share of decided pixels is not reported (its depth is the hole
    # filling's extrapolation), unless the whole map is below min_decided_share.
    min_region_decided_share: float = setting(
        0.25,
        "a region with fewer decided pixels is not reported (filled = extrapolated), unless the map is below min_decided_share",
        lambda v: 0 <= v <= 1, "a number in [0, 1]")
    frame_spacing_m: float = setting(
        0.0,
        "distance driven between frames, metres: road_survey.json gives potholes per km (0: unknown)",
        lambda v: v >= 0, "a number >= 0 (metres; 0: unknown)")
    # The survey on a map (d3cli.survey, docs/survey.md): the frames' positions and the rig on the car.
    track: str = setting(
        "",
        'track of the frames\' positions (track.csv or GPX; --track); "": track.csv or track.gpx beside the pair folders, else EXIF GPS')
    antenna_forward_m: float = setting(
        0.0,
        "the GPS fix is this far ahead of the point below the stereo rig's mid-point, metres",
        lambda v: abs(v) <= 100, "a number in [-100, 100] (metres)")
    antenna_right_m: float = setting(
        0.0,
        "... and this far to its right, metres",
        lambda v: abs(v) <= 100, "a number in [-100, 100] (metres)")
    camera_yaw_deg: float = setting(
        0.0,
        "the camera looks this far clockwise of the heading of travel, degrees",
        lambda v: -180 <= v <= 180, "a number in [-180, 180] (degrees)")
    merge_distance_m: float = setting(
        0.3,
        "sightings of one kind in different frames are one defect within this distance (or where their outlines overlap), metres",
        lambda v: v >= 0, "a number >= 0 (metres)")


def _at_level(level: int, finest, rest):
    """A per-level setting: ``finest`` at level 0 (full resolution) where it is set (not
    None), else ``rest`` (the value of every level)."""
    return finest if level == 0 and finest is not None else rest


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

    @property
    def equiangular_subpixel(self) -> bool:
        """Whether the sub-pixel step fits two lines of equal slope rather than a parabola:
        ``refine.subpixel_fit``, where ``auto`` takes the lines for a cost smoothed by the
        semi-global paths (``aggregation.sgm_p2 > 0``), whose linear penalties make its
        minimum a V, and the parabola for the RBF-aggregated cost, whose minimum is round."""
        if self.refine.subpixel_fit == "auto":
            return self.aggregation.sgm_p2 > 0
        return self.refine.subpixel_fit == "equiangular"

    def level_t_max(self, level: int) -> int:
        """RBF passes at ``level`` (0 = full resolution): ``aggregation.level_t_max[level]``
        where that list is given (its last value below its end), else
        ``aggregation.finest_t_max`` at level 0 where it is set, else ``aggregation.t_max``.

        Parameters
        ----------
        level : int
            Pyramid level, 0 at full resolution.
        """
        per_level = self.aggregation.level_t_max
        if per_level:
            return per_level[min(level, len(per_level) - 1)]
        return _at_level(level, self.aggregation.finest_t_max, self.aggregation.t_max)

    def level_band_tile(self, level: int) -> int:
        """Band tile at ``level`` (0 = full resolution): ``pyramid.finest_band_tile`` at
        level 0 where it is set, else ``pyramid.band_tile``.

        Parameters
        ----------
        level : int
            Pyramid level, 0 at full resolution.
        """
        return _at_level(level, self.pyramid.finest_band_tile, self.pyramid.band_tile)

    def level_window(self, level: int) -> int:
        """NCC window size at ``level`` (0 = full resolution).

        Parameters
        ----------
        level : int
            Pyramid level, 0 at full resolution.
        """
        lw = self.cost.level_windows
        if lw:
            return lw[min(level, len(lw) - 1)]
        return self.cost.window
