"""Compiling the numba kernels once, before the first pair, so no pair's time includes it.

A batch calls :func:`warm_jit` up front (in the parent before a local pool fans out, on
every worker of a Dask cluster before pairs are submitted).  The kernels are compiled
with ``cache=True``, so a warm-up writes the on-disk cache that pool workers then load
instead of each compiling the same kernels at once (a compile storm).  The time it took
is stored in ``run.json`` as ``compile_s``; per-pair ``wall`` times exclude it.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from ..config import Config
from ..errors import D3Error
from . import methods

log = logging.getLogger(__name__)

#: Methods without numba kernels: nothing to compile.
_NO_JIT = ("sgbm",)

#: Size of the warm-up pair (H, W) and its disparity range, pixels: small enough to cost
#: nothing once compiled, large enough for every window and pyramid level of the defaults.
_WARM_SHAPE = (64, 96)
_WARM_DMAX = 16


def warm_pair(shape: tuple[int, int] = _WARM_SHAPE, shift: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """A fixed textured uint8 pair ``(left, right)``, shape (H, W), right = left shifted by ``shift`` px."""
    rng = np.random.default_rng(12345)
    height, width = shape
    wide = rng.integers(0, 256, size=(height, width + shift), dtype=np.uint8)
    return wide[:, shift:].copy(), wide[:, :width].copy()


def warm_jit(cfg: Config, method: str) -> float:
    """Run ``method`` with ``cfg`` once on a tiny pair; returns the seconds it took.

    Compiles (or loads from the numba cache) every kernel the run will use with the
    run's own types and backend.  A failure of the tiny pair itself (e.g. no road plane
    found by PT) is logged and ignored: the kernels it reached are compiled anyway.
    """
    if method in _NO_JIT:
        return 0.0
    left, right = warm_pair()
    t0 = time.perf_counter()
    try:
        methods.compute_pair(method, cfg, left, right, max_disparity=_WARM_DMAX)
    except D3Error as exc:
        log.debug("JIT warm-up pair failed (ignored): %s", exc)
    seconds = time.perf_counter() - t0
    log.info("JIT warm-up (%s): %.2f s", method, seconds)
    return seconds
