"""Compiling the numba kernels once, before the first pair, so no pair's time includes it.

A batch calls :func:`warm_jit` up front (in the parent before a local pool fans out, on
every worker of a Dask cluster before pairs are submitted).  The kernels are compiled
with ``cache=True``, so a warm-up writes the on-disk cache that pool workers then load
instead of each compiling the same kernels at once (a compile storm).  The time it took
is stored in ``run.json`` as ``compile_s``; per-pair ``wall`` times exclude it.

A first run compiles for a minute or more: on a cold cache it says so before it starts
(:func:`d3cli.kernels.cachedir.announce`, which the command line calls before its imports)
and reports progress while it compiles (:class:`CompileProgress`), as log records of level
:data:`~d3cli.kernels.cachedir.NOTICE`, shown unless ``-q``.
"""

from __future__ import annotations

import logging
import time

import numpy as np
from numba.core import event as numba_event

from ..config import Config
from ..errors import D3Error
from ..kernels import cachedir
from . import methods

log = logging.getLogger(__name__)

NOTICE = cachedir.NOTICE
#: Seconds between two progress lines while the kernels compile.
PROGRESS_EVERY_S = 10.0

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


class CompileProgress(numba_event.Listener):
    """Counts numba's compiles (cache misses only; a kernel's callees each count) and logs
    progress every :data:`PROGRESS_EVERY_S` seconds:
    ``compiled 40 of about 120 kernel functions (31 s)``.

    Parameters
    ----------
    expected : int or None
        Functions a cold compile compiles, for the "of about N"; None: count only.
    every : float
        Seconds between two progress lines.
    clock : callable
        Seconds now (``time.perf_counter``).
    """

    def __init__(self, expected: int | None, every: float = PROGRESS_EVERY_S, clock=time.perf_counter):
        self.expected = expected
        self.every = every
        self.clock = clock
        self.compiled = 0
        self._t0 = self._last = clock()

    def on_start(self, event) -> None:
        pass

    def on_end(self, event) -> None:
        self.compiled += 1
        now = self.clock()
        if now - self._last >= self.every:
            self._last = now
            log.log(NOTICE, self.line(now - self._t0))

    def line(self, seconds: float) -> str:
        """``compiled 40 of about 120 kernel functions (31 s)``."""
        total = f" of about {self.expected}" if self.expected and self.expected > self.compiled else ""
        return f"compiled {self.compiled}{total} kernel functions ({seconds:.0f} s)"


def warm_jit(cfg: Config, method: str) -> float:
    """Run ``method`` with ``cfg`` once on a tiny pair; returns the seconds it took.

    Compiles (or loads from the numba cache) every kernel the run will use with the
    run's own types and backend.  A failure of the tiny pair itself (e.g. no road plane
    found by PT) is logged and ignored: the kernels it reached are compiled anyway.  On
    a cold cache it logs the compile notice first (unless the command line did) and
    progress while compiling.
    """
    if method in _NO_JIT:
        return 0.0
    cold = cachedir.announce(method)
    expected = cachedir.compile_estimate(method)["kernels"] if cold else None
    left, right = warm_pair()
    t0 = time.perf_counter()
    with numba_event.install_listener("numba:compile", CompileProgress(expected)) as progress:
        try:
            methods.compute_pair(method, cfg, left, right, max_disparity=_WARM_DMAX)
        except D3Error as exc:
            log.debug("JIT warm-up pair failed (ignored): %s", exc)
    seconds = time.perf_counter() - t0
    if cold:
        cachedir.record_compile(method, seconds, progress.compiled)
        log.log(NOTICE, f"compiled {progress.compiled} kernel functions in {seconds:.0f} s")
    log.info("JIT warm-up (%s): %.2f s, %d kernel functions compiled", method, seconds, progress.compiled)
    return seconds
