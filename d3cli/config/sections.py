"""The configuration's sections: one frozen dataclass per YAML section, with every default.

``configs/default.yaml`` (in the wheel ``d3cli/configs``) documents every key; :mod:`d3cli.config.checks` holds the range
checks and :mod:`d3cli.config.load` builds a :class:`Config` from a file and ``--set``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field, fields

from .methods import METHODS

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

    method: str = "d3stereo"
    backend: str = "auto"
    max_disparity: int | None = None  # None: from the dataset layout, else width // 4
    max_memory_gb: float | None = None  # refuse pairs whose estimated peak exceeds this; None: 75 % of RAM
    color_range: tuple[float, ...] = ()  # [min, max] px of disp_color.png for a whole batch; []: per-pair percentiles
    outputs: str = "all"  # per-pair files written: all | survey[,kitti][,pictures][,height] (OUTPUT_CHOICES)


@dataclass(frozen=True)
class PyramidConfig:
    """Image/cost pyramid and hierarchy (paper section III, Fig. 1)."""

    levels: int = 4  # k: number of scales; level 1 is full resolution
    ars: bool = True  # alternating inheritance/diffusion; False: DFM linear hierarchy (diffusion at level 1 only, no fresh seeds)
    band: bool = True  # levels below the coarsest search a band around the coarser level's map (docs/design.md, 'Pyramid and bands')
    band_margin: int = 2  # the band: 2 d_coarse +- this many disparities, hull over a tile and its neighbours
    band_tile: int = 32  # tile size (pixels of the level); a tile searches the hull over itself and its 8 neighbours
    # The tile at full resolution (level 1); None: band_tile.  16 by default: on the 22
    # Middlebury pairs the same maps to 0.01 EPE as 32 (EPE / PEP0.5 / PEP1 / PEP2 1.351 /
    # 20.09 / 12.53 / 8.89 against 1.350 / 20.09 / 12.51 / 8.85; 8: EPE 1.386) in about
    # 7 % less time on Middlebury-Q (the finest level's bands are its NCC, smoothing,
    # inheritance and diffusion cells); tiles of 16 at every level lose (1.395: a coarse
    # band too narrow is not made good below).  kitti.yaml takes 24.  docs/performance.md
    finest_band_tile: int | None = 16


@dataclass(frozen=True)
class CostConfig:
    """Matching cost (docs/design.md, 'Cost volumes'): NCC, or the cosine of deep features."""

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
    t_max: int = 4  # RBF passes of the 3x3 kernel (every level below full resolution, see finest_t_max)
    # RBF passes at full resolution (level 1); None: t_max.  0 by default: there the
    # semi-global smoothing of the cost (below) follows, and the raw NCC under it measures
    # better than 4 passes on the Middlebury and KITTI pairs (EPE and PEP1) at a third less
    # time per pair (the filter and its weights take a quarter of it); below full
    # resolution, where no smoothing runs, the filter keeps the coarse maps and with them
    # the bands narrow (0 there too doubles the decisions' and the diffusion's time).
    # docs/performance.md, 'Default settings'; paper.yaml: None (the paper's RBF everywhere)
    finest_t_max: int | None = 0
    # RBF passes per level, finest first (the last value for every coarser level); () uses
    # finest_t_max and t_max.  No shipped config sets it: (0, 4, 0) for road.yaml keeps the
    # maps and saves 1-4 % of the time but doubles the road check's false defects (docs/road.md)
    level_t_max: tuple[int, ...] = ()
    sigma_space: float = 1.5  # sigma_1 in eq. 3, pixels
    sigma_color: float = 12.0  # sigma_2 in eq. 3, grey levels (0-255)
    kappa_a: int = 4  # radius of the plain bilateral filter used when rbf is False
    # sigma_1 of that plain filter; None: sigma_space * kappa_a, the 3x3 kernel of eq. 3
    # stretched to the (2 kappa_a + 1)^2 window (same receptive field as RBF, Fig. 4)
    bf_sigma_space: float | None = None
    # Semi-global smoothing of the full-resolution aggregated cost (docs/design.md,
    # 'Semi-global smoothing'): the mean of four path costs (left, down, right, up) with
    # penalties P1 (one-disparity step) and P2 (larger jump) in cost units
    # ((1 - NCC) / 2); sgm_p2 0: off (the paper's method, configs/paper.yaml).  On
    # by default: with finest_t_max 0, P1 0.1 / P2 1.2 chosen on the Middlebury pairs and
    # checked leave-one-out (docs/performance.md, 'Default settings');
    # configs/kitti.yaml uses 0.6 / 1.2
    sgm_p1: float = 0.1
    sgm_p2: float = 1.2


@dataclass(frozen=True)
class SeedConfig:
    """Decisive seeds at the coarsest level (docs/design.md, 'Decisive seeds')."""

    pkrn_min: float = 2.0  # keep a WTA disparity when (c2 + eps) / (c1 + eps) >= this
    epsilon: float = 1e-3  # eps in the PKRN ratio
    lr_tolerance: int = 1  # max |d_left - d_right| for the left-right check
    pkrn_exclusion: int = 0  # 0: naive PKRN; r > 0: c2 ignores disparities within r of d*
    every_level: bool = True  # also add fresh seeds below the coarsest level where nothing was inherited (ars only)


@dataclass(frozen=True)
class DiffusionConfig:
    """Intra-scale decisive diffusion, paper eq. 4-5 and Algorithm 1."""

    tau: int = 1  # disparity search tolerance r in [-tau, tau]
    kappa_d: int = 1  # neighbourhood radius
    adversarial: bool = True  # decided pixels may switch to a better candidate (eq. 5)
    max_sweeps: int = 100000  # safeguard; diffusion normally stops when nothing changes
    max_gap: float = 0.0  # accepted states cost <= the pixel's least cost + this; -1: off (paper)


@dataclass(frozen=True)
class InheritanceConfig:
    """Inter-scale decisive inheritance, paper eq. 6-8 and Algorithm 2."""

    prc: bool = True  # patch reliability constraint; False: DFM-style PKRN test in the patch
    dfm_pkrn_min: float = 1.05  # PKRN threshold of the DFM-style test (prc False)
    # symmetric: {2dc-1, 2dc, 2dc+1} in the patch, {2dc-2, 2dc+2} outside, every pixel;
    # paper: eq. 6-7 read literally, the co-row partners of each pixel (two per pixel)
    candidates: str = "symmetric"


@dataclass(frozen=True)
class PTConfig:
    """Perspective transformation for road scenes (docs/design.md, 'Perspective transformation')."""

    enabled: bool = False
    margin: int = 8  # delta: full-resolution disparity margin around the road model
    slack: int = 2  # extra disparities added to the narrow range [0, 2 delta + slack]
    min_inlier_share: float = 0.5  # below this the scene is not road-like: full range
    inlier_threshold: float = 1.0  # |residual| in coarse-level pixels counted as inlier
    iterations: int = 10  # iteratively re-weighted least-squares rounds
    max_band_end_share: float = 0.03  # more pixels matched at the narrow range's ends: not a road, full range
    fallback_config: str = ""  # bundled config whose settings match a pair that is not a road; "": this one's

    @property
    def narrow_range(self) -> int:
        """Largest disparity searched after the transformation: ``2 margin + slack``."""
        return 2 * self.margin + self.slack


@dataclass(frozen=True)
class RefineConfig:
    """Sub-pixel refinement and hole filling (docs/design.md, 'Finishing')."""

    subpixel: bool = True  # fit through C(d-1), C(d), C(d+1), offset clamped to +-0.5
    # the fit: parabola (the paper's) | equiangular (two lines of equal slope: a V-shaped
    # minimum) | auto: equiangular on the semi-global smoothing's cost, else parabola
    subpixel_fit: str = "auto"
    occlusion_check: bool = True  # uniqueness + left-border tests: estimates with no possible true match become holes
    # connected regions of decided pixels (neighbours within speckle_range px) with at most
    # speckle_size pixels become holes before filling; 0: off
    speckle_size: int = 0
    speckle_range: float = 1.0
    fill: bool = True  # False: undecided pixels stay inf in disp.pfm
    fill_inside: bool = False  # non-occluded holes take the median of 4 directions, not the background side
    smooth_filled: bool = True  # 5x5 median over the filled pixels only
    smooth_radius: int = 3  # edge-preserving smoothing of the result, box radius in pixels; 0: off
    smooth_sigma: float = 2.0  # range sigma of that smoothing, disparity pixels (residual to the road model with PT)
    smooth_kernel: str = "box"  # its range kernel: gaussian | box (mean of neighbours within smooth_sigma; faster)


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
    # Depth range of cloud.ply points, metres (near-zero disparities give points at 1e33 m).  100 m: KITTI's useful range is about 80 m; road scenes are closer.
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
    # Splitting joined potholes (d3cli.road.splitting.split_parts): a depth saddle this deep, or a
    # neck at most split_neck x the smaller lobe's inscribed radius, separates two defects
    # whose parts are each at least split_min_area_m2.
    split_prominence_mm: float = 6.0
    split_neck: float = 0.9
    split_min_area_m2: float = 0.01
    # A region with a smaller share of decided pixels is not reported (its depth is the hole
    # filling's extrapolation), unless the whole map is below min_decided_share.
    min_region_decided_share: float = 0.25
    frame_spacing_m: float = 0.0  # distance between frames for road_survey.json's per-km counts (0: unknown)


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
