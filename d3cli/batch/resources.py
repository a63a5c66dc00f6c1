"""Resource limits: estimate a pair's peak memory before allocating anything big.

A 3,000-pair batch should not die in the middle of pair 1,742 because one pair is
larger than the rest: :func:`check_memory` turns "this would need 90 GB" into a per-pair
:class:`~d3cli.errors.InputError` that names the estimate and the fix, before the cost
volume is allocated.

The estimate models the pipeline's peak (cost, aggregation, seeds and diffusion;
docs/design.md, 'Cost volumes'), which is reached at the finest level (level 1):

* cost volumes: float32 ``(H, W, D + 1)``, the worst case of the band search (a band
  can be the full range); RBF filters the NCC volume in place (1 volume), the plain
  bilateral filter also needs its output volume (2);
* the RBF weights: float32 ``(H, W, 9)``;
* with ``cost.kind: features``: the feature maps of both views at every level, float32
  ``(H / 2^i, W / 2^i, C_i + 1)`` (vectors and norms), twice (the model's raw outputs and
  the normalised copies); C_i from ``features.npz``'s headers or the model's output
  shapes (:func:`d3cli.method.features.feature_channels`);
* per-pixel maps: grey images and their pyramids, the integer disparity maps and the
  diffusion's frontier arrays (int32 lists), the band indexes (two int32 ``(H, W, 3)``),
  min-cost, sub-pixel and output maps.

SGBM (``sgbm``, ``pt-sgm``) holds OpenCV's int16 path buffers: for the full-DP modes
(``hh``, ``hh4``) a cost and a sum volume ``(H, W, D16)`` each, for ``sgbm``/``3way`` a
few rows of them.
"""

from __future__ import annotations

import logging
import math
import os

from ..config import Config
from ..errors import InputError, where_what_fix
from ..method.features import feature_bytes, feature_channels

log = logging.getLogger(__name__)

#: Bytes per pixel of the per-pixel maps of the d3stereo pipeline: 2 raw images
#: (worst case 3 x uint16 = 6 B each), 2 grey float32 images with pyramids (x 4/3),
#: disparity int32 double buffer, seeds int32, min cost float32, diffusion's changed,
#: stamp and active int32 lists, new values int32, the stored and visible band indexes
#: (2 x 3 int32) and the uniform-band mask, sub-pixel float32, valid/occluded bool,
#: output float32 and its filled copy.
D3_BYTES_PER_PIXEL = 12 + 2 * 4 * 4 / 3 + 8 + 4 + 4 + 3 * 4 + 4 + 2 * 12 + 1 + 4 + 2 + 8
#: Bytes per pixel around OpenCV SGBM: raw images, grey float32 and uint8, int16
#: disparity, float32 disparity and filled copy, valid mask, index maps of the filling.
SGBM_BYTES_PER_PIXEL = 12 + 2 * (4 + 1) + 2 + 2 * 4 + 1 + 4 * 8
#: Bytes per pixel around libelas: 8-bit images, two 16-byte descriptor images, two float
#: disparity maps, the support grid and the filled copy (a generous bound).
ELAS_BYTES_PER_PIXEL = 2 + 2 * 16 + 2 * 4 + 16 + SGBM_BYTES_PER_PIXEL
#: Rows of SGBM path buffers kept by the one-pass modes (a generous bound).
SGBM_BUFFER_ROWS = 16
#: Share of the physical memory used as the limit when run.max_memory_gb is unset.
DEFAULT_RAM_SHARE = 0.75
GB = 1e9


def _sgbm_disparities(max_disparity: int) -> int:
    """OpenCV's numDisparities: a multiple of 16 covering 0..max_disparity."""
    return int(math.ceil((max_disparity + 1) / 16.0)) * 16


def _d3_volume_bytes(cfg: Config, pixels: int, n_disp: int) -> int:
    """Bytes of the float32 cost volumes alive at once at the finest level.

    RBF filters the raw NCC volume in place, row strip by row strip (one volume and a
    few rows); the plain bilateral filter holds the NCC volume and its output.  The
    full range is assumed (the band search can fall back to it).
    """
    volume = pixels * n_disp * 4
    agg = cfg.aggregation
    if agg.rbf:
        return volume
    return 2 * volume if agg.kappa_a > 0 else volume


def estimate_peak_bytes(shape, max_disparity: int, cfg: Config, *, method: str) -> int:
    """Estimated peak memory of computing one pair.

    Parameters
    ----------
    shape : sequence of int
        ``(H, W)`` (or ``(H, W, C)``) of the full-resolution images, pixels.
    max_disparity : int
        Largest disparity searched at full resolution, pixels (the volume has
        ``max_disparity + 1`` slices).
    cfg : Config
        Resolved configuration (aggregation settings change the number of volumes).
    method : {"d3stereo", "sgbm", "pt-sgm", "elas", "pandora-sgm"}, keyword-only

    Returns
    -------
    int
        Bytes; an upper estimate of the largest simultaneous allocation, not counting
        the Python interpreter and the libraries themselves.
    """
    height, width = int(shape[0]), int(shape[1])
    pixels = max(height, 0) * max(width, 0)
    n_disp = max(int(max_disparity), 0) + 1
    if method in ("sgbm", "pt-sgm"):
        d16 = _sgbm_disparities(max(int(max_disparity), 1))
        rows = height if cfg.sgbm.mode in ("hh", "hh4") else min(height, SGBM_BUFFER_ROWS)
        path_buffers = 2 * rows * width * d16 * 2  # int16 cost + sum buffers
        per_pixel = SGBM_BYTES_PER_PIXEL * pixels
        if method == "pt-sgm":
            per_pixel += 2 * 4 * pixels  # the warped right image and the shift map
        return int(path_buffers + per_pixel)
    if method == "elas":
        return int(ELAS_BYTES_PER_PIXEL * pixels)
    if method == "pandora-sgm":
        # float32 cost volume, SGM's aggregated volume and the right view's for the
        # cross-check, plus an xarray copy of each: a generous four volumes
        return int(4 * pixels * n_disp * 4 + SGBM_BYTES_PER_PIXEL * pixels)
    volumes = _d3_volume_bytes(cfg, pixels, n_disp)
    weights = pixels * 9 * 4
    features = 0
    if cfg.cost.kind == "features":
        # the model's raw maps of both views, then the normalised (H_i, W_i, C) maps and
        # norms of every level, alive while the levels are matched: twice the latter
        channels = feature_channels(cfg.features, cfg.pyramid.levels)
        features = 2 * feature_bytes((height, width), channels)
    return int(volumes + weights + features + D3_BYTES_PER_PIXEL * pixels)


def physical_memory_bytes() -> int | None:
    """Total physical memory of this machine in bytes, or None when it cannot be told."""
    try:
        pages, page_size = os.sysconf("SC_PHYS_PAGES"), os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        return None
    if pages <= 0 or page_size <= 0:
        return None
    return int(pages) * int(page_size)


def memory_limit_bytes(cfg: Config) -> tuple[int | None, str]:
    """The memory limit in bytes and where it comes from (for the message).

    ``run.max_memory_gb`` when set, else 75 % of the physical memory; ``None`` when
    neither is known (no check).
    """
    if cfg.run.max_memory_gb is not None:
        return int(cfg.run.max_memory_gb * GB), "run.max_memory_gb"
    total = physical_memory_bytes()
    if total is None:
        return None, "unknown physical memory"
    return int(DEFAULT_RAM_SHARE * total), f"{DEFAULT_RAM_SHARE:.0%} of the {total / GB:.1f} GB of RAM"


def check_memory(shape, max_disparity: int, cfg: Config, *, method: str, where: str = "pair") -> int:
    """Refuse a pair whose estimated peak memory exceeds the limit, before allocating.

    Parameters
    ----------
    shape : sequence of int
        ``(H, W)`` of the full-resolution images.
    max_disparity : int
        Largest disparity searched, pixels.
    cfg : Config
        Resolved configuration; ``run.max_memory_gb`` is the limit (None: 75 % of RAM).
    method : str, keyword-only
        Stereo method (see :func:`estimate_peak_bytes`).
    where : str, keyword-only
        What the message names first (the pair's name).

    Returns
    -------
    int
        The estimate in bytes (logged at debug level).

    Raises
    ------
    InputError
        ``<where>: estimated peak memory X GB for HxW with max disparity D exceeds the
        limit Y GB (<source>); <fix>``.
    """
    estimate = estimate_peak_bytes(shape, max_disparity, cfg, method=method)
    limit, source = memory_limit_bytes(cfg)
    log.debug("%s: estimated peak memory %.2f GB (limit %s)", where, estimate / GB,
              "none" if limit is None else f"{limit / GB:.2f} GB")
    if limit is not None and estimate > limit:
        height, width = int(shape[0]), int(shape[1])
        raise InputError(
            where_what_fix(
                where,
                f"estimated peak memory {estimate / GB:.2f} GB for {height}x{width} with max disparity "
                f"{max_disparity} ({method}) exceeds the limit {limit / GB:.2f} GB ({source})",
                "use a smaller --max-disparity, downscale the images, or raise run.max_memory_gb "
                "(--set run.max_memory_gb=N) if the machine has the memory",
            )
        )
    return estimate
