"""Resource limits: estimate a pair's peak memory before allocating anything big.

A 3,000-pair batch should not die in the middle of pair 1,742 because one pair is
larger than the rest: :func:`check_memory` turns "this would need 90 GB" into a per-pair
:class:`~d3cli.errors.InputError` that names the estimate and the fix, before the cost
volume is allocated.

Each method brings its own memory model, named by its declaration
(:attr:`d3cli.config.MethodSpec.peak_bytes`): d3stereo's in :mod:`d3cli.method.memory`
(cost volumes, RBF weights, feature maps, per-pixel maps), SGBM's and PT-SGM's beside
them in :mod:`d3cli.baselines` (OpenCV's int16 path buffers), the peers' in
:mod:`d3cli.baselines.peers`.  This module holds the limit and the check.
"""

from __future__ import annotations

import logging
import os

from ..config import Config
from ..errors import InputError, where_what_fix
from .dispatch import spec_of

log = logging.getLogger(__name__)

#: Share of the physical memory used as the limit when run.max_memory_gb is unset.
DEFAULT_RAM_SHARE = 0.75
GB = 1e9


def estimate_peak_bytes(shape, max_disparity: int, cfg: Config, *, method: str) -> int:
    """Estimated peak memory of computing one pair with ``method``.

    Parameters
    ----------
    shape : sequence of int
        ``(H, W)`` (or ``(H, W, C)``) of the full-resolution images, pixels.
    max_disparity : int
        Largest disparity searched at full resolution, pixels.
    cfg : Config
        Resolved configuration.
    method : str, keyword-only
        One of :data:`d3cli.config.METHODS`; its memory model
        (:attr:`~d3cli.config.MethodSpec.peak_bytes`) gives the estimate.

    Returns
    -------
    int
        Bytes; an upper estimate of the largest simultaneous allocation, not counting
        the Python interpreter and the libraries themselves.

    Raises
    ------
    ConfigError
        No method of that name.
    """
    return spec_of(method).estimate_peak_bytes(shape, max_disparity, cfg)


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
