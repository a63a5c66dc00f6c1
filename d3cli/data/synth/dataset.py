""":func:`render_pair` (one pair in memory) and :func:`generate_dataset` (pair folders
on disk, every file written atomically through :mod:`d3cli.data.formats`).
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...errors import InputError, OutputError, where_what_fix
from ..formats import atomic_write, write_image, write_pfm
from .render import _Lighting, _expose, _render_view, _sample_lighting
from .rig import MATERIALS, VARIANTS, StereoRig, _road_bounds, sample_rig, _texel_size
from .terrain import _build_height_field, _HeightField, _pothole_weight, _RoadShape, _sample_road, _sample_road_point
from .texture import _build_albedo, _build_mipmap, _build_wetness, _MipMap
from .truth import SynthPair, _describe_hole, _ground_truth, _sink_at, pothole_truth

log = logging.getLogger(__name__)


def _check_choice(name: str, value: str, choices) -> None:
    if value not in choices:
        raise InputError(where_what_fix("synth", f"unknown {name} {value!r}", f"use one of {', '.join(choices)}"))


#: Image sides accepted by the generator: smaller cannot hold a road scene, larger would
#: need tens of GB while rendering (a 200000-pixel width would end in a MemoryError).
MIN_SIDE, MAX_SIDE = 32, 8192


#: The file that marks a folder as one synthetic dataset (seed and size).
DATASET_FILE = "synth.json"

#: Memory rendering one pair takes, bytes per pixel: the peak grew by 174 B/px from
#: 1024x1024 to 2048x2048 (height field, mip-mapped texture, both views' radiance and
#: ray buffers scale with the pixels), so 8192x8192 needs about 13 GB; with a margin.
SYNTH_BYTES_PER_PIXEL = 200


def _proc_kib(path: str, field: str) -> int | None:
    """``field`` (kB) of a /proc file as bytes, or None where there is none."""
    try:
        with open(path, encoding="ascii") as fh:
            for line in fh:
                if line.startswith(field + ":"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def memory_left() -> tuple[int, str] | None:
    """(bytes this process can still allocate, what limits it), or None when unknown.

    The tightest of the address-space and data limits (``ulimit -v``, ``ulimit -d``) less
    what the process already uses, the memory the system has free (RAM and swap) and what
    a container's memory limit leaves.
    """
    try:
        import resource
    except ImportError:  # not a POSIX system: no such limits
        resource = None
    left = []
    limits = (((resource.RLIMIT_AS, "VmSize", "ulimit -v"), (resource.RLIMIT_DATA, "VmData", "ulimit -d"))
              if resource is not None else ())
    for limit, used_field, what in limits:
        soft = resource.getrlimit(limit)[0]
        used = _proc_kib("/proc/self/status", used_field)
        if soft != resource.RLIM_INFINITY and used is not None:
            left.append((max(soft - used, 0), f"this process may still use under its limit of {soft / 1e9:.1f} GB "
                                              f"({what})"))
    available, swap = _proc_kib("/proc/meminfo", "MemAvailable"), _proc_kib("/proc/meminfo", "SwapFree")
    if available is not None:
        left.append((available + (swap or 0), "the system has free (RAM and swap)"))
    try:  # a container's limit (cgroup v2), which /proc/meminfo does not show
        with open("/sys/fs/cgroup/memory.max", encoding="ascii") as fh:
            cap = fh.read().strip()
        with open("/sys/fs/cgroup/memory.current", encoding="ascii") as fh:
            current = int(fh.read().strip())
        if cap != "max":
            left.append((max(int(cap) - current, 0), f"the container's memory limit of {int(cap) / 1e9:.1f} GB "
                                                     "leaves"))
    except (OSError, ValueError):
        pass
    return min(left) if left else None


def _size_text(n_bytes: float) -> str:
    """``13.4 GB``, or ``12 MB`` below a tenth of a GB."""
    return f"{n_bytes / 1e9:.1f} GB" if n_bytes >= 1e8 else f"{n_bytes / 1e6:.0f} MB"


def _check_memory(width: int, height: int) -> None:
    """Refuse a size whose rendering cannot fit in memory, before any work: at 8192x8192
    under a 6 GB address-space limit the renderer would run for minutes and then die
    inside OpenBLAS's allocator, with no message of ours."""
    need = width * height * SYNTH_BYTES_PER_PIXEL
    left = memory_left()
    if left is None or need <= left[0]:
        return
    room, what = left
    shrink = math.sqrt(room / need)
    smaller_w, smaller_h = int(width * shrink) // 16 * 16, int(height * shrink) // 16 * 16
    fix = (f"use a smaller --width/--height (about --width {smaller_w} --height {smaller_h} fits)"
           if min(smaller_w, smaller_h) >= MIN_SIDE else "free memory, or raise the limit")
    raise InputError(where_what_fix("synth", f"rendering a {width}x{height} pair needs about {_size_text(need)} "
                                             f"of memory, more than {what}: {_size_text(room)}", fix))


def _out_of_memory(width: int, height: int) -> InputError:
    """The error for a MemoryError while rendering (an estimate that was not enough)."""
    need = width * height * SYNTH_BYTES_PER_PIXEL
    return InputError(where_what_fix("synth", f"out of memory rendering a {width}x{height} pair "
                                              f"(it needs about {_size_text(need)})",
                                     "use a smaller --width/--height, or free memory"))


def _check_size(width: int, height: int) -> None:
    if width < MIN_SIDE or height < MIN_SIDE:
        raise InputError(where_what_fix("synth", f"image size {width}x{height} is too small",
                                        f"use a width and height of at least {MIN_SIDE} pixels"))
    if width > MAX_SIDE or height > MAX_SIDE:
        raise InputError(where_what_fix("synth", f"image size {width}x{height} is too large",
                                        f"use a width and height of at most {MAX_SIDE} pixels"))


def _claim_folder(out_dir: Path, identity: dict,
                  same: str = "the same --seed/--width/--height as before") -> None:
    """Refuse to mix two datasets in one folder; mark the folder as this dataset.

    A folder may be empty, or hold a dataset of the same ``identity`` (a rerun, or more
    pairs of the same set: pairs are deterministic).  Anything else is refused, so that
    pairs of two seeds or sizes never end up side by side; ``same`` names the options
    that must match.
    """
    marker = out_dir / DATASET_FILE
    entries = [p.name for p in out_dir.iterdir()] if out_dir.is_dir() else []
    if entries:
        try:
            stored = json.loads(marker.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            stored = None
        if stored != identity:
            raise OutputError(where_what_fix(
                str(out_dir), f"the folder is not empty (it holds {_made_by(stored, entries)})",
                f"give an empty or new folder, or {same}"))
    atomic_write(marker, lambda tmp: tmp.write_text(json.dumps(identity) + "\n", encoding="utf-8"))


def _made_by(stored, entries: list) -> str:
    """What a folder holds, by its marker (``stored``, None when unreadable)."""
    if not isinstance(stored, dict):
        return f"{len(entries)} other entries"
    what = f"a synthetic drive of {stored.get('drive')} frames" if "drive" in stored else "a synthetic set"
    return f"{what} with seed {stored.get('seed')} and size {stored.get('width')}x{stored.get('height')}"


def render_pair(
    *,
    seed: int,
    width: int = 1280,
    height: int = 720,
    variant: str = "sun",
    material: str = "asphalt",
    noise: bool = True,
    potholes: int | None = None,
    flat: bool = False,
    supersample: int = 2,
    shapes: str = "varied",
) -> SynthPair:
    """Render one synthetic road stereo pair with exact ground truth.

    Parameters
    ----------
    seed : int
        Seed of everything random (rig, road, texture, light, noise); equal seeds give
        bit-identical pairs.
    width, height : int
        Image size in pixels (at least 32).
    variant : {"sun", "dusk", "wet"}
        Illumination (see the module docstring).
    material : {"asphalt", "cement"}
        Road surface texture.
    noise : bool
        False leaves out sensor noise (images are still blurred and quantised).
    potholes : int or None
        Number of potholes; None draws 0-3.
    flat : bool
        True makes the road the exact plane z = 0 (no undulation, slope, potholes or
        bump), so the disparity is exactly ``a0 + a1 (v cos(theta) - u sin(theta))``.
    supersample : int
        Rays per pixel along each axis (antialiasing).
    shapes : {"varied", "classic"}
        Pothole shapes: "varied" draws the families of :mod:`d3cli.data.synth.potholes`
        (bowls, flat floors, cones, multilevel, rough, elongated, ragged, water-filled);
        "classic" only flat floors with raised-cosine walls, the pairs of earlier versions
        bit for bit.

    Returns
    -------
    SynthPair
        Images uint8 (H, W), disparity float32 (H, W) (inf invalid), nocc bool (H, W),
        calib and info dicts.

    Raises
    ------
    InputError
        An unknown choice, a bad size, or a size whose rendering needs more memory than
        the process may use (before rendering) or runs out of it.
    """
    _check_choice("variant", variant, VARIANTS)
    _check_choice("material", material, MATERIALS)
    _check_size(width, height)
    _check_choice("pothole shapes", shapes, ("varied", "classic"))
    if int(supersample) < 1:
        raise InputError(where_what_fix("synth", f"supersample is {supersample}", "use 1 or more rays per axis"))
    _check_memory(width, height)
    rng = np.random.default_rng(seed)
    try:
        scene = _build_scene(rng, width, height, variant, material, potholes, flat, shapes)
        return _render_scene(scene, rng, supersample=int(supersample), noise=noise, surface_truth=shapes == "varied",
                             seed=seed, variant=variant, material=material, flat=flat)
    except MemoryError:
        raise _out_of_memory(width, height) from None


def _render_scene(scene: _Scene, rng, *, supersample: int, noise: bool, surface_truth: bool, seed: int,
                  variant: str, material: str, flat: bool) -> SynthPair:
    """Both views, the exact disparity and the pothole truth of a drawn scene (``rng``
    then draws the sensor noise); ``surface_truth`` measures the potholes on the rendered
    surface (relief and water included), else on their profiles."""
    rig = scene.rig
    left_img, right_img = _render_views(scene, rig.width, rig.height, supersample, rng, noise)
    disparity, nocc, points = _ground_truth(rig, scene.field_, scene.h_top)
    pothole_ids, defects_gt = pothole_truth(scene.road.holes, rig, points, scene.field_ if surface_truth else None)
    finite = disparity[np.isfinite(disparity)]
    calib = rig.calib()
    calib["ndisp"] = int(math.ceil(float(finite.max()))) + 8 if finite.size else rig.width // 4
    info = _pair_info(scene, seed=seed, variant=variant, material=material, noise=noise, flat=flat)
    return SynthPair(left_img, right_img, disparity, nocc, calib, info, pothole_ids, defects_gt)


@dataclass(frozen=True)
class _Scene:
    """Everything :func:`render_pair` draws before rendering: rig, road, texture, light."""

    rig: StereoRig
    road: _RoadShape
    texel: float
    spacing: float
    field_: _HeightField
    h_top: float
    lighting: _Lighting
    mip: _MipMap
    wet: np.ndarray


def _build_scene(rng, width: int, height: int, variant: str, material: str, potholes: int | None,
                 flat: bool, shapes: str = "varied") -> _Scene:
    """Draw the rig, road, height field, light and texture, in the order the seed fixes."""
    rig, road, texel, spacing, bounds, field_, h_top = _build_surface(rng, width, height, potholes, flat, shapes)
    return _dress_scene(rng, variant, material, rig, road, texel, spacing, bounds, field_, h_top)


def _dress_scene(rng, variant: str, material: str, rig: StereoRig, road: _RoadShape, texel: float, spacing: float,
                 bounds, field_: _HeightField, h_top: float, lighting: _Lighting | None = None) -> _Scene:
    """The light (drawn unless given), texture and wetness of a surface, in the order the
    seed fixes."""
    holes = road.holes
    if lighting is None:
        lighting = _sample_lighting(rng, variant, rig)
    light_pool = None
    if variant == "dusk":
        light_pool = (*_sample_road_point(rng, rig), rng.uniform(1.0, 2.5))
    albedo = _build_albedo(rng, material, bounds, texel, holes, light_pool)
    mip = _build_mipmap(albedo, texel, bounds[0], bounds[2])
    del albedo
    wet = _build_wetness(rng, field_) if variant == "wet" else np.zeros((1, 1))
    if field_.water is not None:
        # Standing water: dark and mirror-like in every light (the dry lights' shading
        # has no wet terms: those of a wet road are used on the water only).
        wet = np.maximum(wet, field_.water) if wet.shape == field_.water.shape else field_.water
        shade = lighting.shade.copy()
        shade[3], shade[5], shade[6] = max(shade[3], 0.5), max(shade[5], 200.0), max(shade[6], 0.5)
        lighting = dataclasses.replace(lighting, shade=shade)
    return _Scene(rig, road, texel, spacing, field_, h_top, lighting, mip, wet)


def _build_surface(rng, width: int, height: int, potholes: int | None, flat: bool, shapes: str):
    """The rig, road shape and height field (the first draws of a pair's seed): rig, road,
    texel, grid spacing, bounds, field, h_top."""
    rig = sample_rig(rng, width, height)
    road = _sample_road(rng, rig, potholes, flat, shapes)
    texel, spacing = _grid_steps(rig)
    bounds, z_range = _visible_patch(rig, road)
    field_, h_top = _surface(rng, road, bounds, spacing, z_range)
    return rig, road, texel, spacing, bounds, field_, h_top


def _grid_steps(rig: StereoRig) -> tuple[float, float]:
    """Texel size and height-grid spacing (metres) for a rig."""
    texel = _texel_size(rig)
    return texel, float(np.clip(1.5 * texel, 2e-3, 2e-2))


def _visible_patch(rig: StereoRig, road: _RoadShape):
    """Bounds (x_min, x_max, y_min, y_max) of the road both views see and the height
    range (z_low, z_high) the surface stays in there."""
    # The visible patch depends on the height range and the tilt part of the height
    # range on the patch: two rounds from a generous start settle it.
    z_low, z_high = -0.15, 0.1
    for _ in range(2):
        bounds = _road_bounds(rig, z_low, z_high, margin=0.05)
        z_low, z_high = road.height_range(bounds)
    return _road_bounds(rig, z_low, z_high, margin=0.05), (z_low, z_high)


def _surface(rng, road: _RoadShape, bounds, spacing: float, z_range) -> tuple[_HeightField, float]:
    """The height field of ``road`` over ``bounds`` and the top of the surface (metres)."""
    field_ = _build_height_field(rng, road, bounds, spacing)
    h_top = float(field_.h.max()) + 1e-3
    if field_.h.max() > z_range[1] or field_.h.min() < z_range[0]:
        raise RuntimeError("synthetic road height left the range its visible patch was computed for")
    return field_, h_top


def pothole_depth_image(*, seed: int, width: int, height: int, disparity: np.ndarray,
                        potholes: int | None = None, shapes: str = "varied") -> np.ndarray:
    """How far the potholes lower the road at the surface point each left pixel sees.

    The road of :func:`render_pair` with this ``seed`` and size is drawn again (rig, road
    and height field only: no rendering) and its sink (the road without potholes minus the
    surface, water level included: what ``defects_gt.json`` measures depth, area and
    volume of) is read at the points the exact disparity triangulates.

    Parameters
    ----------
    seed, width, height : int
        Those of the pair (SOURCE.txt ``pair_seed`` and ``image_size``).
    disparity : ndarray, float32, (H, W)
        The pair's exact disparity (``disp_gt.pfm``; inf where no road).
    potholes : int or None
        As in :func:`render_pair`.
    shapes : {"varied", "classic"}
        As in :func:`render_pair`.

    Returns
    -------
    ndarray, float64, (H, W)
        Depth below the road without potholes in mm (0 off the potholes), nan where the
        disparity is not finite.
    """
    rig, road, _, _, _, field_, _ = _build_surface(np.random.default_rng(seed), width, height, potholes, False, shapes)
    d = np.asarray(disparity, np.float64)
    ok = np.isfinite(d) & (d > 0)
    vv, uu = np.mgrid[0:d.shape[0], 0:d.shape[1]].astype(np.float64)
    depth = rig.f * rig.baseline / np.where(ok, d, 1.0)
    points = rig.centres()[0] + depth[..., None] * rig.ray_directions(uu, vv)
    if field_.sink is not None:
        sink = _sink_at(field_, points[..., 0], points[..., 1])
    else:  # classic potholes: no relief, the profiles are the sink
        sink = np.zeros(d.shape)
        for hole in road.holes:
            sink = np.maximum(sink, hole.depth * _pothole_weight(hole, points[..., 0], points[..., 1]))
    return np.where(ok, 1e3 * sink, np.nan)


def _render_views(scene: _Scene, width: int, height: int, supersample: int, rng, noise: bool):
    """Ray-cast both views and expose them (one exposure scale, from the left view)."""
    rig, field_, mip, lighting = scene.rig, scene.field_, scene.mip, scene.lighting
    rot = rig.rotation()
    left_c, right_c = rig.centres()
    hf = (field_.h, field_.grad_x, field_.grad_y, scene.wet, field_.lipschitz, field_.tile,
          field_.x0, field_.y0, field_.spacing, scene.h_top)
    radiance = [
        _render_view(c, rot, rig.f, rig.cx, rig.cy, width, height, supersample, *hf,
                     mip.flat, mip.offsets, mip.shapes, mip.scales, mip.texel, mip.x0, mip.y0,
                     lighting.light, lighting.shade, lighting.shadows)
        for c in (left_c, right_c)
    ]
    scale = lighting.mean_electrons / max(float(radiance[0].mean()), 1e-9)
    return tuple(_expose(r, scale, lighting, rng, noise, rig) for r in radiance)


def _pair_info(scene: _Scene, *, seed: int, variant: str, material: str, noise: bool, flat: bool) -> dict:
    """The scene description stored in ``SynthPair.info`` (and SOURCE.txt)."""
    road, rig, lighting = scene.road, scene.rig, scene.lighting
    return {
        "seed": int(seed),
        "variant": variant,
        "material": material,
        "noise": bool(noise),
        "flat": bool(flat),
        "potholes": [_describe_hole(hole, rig) for hole in road.holes],
        "bump": None if road.bump is None else {"x": road.bump[0], "y": road.bump[1], "height_m": road.bump[4]},
        "undulation_std_m": road.undulation_m,
        "cross_slope": road.cross_slope,
        "grade": road.grade,
        "light_elevation_deg": math.degrees(math.asin(float(lighting.light[2]))),
        "texel_m": scene.texel,
        "grid_spacing_m": scene.spacing,
    }


def _write_text(path: Path, lines: list[str]) -> None:
    atomic_write(path, lambda tmp: tmp.write_text("\n".join(lines) + "\n", encoding="utf-8"))


def pair_name(index: int, variant: str, material: str) -> str:
    """Folder name of pair ``index``: ``synth-0000-sun-asphalt``."""
    return f"synth-{index:04d}-{variant}-{material}"


def generate_dataset(out_dir, *, n: int = 12, seed: int = 0, width: int = 1280, height: int = 720,
                     on_pair=None) -> list[Path]:
    """Render ``n`` pairs into pair folders under ``out_dir``.

    Variants cycle sun, dusk, wet and materials asphalt, cement, so six consecutive
    pairs cover every combination.  Each folder holds ``left.png``, ``right.png``
    (8-bit grey), ``disp_gt.pfm`` (float32, inf invalid), ``mask0nocc.png`` (255 =
    visible in the right view), ``calib.txt`` and ``SOURCE.txt`` (``gt_scale: 1``,
    ``gt_invalid: inf``, seeds and scene description); every file is written under a
    temporary name and renamed.  The same (seed, index, size) always gives the same
    pair; ``render_pair(seed=<pair_seed in SOURCE.txt>, ...)`` reproduces it.

    Parameters
    ----------
    out_dir : str or os.PathLike
        Folder of the pair folders; created when missing.
    n : int
        Number of pairs.
    seed : int
        Seed of the whole set; each pair gets its own seed from it.
    width, height : int
        Image size in pixels.
    on_pair : callable, optional
        Called as ``on_pair(index, folder, seconds)`` once each pair is written (a pair
        takes seconds at the default size: the command's progress).

    Returns
    -------
    list of Path
        The pair folders, in index order.

    Raises
    ------
    InputError
        A bad count, seed or size, or a size whose rendering needs more memory than the
        process may use (checked before anything is written) or runs out of it.
    """
    if int(n) < 1:
        raise InputError(where_what_fix("synth", f"--n is {n}", "ask for at least one pair"))
    if int(seed) < 0:  # numpy's SeedSequence takes non-negative integers only
        raise InputError(where_what_fix("synth", f"--seed is {seed}", "give a seed >= 0 (the same seed gives the same pairs)"))
    _check_size(width, height)
    _check_memory(width, height)  # before the folder is made: a refused size leaves nothing
    out_dir = Path(out_dir)
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(where_what_fix(str(out_dir), f"cannot create the folder ({exc.strerror or exc})",
                                         "choose a writable output folder")) from exc
    _claim_folder(out_dir, {"generator": "d3stereo synth", "seed": int(seed), "width": int(width),
                            "height": int(height)})
    folders = []
    for index in range(int(n)):
        variant = VARIANTS[index % len(VARIANTS)]
        material = MATERIALS[index % len(MATERIALS)]
        pair_seed = int(np.random.SeedSequence([int(seed), index]).generate_state(1)[0])
        folder = out_dir / pair_name(index, variant, material)
        started = time.perf_counter()
        try:
            pair = render_pair(seed=pair_seed, width=width, height=height, variant=variant, material=material)
            folders.append(_write_pair(folder, pair, dataset_seed=int(seed), index=index))
        except MemoryError:
            raise _out_of_memory(width, height) from None
        finite = pair.disparity[np.isfinite(pair.disparity)]
        log.info("synth: wrote %s (disparity %.1f-%.1f px)", folder.name, finite.min(), finite.max())
        if on_pair is not None:
            on_pair(index, folder, time.perf_counter() - started)
    return folders


def _write_pair(folder: Path, pair: SynthPair, *, dataset_seed: int, index: int,
                source: list[str] | None = None) -> Path:
    """Write ``pair``'s files into ``folder``; ``source`` replaces the SOURCE.txt lines
    that say how to render the pair again (its seed and ``reproduce``)."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(where_what_fix(str(folder), f"cannot create the folder ({exc.strerror or exc})",
                                         "choose a writable output folder")) from exc
    write_image(folder / "left.png", pair.left)
    write_image(folder / "right.png", pair.right)
    write_pfm(folder / "disp_gt.pfm", pair.disparity)
    write_image(folder / "mask0nocc.png", np.where(pair.nocc, 255, 0).astype(np.uint8))
    if pair.pothole_ids is not None:
        write_image(folder / "potholes_gt.png", pair.pothole_ids)
    gt_text = json.dumps({"definitions": "depth_mm: below the surrounding surface; area_m2: horizontal area "
                                         "deeper than 10 mm; volume_l: fill volume up to the surrounding "
                                         "surface; visible_px: pixels of potholes_gt.png with this id; nested potholes (the "
                                         "floor of one inside the other's part deeper than 10 mm) are one defect: "
                                         "the deepest one's entry lists its members and holds the union's area and "
                                         "volume, the others say part_of that id",
                          "potholes": pair.defects_gt}, indent=2) + "\n"
    atomic_write(folder / "defects_gt.json", lambda tmp: tmp.write_text(gt_text, encoding="utf-8"))
    calib = pair.calib
    _write_text(folder / "calib.txt", [f"{key}: {_fmt(calib[key])}" for key in
                                       ("f", "baseline", "cx", "cy", "width", "height", "height_m",
                                        "pitch_deg", "roll_deg", "doffs", "ndisp")])
    info = pair.info
    finite = pair.disparity[np.isfinite(pair.disparity)]
    holes = "; ".join(f"shape={h['shape']} x={h['x']:.3f} y={h['y']:.3f} depth={h['depth_m']:.3f} diameter={h['diameter_m']:.2f} "
                      f"u={h['u']:.1f} v={h['v']:.1f}" for h in info["potholes"]) or "none"
    bump = "none" if info["bump"] is None else (f"x={info['bump']['x']:.3f} y={info['bump']['y']:.3f} "
                                                 f"height={info['bump']['height_m']:.3f}")
    _write_text(folder / "SOURCE.txt", [
        "source: d3stereo synthetic road (d3cli.synth), exact ground truth by ray casting",
        "family: synth",
        "gt_scale: 1",
        "gt_invalid: inf",
        f"dataset_seed: {dataset_seed}",
        f"index: {index}",
        *(source if source is not None else [f"pair_seed: {info['seed']}"]),
        f"variant: {info['variant']}",
        f"material: {info['material']}",
        f"potholes: {holes}",
        f"bump: {bump}",
        f"max_disparity: {calib['ndisp']}",
        f"image_size: {calib['width']}x{calib['height']}",
        f"disparity_range: {finite.min():.3f} {finite.max():.3f}",
        f"nocc_share: {pair.nocc.mean():.4f}",
        *([] if source is not None else
          [f"reproduce: render_pair(seed={info['seed']}, width={calib['width']}, height={calib['height']}, "
           f"variant={info['variant']!r}, material={info['material']!r})"]),
    ])
    return folder


def _fmt(value) -> str:
    return str(value) if isinstance(value, int) else f"{value:.10g}"
