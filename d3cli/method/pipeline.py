"""D3Stereo pipeline: ``D3Stereo(cfg).compute(left, right) -> DisparityResult``."""

from __future__ import annotations

import dataclasses
import logging
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..config import Config, load_config
from ..data.formats import to_grey
from ..data.layouts import normalise_bit_depth
from ..errors import InputError
from ..kernels import get_backend, host
from ..kernels.backend import Backend
from .cost import aggregation_halo, level_cost
from .decisive import decisive_seeds, diffuse, inherit
from .features import feature_pyramid, load_feature_npz, npz_path
from .perspective import (REFIT_SHARE, RoadModel, fit_road_model, refit_on_band, restored_shares,
                          restored_validity_counts)
from .pyramid import level_max_disparity, usable_levels
from .refinement import drop_occluded, drop_speckles, fill_holes, refine_subpixel

log = logging.getLogger(__name__)


@dataclass
class DisparityResult:
    """Output of a stereo method on one pair.

    Attributes
    ----------
    disparity : ndarray, float32, (H, W)
        Left-view disparity in pixels (left (u, v) matches right (u - d, v)).
        ``inf`` where invalid (only when hole filling is off).
    valid : ndarray, bool, (H, W)
        True where the method decided the disparity itself (before any filling).
    levels : sequence of ndarray
        Per-level integer disparity maps (int32, -1 = undecided), finest first; empty for
        baselines.  A map computed on a GPU is copied to the host when it is first read
        (:class:`HostMaps`).  With the perspective transformation these are the narrow-range
        disparities d' against the warped right image (``info['pt']`` has the model).
    timings : dict of str to float
        Seconds per step.
    info : dict
        JSON-serialisable facts about the run (backend, seeds, fitted PT model, ...).
    warnings : list of str
        Human-readable warnings (e.g. "no decisive seeds").
    """

    disparity: np.ndarray
    valid: np.ndarray
    levels: Sequence[np.ndarray] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    info: dict[str, Any] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)


class HostMaps(Sequence):
    """Backend maps read as NumPy arrays, each copied to the host when first indexed.

    On the CPU the maps are NumPy arrays already; on CUDA a pair's per-level maps stay on
    the device unless someone reads them (most batch runs do not), which saves a copy per
    level.  Pickling (a result sent back from a worker process) copies them all.
    """

    def __init__(self, maps, to_host):
        self._maps = list(maps)
        self._to_host = to_host
        self._host: dict[int, np.ndarray] = {}

    def __len__(self) -> int:
        return len(self._maps)

    def __getitem__(self, i):
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(len(self)))]
        i = range(len(self))[i]  # negative indices, IndexError
        if i not in self._host:
            self._host[i] = self._to_host(self._maps[i])
        return self._host[i]

    def __reduce__(self):
        return list, (list(self),)

    def __repr__(self) -> str:
        return f"HostMaps({len(self)} maps)"


def _grey(img: np.ndarray, name: str) -> np.ndarray:
    """Grey float32 image on the 0-255 scale from a raw image array."""
    arr = np.asarray(img)
    if arr.ndim not in (2, 3) or arr.size == 0:
        raise InputError(f"{name} image: expected a non-empty (H, W) or (H, W, C) array, got shape {arr.shape}; pass an image")
    if arr.dtype.kind == "f" and not np.isfinite(arr).all():
        raise InputError(f"{name} image: contains NaN or inf values; pass finite intensities")
    return to_grey(arr)


def _narrowest(raw, grey: np.ndarray) -> np.ndarray:
    """The image to hand to ``backend.pyramid``: ``raw`` itself when it is a uint8 grey
    image (the same values as ``grey``, a quarter of its bytes to upload), else ``grey``."""
    arr = np.asarray(raw)
    if arr.dtype == np.uint8 and arr.shape[:2] == grey.shape and (arr.ndim == 2 or arr.shape[2:] == (1,)):
        return arr.reshape(grey.shape)
    return grey


def _float_images_scaled(left, right):
    """Two float images on the 0-255 scale, by the rule float image files follow
    (:func:`d3cli.data.layouts.normalise_bit_depth`): [0, 1] (scikit-image's convention)
    times 255, up to 255 unchanged, larger values as integer counts; negative values are
    an InputError.  Taken as 0-255 unchanged, [0, 1] images would give a far worse map
    with only "no decisive seeds" as a hint.  Other dtypes, or one float view, are unchanged.
    """
    arrays = [np.asarray(left), np.asarray(right)]
    if any(arr.dtype.kind != "f" or arr.size == 0 for arr in arrays):
        return left, right
    for arr, name in zip(arrays, ("left", "right")):
        if not np.isfinite(arr).all():
            raise InputError(f"{name} image: contains NaN or inf values; pass finite intensities")
    scaled_l, scaled_r, _ = normalise_bit_depth(*arrays, where="pair")
    return scaled_l, scaled_r


def _as_0_255(img) -> np.ndarray:
    """A raw image as float32 on the 0-255 scale, channels kept (the networks want colour)."""
    arr = np.asarray(img)
    if arr.dtype == np.uint16:
        return arr.astype(np.float32) / np.float32(257.0)
    return arr.astype(np.float32)


#: The per-level statistics that are counts (read from the device together).
_COUNT_KEYS = ("seeds", "inherited", "decided", "sweeps", "band_cells")


def _count_keys(per_level: list[dict]) -> list[tuple[dict, str]]:
    """``(stats, key)`` of every count of the levels' statistics."""
    return [(stats, key) for stats in per_level for key in _COUNT_KEYS if key in stats]


@dataclass
class _Match:
    """What :meth:`D3Stereo._match` leaves for the next step (backend arrays)."""

    disparity: object  # int32 (H, W), -1 undecided
    cost: object  # Volume, aggregated (the visible bands)
    level_maps: list
    per_level: list
    range_ends: int | None = None  # pixels at an end of the narrow range (a narrow match only)
    counts_read: bool = True  # False: the levels' counts are still on the device (_finish reads them)


def _border_start(max_disparity: int, width: int) -> int:
    """First column the left-border test searches (``refinement.drop_occluded``'s start)."""
    start = min(int(max_disparity), width - 1)
    return max(start + width, 0) if start < 0 else start


def fallback_settings(cfg: Config) -> Config | None:
    """The settings a pair that is not a road is matched with: the bundled config
    ``pt.fallback_config`` names, its perspective transformation off, with ``cfg``'s run
    section (backend, threads); None when ``cfg`` has no PT or no fallback config."""
    if not (cfg.pt.enabled and cfg.pt.fallback_config):
        return None
    other = load_config(cfg.pt.fallback_config)
    return dataclasses.replace(other, run=cfg.run, pt=dataclasses.replace(other.pt, enabled=False))


def d3stereo_disparity(left: np.ndarray, right: np.ndarray, *, max_disparity: int, cfg: Config,
                       pair_dir: str | os.PathLike | None = None) -> DisparityResult:
    """The entry point of ``--method d3stereo`` (:data:`d3cli.config.methods.METHOD_SPECS`):
    :meth:`D3Stereo.compute` with ``cfg``.

    Parameters
    ----------
    left, right : ndarray, (H, W) or (H, W, C)
        Rectified images (see :meth:`D3Stereo.compute`).
    max_disparity : int, keyword-only
        Largest disparity searched at full resolution.
    cfg : Config, keyword-only
        Resolved configuration.
    pair_dir : path-like, optional, keyword-only
        The pair's folder: a relative ``features.npz`` is looked up there.

    Returns
    -------
    DisparityResult
    """
    return D3Stereo(cfg).compute(left, right, max_disparity=max_disparity, pair_dir=pair_dir)


class D3Stereo:
    """The D3Stereo stereo matcher (NCC + RBF + decisive diffusion/inheritance).

    Parameters
    ----------
    cfg : Config, optional
        Resolved configuration (:func:`d3cli.load_config`); defaults when omitted.

    Examples
    --------
    >>> from d3cli import D3Stereo, load_config
    >>> result = D3Stereo(load_config()).compute(left, right, max_disparity=64)  # doctest: +SKIP
    """

    def __init__(self, cfg: Config | None = None) -> None:
        self.cfg = cfg if cfg is not None else Config()
        self.backend: Backend
        self.backend, self.backend_name = get_backend(self.cfg.run.backend)

    def compute(self, left: np.ndarray, right: np.ndarray, *, max_disparity: int | None = None,
                pair_dir: str | os.PathLike | None = None) -> DisparityResult:
        """Estimate the left-view disparity map of a rectified pair.

        Parameters
        ----------
        left, right : ndarray, (H, W) or (H, W, C), any integer or float dtype
            Rectified images; left (u, v) matches right (u - d, v) with d >= 0.  uint16
            is divided by 257; two float views are read as float image files are:
            values in [0, 1] scaled to 0-255, up to 255 as they are, larger ones as
            integer counts of the smallest bit depth that holds them.
        max_disparity : int, optional, keyword-only
            Largest disparity searched at full resolution; default ``cfg.run.max_disparity``
            or, if that is unset, ``W // 4``.
        pair_dir : path-like, optional, keyword-only
            The pair's folder: a relative ``features.npz`` is looked up there.

        Returns
        -------
        DisparityResult
            float32 disparity (sub-pixel; filled unless ``refine.fill`` is false, in which
            case undecided pixels are inf), validity mask, per-level maps, timings, info.

        Raises
        ------
        InputError
            Shapes differ, an image is empty, not finite or (float) negative, or
            max_disparity is not in [1, W - 1].
        """
        cfg = self.cfg
        timings: dict[str, float] = {}
        t_start = time.perf_counter()
        given = (left, right)  # for a fallback with other settings (pt.fallback_config)
        left, right = _float_images_scaled(left, right)
        grey_l, grey_r, dmax = self._prepare(left, right, max_disparity)
        levels = usable_levels(grey_l.shape, cfg.pyramid.levels)
        backend = self.backend
        # One upload of each image (a uint8 grey image in its own bytes); the pyramid is
        # built on the backend, and everything below stays there.
        pyr_l = backend.pyramid(_narrowest(left, grey_l), levels)
        pyr_r = backend.pyramid(_narrowest(right, grey_r), levels)
        timings["pyramid"] = time.perf_counter() - t_start

        info: dict = {"backend": self.backend_name, "levels": levels, "max_disparity": dmax}
        warnings: list[str] = []
        road = None
        search = dmax
        plain_r = pyr_r  # the unwarped right pyramid, for a fallback after the narrow match
        if cfg.pt.enabled:
            road, pyr_r, search = self._perspective(pyr_l, pyr_r, dmax, timings, info, warnings)
            if road is None and cfg.pt.fallback_config:
                return self._fallback(given, dmax, pair_dir, timings, info, warnings, t_start)
        features = self._pair_features(left, right, grey_l.shape, pyr_l, pair_dir, road, timings, info)
        # the levels' counts are read with the finishing's (one copy), except where the road
        # check needs them first
        match = self._match(pyr_l, pyr_r, search, timings, features=features,
                            range_ends=None if road is None else cfg.pt.narrow_range, read_counts=road is not None)
        if road is not None and self._band_share(match) > REFIT_SHARE * cfg.pt.max_band_end_share:
            # Many pixels at the band's ends: first the plane fitted again to the match
            # inside the band (the coarse fit may have tilted it), and the pair matched
            # again against it (refit_on_band).
            road, pyr_r, match, features = self._refit(road, match, (pyr_l, pyr_r, plain_r), features, search,
                                                       (left, right, grey_l.shape), pair_dir, timings, info)
        if road is not None and not self._on_road_band(match, road, dmax, info, warnings):
            # Not a road after all: the pair is matched again over the full range, unwarped.
            road, search, match, features = None, dmax, None, None
            if cfg.pt.fallback_config:
                return self._fallback(given, dmax, pair_dir, timings, info, warnings, t_start)
            features = self._pair_features(left, right, grey_l.shape, pyr_l, pair_dir, None, timings, info)
            match = self._match(pyr_l, plain_r, search, timings, features=features, read_counts=False)
        info["per_level"] = match.per_level
        t0 = time.perf_counter()
        out, valid = self._finish(match, dmax, info, road=road)
        timings["finish"] = time.perf_counter() - t0
        if match.per_level[0].get("seeds", 0) == 0:  # read by _finish
            warnings.append(
                "no decisive seeds at the coarsest level (textureless or unrectified pair?); "
                "the disparity map is all invalid"
            )
        timings["total"] = time.perf_counter() - t_start
        return DisparityResult(
            disparity=out,
            valid=valid,
            levels=HostMaps(match.level_maps, backend.to_host),
            timings=timings,
            info=info,
            warnings=warnings,
        )

    def _prepare(self, left, right, max_disparity):
        """Grey float32 images of equal shape and the checked full-resolution range."""
        grey_l = _grey(left, "left")
        grey_r = _grey(right, "right")
        if grey_l.shape != grey_r.shape:
            raise InputError(
                f"pair: left is {grey_l.shape[0]}x{grey_l.shape[1]} but right is "
                f"{grey_r.shape[0]}x{grey_r.shape[1]}; a stereo pair needs equal sizes"
            )
        w = grey_l.shape[1]
        dmax = max_disparity if max_disparity is not None else self.cfg.run.max_disparity
        if dmax is None:
            dmax = max(1, w // 4)
        if not 1 <= int(dmax) <= w - 1:
            raise InputError(
                f"pair: max disparity {dmax} is outside [1, {w - 1}] for an image {w} px wide; "
                f"pass --max-disparity in that range"
            )
        return grey_l, grey_r, int(dmax)

    def _pair_features(self, left, right, shape, pyr_l, pair_dir, road, timings: dict, info: dict):
        """The feature pyramid of the pair (``cost.kind: features``; None otherwise), from
        the right image warped by ``road`` when there is one."""
        cfg = self.cfg
        if cfg.cost.kind != "features":
            return None
        t0 = time.perf_counter()
        shapes = [tuple(p.shape) for p in pyr_l]
        if cfg.features.npz:
            features = self._npz_features(shape, shapes, pair_dir, road)
        else:
            features = self._features(left, right if road is None else self._warped_right(right, road), shapes)
        timings["features"] = timings.get("features", 0.0) + time.perf_counter() - t0
        info["feature_levels"] = [level + 1 for level, f in enumerate(features) if f is not None]
        return features

    def _fallback(self, given, dmax: int, pair_dir, timings: dict, info: dict, warnings: list,
                  t_start: float) -> DisparityResult:
        """A pair that is not a road, matched over the full range with the settings of the
        bundled config ``pt.fallback_config`` (its perspective transformation off, this
        run's backend); the road fit's timings, ``info['pt']`` and warnings kept.

        The road settings are chosen for a camera looking down at a road; on other scenes
        they cost accuracy even over the full range (the Motorcycle sample: EPE 1.734 px
        with configs/road.yaml's, 0.910 with default.yaml's).
        """
        cfg = self.cfg
        left, right = given
        result = D3Stereo(fallback_settings(cfg)).compute(left, right, max_disparity=dmax, pair_dir=pair_dir)
        result.info["pt"] = info["pt"] | {"fallback_config": cfg.pt.fallback_config}
        result.warnings[:0] = warnings
        result.timings.update({k: v for k, v in timings.items() if k.startswith("pt_")})
        result.timings["total"] = time.perf_counter() - t_start  # the road attempt included
        return result

    def _band_share(self, match: "_Match") -> float:
        """The share of all pixels matched at an end of the narrow range
        (:func:`~d3cli.method.perspective.band_end_share`), from the count the match read
        with its others."""
        h, w = match.disparity.shape
        return float(match.range_ends) / max(h * w, 1)

    def _refit(self, road: RoadModel, match: "_Match", pyramids: tuple, features, search: int, images: tuple,
               pair_dir, timings: dict, info: dict):
        """The road model fitted again to ``match`` (:func:`~d3cli.method.perspective.refit_on_band`)
        and the pair matched against it; ``(road, pyr_r, match, features)``: the refitted
        ones where their match puts fewer pixels at the band's ends, else the given ones
        (the band test then decides on the first match).

        ``pyramids``: the left pyramid, the right one warped by ``road`` and the unwarped
        right one; ``images``: the left and right images and the grey shape (features).

        Where the refit is kept, ``info['pt']`` holds its model, ``refit`` True and the first
        model's band-end share (``first_band_end_share``)."""
        pt = self.cfg.pt
        t0 = time.perf_counter()
        first_share = self._band_share(match)
        pyr_l, pyr_r, plain_r = pyramids
        levels = len(pyr_l)
        refit = refit_on_band(self.backend.to_host(match.disparity), road, margin=float(pt.margin),
                              narrow_range=pt.narrow_range, scale=2 ** (levels - 1), iterations=pt.iterations,
                              min_inlier_share=pt.min_inlier_share)
        if not refit.road_like:
            return road, pyr_r, match, features
        log.info("PT: %.1f%% of the pixels at the band's ends; plane fitted again to the band: d = %.3f + %.5f v + "
                 "%.5f u", 100 * first_share, refit.a0, refit.b1, refit.b2)
        warped = self.backend.pt_warp(plain_r[0], refit.a0, refit.b1, refit.b2, float(pt.margin))
        refit_r = self.backend.pyramid(warped, levels)
        left, right, shape = images
        refit_features = self._pair_features(left, right, shape, pyr_l, pair_dir, refit, timings, info)
        timings["pt_refit"] = time.perf_counter() - t0
        again = self._match(pyr_l, refit_r, search, timings, features=refit_features, range_ends=pt.narrow_range,
                            read_counts=True)
        again_share = self._band_share(again)
        if again_share >= first_share:
            log.info("PT: the refitted plane puts %.1f%% at the band's ends; the first one kept", 100 * again_share)
            return road, pyr_r, match, features
        info["pt"] = refit.to_info(narrow_range=pt.narrow_range) | {"refit": True, "first_band_end_share": first_share}
        return refit, refit_r, again, refit_features

    def _on_road_band(self, match: "_Match", road: RoadModel, dmax: int, info: dict, warnings: list) -> bool:
        """Whether the narrow-range match keeps the road model (:meth:`RoadModel.off_band`).

        False, with the fallback in ``info['pt']`` (``band_end_share`` the measured share)
        and its warning in ``warnings``, when more than ``pt.max_band_end_share`` of the
        pixels are matched at an end of the narrow range.
        """
        pt = self.cfg.pt
        share = self._band_share(match)
        checked = road.off_band(share, limit=pt.max_band_end_share, margin=pt.margin)
        if checked.road_like:  # the share is recorded as range_end_share by _pt_valid
            return True
        info["pt"] = info["pt"] | checked.to_info(narrow_range=pt.narrow_range) | {"band_end_share": share}
        msg = checked.fallback_warning(dmax, settings=pt.fallback_config)
        log.debug(msg)  # returned in result.warnings; the batch logs those once
        warnings.append(msg)
        return False

    def _features(self, left, right, shapes):
        """Feature pyramid of the pair (step 2 with deep features), finest level first."""
        return feature_pyramid(_as_0_255(left), _as_0_255(right), shapes, self.cfg.features)

    def _npz_features(self, image_shape, shapes, pair_dir, road):
        """Feature pyramid from the precomputed ``features.npz`` (finest level first)."""
        path = npz_path(self.cfg.features.npz, pair_dir)
        if road is not None:
            raise InputError(f"{path}: precomputed features cannot follow the perspective transformation (the "
                             "right features must come from the warped image); use features.model or pt.enabled: false")
        return load_feature_npz(path, tuple(image_shape), shapes)

    def _warped_right(self, right, road: RoadModel):
        """The right image warped by the road model, every channel (PT with features).

        Features are extracted again from the warped image (step 6 with deep features):
        warping feature maps instead would blur them across the stride of coarse taps.
        """
        img = _as_0_255(right)
        pt = self.cfg.pt
        channels = [img] if img.ndim == 2 else [img[:, :, c] for c in range(img.shape[2])]
        warped = [host.pt_warp(np.ascontiguousarray(c, np.float32), road.a0, road.b1, road.b2, float(pt.margin))
                  for c in channels]
        return warped[0] if img.ndim == 2 else np.stack(warped, axis=2)

    def _match(self, pyr_l, pyr_r, dmax: int, timings: dict, *, stop_level: int = 0,
               features=None, range_ends: int | None = None, read_counts: bool = True) -> "_Match":
        """Steps 2-5 and 7 over the pyramid, coarsest level first (paper Fig. 1).

        Parameters
        ----------
        pyr_l, pyr_r : list of backend float32 (H_i, W_i) arrays, finest first
        dmax : int
            Largest disparity at full resolution; level i searches ceil(dmax / 2^i).
        timings : dict
            Seconds per step are added to it.
        stop_level : int
            Finest level to compute (0 = full resolution); the perspective transformation
            stops at the coarsest level.
        range_ends : int, optional
            The narrow range of a match against the warped right image: the pixels matched
            at its ends are counted (``_Match.range_ends``) with the levels' counts.
        read_counts : bool
            False: counts left on the device stay there (no copy; the levels are not
            logged), for a pass whose statistics nobody reads (the road fit's coarse pass)
            or that :meth:`_finish` reads with its own counts (``_Match.counts_read``).

        Returns
        -------
        _Match
            Integer map and aggregated cost volume of ``stop_level`` (backend arrays), the
            per-level maps (finest first) and per-level statistics (coarsest first).
        """
        levels = len(pyr_l)
        per_level: list[dict] = []
        level_maps: list = []
        disp = None
        cost = None
        for level in range(levels - 1, stop_level - 1, -1):
            disp, cost, stats = self._match_level(pyr_l[level], pyr_r[level], disp, level=level,
                                                  coarsest=level == levels - 1, dmax=dmax, stop_level=stop_level,
                                                  features=None if features is None else features[level])
            for key in ("cost", "sgm", "decide", "diffusion"):
                if "time_" + key in stats:  # sgm: where the semi-global smoothing runs
                    timings[key] = timings.get(key, 0.0) + stats["time_" + key]
            per_level.append(stats)
            level_maps.insert(0, disp)
            if level > stop_level:
                cost = None  # free the coarse volume before the next, larger one
        extra = [] if range_ends is None else [self.backend.count_range_ends(disp, range_ends)]
        counts_read = read_counts or all(isinstance(s[k], (int, np.integer))
                                         for s in per_level for k in _COUNT_KEYS if k in s)
        if counts_read:
            extra = self._read_counts(per_level, extra)
        return _Match(disparity=disp, cost=cost, level_maps=level_maps, per_level=per_level,
                      range_ends=extra[0] if extra else None, counts_read=counts_read)

    def _read_counts(self, per_level: list[dict], extra=()) -> list[int]:
        """Turn every level's counts into ints, all at once, and log the levels; returns
        ``extra`` (more counts, read with them) as ints.

        On CUDA the counts (seeds, inherited and decided pixels, sweeps, band cells) stay on the device
        while the levels run, so that no level waits for a copy to the host; they are read
        here together (``backend.counts_to_host``: one copy).
        """
        keys = _count_keys(per_level)
        values = self.backend.counts_to_host([s[k] for s, k in keys] + list(extra))
        for (stats, key), value in zip(keys, values):
            stats[key] = value
        for stats in per_level:
            shape = stats["shape"]
            stats["decided_share"] = stats.pop("decided") / float(shape[0] * shape[1])
            coarsest = "inherited" not in stats
            log.debug(
                "level %d %s: %s %d, %d sweeps, %.1f%% decided; cost %.3fs, %s %.3fs, diffusion %.3fs",
                stats["level"],
                "x".join(map(str, shape)),
                "seeds" if coarsest else "inherited",
                stats.get("seeds", stats.get("inherited", 0)),
                stats["sweeps"],
                100 * stats["decided_share"],
                stats["time_cost"],
                "seeds" if coarsest else "inheritance",
                stats["time_decide"],
                stats["time_diffusion"],
            )
        return values[len(keys):]

    def _match_level(self, left, right, coarser, *, level: int, coarsest: bool, dmax: int, stop_level: int,
                     features):
        """One level of :meth:`_match`: cost, seeds or inheritance, diffusion.

        ``coarser``: the integer map of the level above (None at the coarsest level).
        Returns ``(disparity, cost volume, statistics)`` of this level.
        """
        cfg = self.cfg
        backend = self.backend
        shape = tuple(left.shape)
        stats: dict = {"level": level + 1, "shape": list(shape)}
        t0 = time.perf_counter()
        bands = None
        if coarser is not None and cfg.pyramid.band:
            bands = backend.band_indexes(coarser, shape, n_disp=level_max_disparity(dmax, level) + 1,
                                         margin=cfg.pyramid.band_margin, tile=cfg.level_band_tile(level),
                                         halo=aggregation_halo(cfg, level))
            stats["band_cells"] = bands[2]
        cost = level_cost(left, right, level=level, max_disparity=dmax, cfg=cfg, backend=backend,
                          features=features, bands=bands, step_times=stats)
        t1 = time.perf_counter()
        disp = self._decide(cost, coarser, stats, coarsest=coarsest)
        t2 = time.perf_counter()
        sweeps = 0
        if cfg.pyramid.ars or level == stop_level:
            disp, sweeps = diffuse(
                cost,
                disp,
                max_gap=cfg.diffusion.max_gap,
                tau=cfg.diffusion.tau,
                kappa_d=cfg.diffusion.kappa_d,
                adversarial=cfg.diffusion.adversarial,
                max_sweeps=cfg.diffusion.max_sweeps,
                backend=backend,
            )
        t3 = time.perf_counter()
        stats.update(  # counts may still be on the device: _read_counts makes them ints
            sweeps=sweeps,
            decided=backend.count_decided(disp),
            time_cost=t1 - t0 - stats.get("time_sgm", 0.0),  # the smoothing is a step of its own
            time_decide=t2 - t1,
            time_diffusion=t3 - t2,
        )
        return disp, cost, stats

    def _decide(self, cost, coarser, stats: dict, *, coarsest: bool):
        """The decided pixels before diffusion: seeds at the coarsest level, below it the
        inherited disparities of ``coarser`` (plus fresh seeds where configured); counts
        go into ``stats``."""
        cfg = self.cfg
        backend = self.backend
        if coarsest:
            disp = self._seeds(cost)
            stats["seeds"] = backend.count_decided(disp)
            return disp
        disp = inherit(
            cost,
            coarser,
            prc=cfg.inheritance.prc,
            dfm_pkrn_min=cfg.inheritance.dfm_pkrn_min,
            epsilon=cfg.seeds.epsilon,
            backend=backend,
            candidates=cfg.inheritance.candidates,
        )
        stats["inherited"] = backend.count_decided(disp)
        if cfg.seeds.every_level and cfg.pyramid.ars:
            # (the linear structure, ars false, has seeds at the coarsest level only)
            # inherited disparities win; fresh seeds cover what inheritance left
            seeds = self._seeds(cost, skip=disp)
            disp = backend.merge_sparse(disp, seeds)
            stats["seeds"] = backend.count_decided(seeds)
        return disp

    def _seeds(self, cost, *, skip=None):
        """Decisive seeds of a level (step 4) with the configured tests; ``skip`` as in
        :func:`decisive_seeds`."""
        seeds = self.cfg.seeds
        return decisive_seeds(cost, pkrn_min=seeds.pkrn_min, epsilon=seeds.epsilon, lr_tolerance=seeds.lr_tolerance,
                              exclusion=seeds.pkrn_exclusion, backend=self.backend, skip=skip)

    def _perspective(self, pyr_l, pyr_r, dmax: int, timings: dict, info: dict, warnings: list):
        """Step 6: full-range pass at the coarsest level, robust road fit, warped right.

        Returns
        -------
        model : RoadModel or None
            The fitted road model; None when the scene is not road-like (fallback).
        pyr_r : list of backend arrays
            Pyramid of the warped right image (the input pyramid on fallback).
        search : int
            Full-resolution range to match: ``2 margin + slack``, or ``dmax`` on fallback.
        """
        pt = self.cfg.pt
        backend = self.backend
        levels = len(pyr_l)
        t0 = time.perf_counter()
        coarse = self._match(pyr_l, pyr_r, dmax, {}, stop_level=levels - 1, read_counts=False)
        # small: 1/4^(k-1) of the image, downloaded as int8 where the level's range allows
        # (the same values, a quarter of the bytes)
        coarse_map = backend.small_ints_to_host(coarse.disparity, level_max_disparity(dmax, levels - 1))
        del coarse
        t1 = time.perf_counter()
        model = fit_road_model(
            coarse_map,
            scale=2 ** (levels - 1),
            inlier_threshold=pt.inlier_threshold,
            iterations=pt.iterations,
            min_inlier_share=pt.min_inlier_share,
        )
        t2 = time.perf_counter()
        timings["pt_coarse"] = t1 - t0
        timings["pt_fit"] = t2 - t1
        narrow = pt.narrow_range
        info["pt"] = model.to_info(narrow_range=narrow)
        if not model.road_like:
            msg = model.fallback_warning(dmax, settings=pt.fallback_config)
            log.debug(msg)  # returned in result.warnings; the batch logs those once
            warnings.append(msg)
            return None, pyr_r, dmax
        log.info(
            "PT: d = %.3f + %.5f (v cos %.2f deg - u sin %.2f deg), %.1f%% inliers of %d; range 0-%d",
            model.a0, model.a1, info["pt"]["theta_deg"], info["pt"]["theta_deg"],
            100 * model.inlier_share, model.n_points, narrow,
        )
        # pyr_r[0] is the full-resolution right image, already on the backend
        warped = backend.pt_warp(pyr_r[0], model.a0, model.b1, model.b2, float(pt.margin))
        pyr_r = backend.pyramid(warped, levels)
        timings["pt_warp"] = time.perf_counter() - t2
        return model, pyr_r, narrow

    def _pt_restore(self, disp_f, road: RoadModel):
        """Full-range disparity ``d' (1 - b2) + s(u, v)`` of a backend float32 map."""
        return self.backend.pt_restore(disp_f, road.a0, road.b1, road.b2, float(self.cfg.pt.margin))

    def _finish(
        self, match: "_Match", dmax: int, info: dict, *, road: RoadModel | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Step 8: sub-pixel refinement, occlusion check, hole filling; host arrays.

        With a road model (step 6) the disparity is restored to the full range first, and
        on the backend estimates at the ends of the narrow range (the true match probably
        lies outside it: not road) and estimates whose match falls left of the right image
        become holes (``backend.pt_validity``: the map and the validity come back masked).
        On a device backend the occlusion check, the speckle filter, the filling with its
        median and the smoothing run there too (:meth:`_finish_on_backend`), before the one
        download of the map, the validity and the counts.
        """
        cfg = self.cfg
        backend = self.backend
        if cfg.refine.subpixel:
            sub = refine_subpixel(match.cost, match.disparity, backend=backend,
                                  equiangular=cfg.equiangular_subpixel)
        # The volume's last reader was the sub-pixel step: release it before the host
        # finishing allocates its own maps (the peak of a 720p road pair).
        match.cost = None
        if cfg.refine.subpixel and not isinstance(sub, np.ndarray):
            return self._finish_on_backend(match, sub, dmax, info, road)
        if not match.counts_read:
            self._read_counts(match.per_level)
            match.counts_read = True
        restored = False  # the road model's validity applied on the backend
        if cfg.refine.subpixel:
            if road is not None:
                sub = self._pt_restore(sub, road)
                kept, sub, counts = backend.pt_validity(match.disparity, sub, self.cfg.pt.narrow_range)
                restored = True
            out = backend.to_host(sub)
            disp = None
        else:
            disp = backend.to_host(match.disparity)
            out = np.where(disp >= 0, disp, np.inf).astype(np.float32)
            if road is not None:
                out = backend.to_host(self._pt_restore(backend.to_device(out), road))
        if restored:
            valid = backend.to_host(kept)
            info["pt"].update(restored_shares(backend.counts_to_host(counts), valid.size))
        elif disp is not None:
            valid = disp >= 0
        else:
            valid = backend.to_host(backend.decided_mask(match.disparity))
        # Peak memory: each test below makes its holes in one pass (valid in place, the map
        # masked into ``out``); ``owned``: ``out`` is this method's own map, written in place.
        owned = restored
        if road is not None and not restored:
            valid, out = self._pt_valid(valid, disp, out, info)
            owned = True
        return self._finish_on_host(out, valid, owned, dmax, info, road)

    def _finish_on_backend(self, match: "_Match", sub, dmax: int, info: dict, road: RoadModel | None):
        """:meth:`_finish` of a sub-pixel map on a device: the road model's validity, the
        occlusion check (``backend.drop_occluded``), the speckle filter
        (``backend.drop_speckles``), the filling (``backend.fill_rows``, or
        ``backend.fill_inside`` with the occluded pixels, and the median of the filled
        pixels, ``backend.median_of_holes``) and the smoothing (``backend.smooth_map``, the
        road plane from its coefficients) run on the device, in the order and with the
        values of :meth:`_finish_on_host`; then one download of the map, the validity and
        every count (the levels', the road model's, the occluded and the speckle pixels)
        together (``backend.outputs_to_host``)."""
        cfg = self.cfg
        refine = cfg.refine
        backend = self.backend
        pending = []
        if road is not None:
            sub = self._pt_restore(sub, road)
            valid, sub, pt_counts = backend.pt_validity(match.disparity, sub, cfg.pt.narrow_range)
            pending += list(pt_counts)
        else:
            valid = backend.decided_mask(match.disparity)
        shares = {}  # info key -> index of its count in pending
        occluded = None
        if refine.occlusion_check:
            # sub is this method's own map: masked in place
            occluded, count = backend.drop_occluded(sub, valid, 1.0, _border_start(dmax, sub.shape[1]), sub)
            shares["occluded_share"] = len(pending)
            pending.append(count)
        if refine.speckle_size > 0:
            count = backend.drop_speckles(sub, valid, refine.speckle_size, refine.speckle_range, sub)
            shares["speckle_share"] = len(pending)
            pending.append(count)
        if refine.fill:
            if refine.fill_inside and occluded is not None:
                sub, use = backend.fill_inside(sub, valid, occluded)
            else:
                sub, use = backend.fill_rows(sub, valid)
            if refine.smooth_filled and min(sub.shape) >= 5:
                sub = backend.median_of_holes(sub, use)
        if refine.smooth_radius > 0:
            # the range weight compares residuals from the road plane when there is one
            plane = None if road is None else (road.a0, road.b1, road.b2)
            sub = backend.smooth_map(sub, refine.smooth_radius, refine.smooth_sigma, refine.smooth_kernel, plane, True)
        # one download of whatever map and validity the device steps above leave, with
        # every count not read yet (the levels' too): on CUDA one copy of one packed buffer
        unread = [] if match.counts_read else [s[k] for s, k in _count_keys(match.per_level)]
        out, valid, values = backend.outputs_to_host(sub, valid, pending + unread)
        values = values[:len(pending)]
        if not match.counts_read:
            self._read_counts(match.per_level)  # read with the outputs: no copy
            match.counts_read = True
        if road is not None:
            info["pt"].update(restored_shares(values[:3], valid.size))
        for key, i in shares.items():
            info[key] = values[i] / valid.size
        return self._finish_on_host(out, valid, True, dmax, info, road, occlusion=False, speckles=False, fill=False,
                                    smooth=False)

    def _finish_on_host(self, out: np.ndarray, valid: np.ndarray, owned: bool, dmax: int, info: dict,
                        road: RoadModel | None, *, occlusion: bool = True, speckles: bool = True,
                        fill: bool = True, smooth: bool = True):
        """The host part of :meth:`_finish`: the occlusion check, the speckles, the
        filling and the smoothing (each unless its flag is False: done on the backend) of a
        host map and its validity (``owned``: ``out`` may be written in place)."""
        cfg = self.cfg
        occluded = None
        if occlusion and cfg.refine.occlusion_check:
            occluded, count, out = drop_occluded(out, valid, max_disparity=dmax, out=out if owned else None)
            owned = True
            info["occluded_share"] = count / valid.size
        if speckles and cfg.refine.speckle_size > 0:
            count, out = drop_speckles(out, valid, max_size=cfg.refine.speckle_size,
                                       max_diff=cfg.refine.speckle_range, out=out if owned else None)
            owned = True
            info["speckle_share"] = count / valid.size
        if fill and cfg.refine.fill:
            out = fill_holes(
                out, valid, smooth=cfg.refine.smooth_filled, occluded=occluded if cfg.refine.fill_inside else None
            )
        if smooth and cfg.refine.smooth_radius > 0:
            # edge-preserving smoothing of the finished map, every finite pixel used; the
            # range weight compares residuals from the road plane when there is one (a
            # slanted road is no edge).  Averaging residuals to a plane that dips below zero
            # (far road, sky) can end a hair below 0; disparities are >= 0 by contract
            # (non_negative: set to 0 in the smoothing's last pass).  The same call as a
            # device backend's (backend.smooth_map), on the host.
            plane = None if road is None else (road.a0, road.b1, road.b2)
            out = host.smooth_map(out, cfg.refine.smooth_radius, cfg.refine.smooth_sigma, cfg.refine.smooth_kernel,
                                  plane, True)
        info["decided_share"] = int(np.count_nonzero(valid)) / valid.size
        return np.ascontiguousarray(out, dtype=np.float32), valid

    def _pt_valid(self, valid: np.ndarray, disp: np.ndarray, out: np.ndarray, info: dict):
        """Validity after PT (:func:`restored_validity`) and ``np.where(valid, out, inf)``,
        from one pass (no extra full-size map); the shares go to ``info['pt']``.  Returns ``(valid,
        masked_map)``."""
        valid, counts, out = restored_validity_counts(valid, disp, out, narrow_range=self.cfg.pt.narrow_range,
                                                     masked=True)
        info["pt"].update(restored_shares(counts, valid.size))
        return valid, out
