"""Where the pairs of a batch run: in this process, a local process pool, or a Dask cluster.

Every executor runs the same picklable per-pair task (a ``functools.partial`` of
:func:`d3cli.batch.runner._batch_pair`, which writes one pair's outputs atomically into
OUT and returns its report row and run.json record), so the per-pair files are the same
whichever runs them.  The parent (client) keeps the OUT lock, collects the results and
writes ``run.json`` / the summary.

Each executor has its module here and follows the :class:`~.base.Executor` protocol
(``base.py``, with what they share: cores, ``--workers``, ``--shard``, largest first);
:func:`make_executor` picks one.  May import: :mod:`d3cli.batch.warmup`, data, errors.

* :class:`SerialExecutor` (``local.py``) - one pair after the other, here (``--workers 1``, the default).
* :class:`PoolExecutor` (``pooled.py``) - ``--workers N``: N processes, each taking whole pairs (largest
  first), numba and OpenCV threads set per worker so that workers x threads <= cores.
  Workers are forked where that is safe, inheriting every imported module (a spawned
  worker re-imports them: 1.2 s of CPU each on the 2-core test machine, as much as
  two pairs of 640x360); the first worker compiles or loads the kernels, the others then
  load the cache it wrote.  At most 2 N pairs are in flight, so a huge manifest never
  becomes a huge queue.
* :class:`PipelinedExecutor` (``pipelined.py``) - ``--prefetch N`` (``auto``:
  2 on the CUDA backend): one process, the next pairs read by a thread while this one
  computes, the previous written behind by another; for one GPU.
* :class:`DaskExecutor` (``cluster.py``) - ``--scheduler tcp://HOST:PORT``: each pair a task on an existing
  ``dask.distributed`` cluster, submitted through a window of in-flight futures
  (``as_completed``), checked up front (scheduler reachable, workers present with the
  same d3stereo version, OUT writable from every worker).  A worker that dies mid-pair
  has its task rescheduled elsewhere by the scheduler (``distributed.scheduler.
  allowed-failures``); a pair failing deterministically returns a ``failed`` record from
  inside the task, so it is recorded once and never retried.

Ctrl-C: queued pairs are cancelled; pool workers ignore SIGINT and finish the pair they
hold (whole pairs only, written atomically; counted as done, :meth:`PoolExecutor.drain`), Dask tasks in flight are cancelled (a
cancelled pair leaves no ``result.json``, so a rerun computes it again); the pipelined
executor's writer finishes the pairs already computed.
"""

from __future__ import annotations

import logging
from pathlib import Path

from ...errors import ConfigError
from .base import (AUTO_SERIAL_CORES, LARGEST_FIRST_LIMIT, MAX_WORKERS, Executor, available_cores, largest_first,
                   pair_cost, parse_shard, parse_workers, select_shard)
from .cluster import CONNECT_TIMEOUT_S, SCHEDULER_ENV, WORKER_TIMEOUT_S, DaskExecutor
from .local import SerialExecutor
from .pipelined import DEFAULT_PREFETCH, PipelinedExecutor
from .pooled import START_METHOD_ENV, PoolExecutor, pool_start_method

log = logging.getLogger(__name__)


def parse_prefetch(value: str | int | None) -> int | None:
    """``--prefetch`` value -> pairs read ahead (0: none, serial), or None for ``auto``.

    Raises
    ------
    ConfigError
        When the value is neither a number from 0 to :data:`MAX_PREFETCH` nor ``auto``.
    """
    if value is None or str(value).strip().lower() == "auto":
        return None
    try:
        n = int(value)
    except ValueError:
        n = -1
    if not 0 <= n <= MAX_PREFETCH:
        raise ConfigError(f"--prefetch {str(value)[:30]}: use a number of pairs from 0 (none) to {MAX_PREFETCH}, "
                          f"or 'auto' ({DEFAULT_PREFETCH} on a GPU, none on the CPU)")
    return n


#: Most pairs ``--prefetch`` reads ahead (each holds its decoded images in memory).
MAX_PREFETCH = 64


def resolve_prefetch(prefetch: int | None, cfg=None, method: str | None = None) -> int:
    """Pairs read ahead by a batch in this process: ``prefetch``, or for ``auto`` (None)
    :data:`~d3cli.batch.executors.pipelined.DEFAULT_PREFETCH` when ``method`` runs the kernels
    (d3stereo, pt-sgm) on the CUDA backend, whose host work would otherwise leave the device
    idle; else 0 (serial: on the CPU the reading and writing threads take cores from the
    numba kernels, and sgbm, elas and pandora-sgm never use the device)."""
    if prefetch is not None:
        return prefetch
    from ...config import method_spec
    from ...kernels import chosen_backend

    spec = method_spec(method)
    if cfg is None or spec is None or not spec.kernels:  # sgbm, elas, pandora-sgm never use the device
        return 0

    return DEFAULT_PREFETCH if chosen_backend(cfg.run.backend) == "cuda" else 0


def make_executor(workers: int = 1, scheduler: str | None = None, out: Path | None = None,
                  n_pairs: int | None = None, *, prefetch: int | None = 0, cfg=None, method: str | None = None):
    """The executor for ``--workers`` / ``--scheduler`` / ``--prefetch`` (scheduler wins;
    1 worker is serial, or pipelined with ``prefetch`` >= 1).

    A pool gets at most ``n_pairs`` workers: more would only start, load the kernels one
    after the other and idle (``--workers 1000`` on two pairs would keep 999 processes
    alive long after both pairs are done).  ``prefetch`` (None: ``auto``, resolved for ``cfg``
    and ``method`` by :func:`resolve_prefetch`) applies to a batch in this process only:
    a pool's or a cluster's workers take whole pairs.
    """
    if scheduler:
        return DaskExecutor(scheduler, Path(out).resolve())
    if n_pairs is not None and workers > max(1, n_pairs):
        log.info("--workers %d: %d pair(s) to run, so %d worker process(es)", workers, n_pairs, max(1, n_pairs))
        workers = max(1, n_pairs)
    if workers > 1:
        if prefetch:
            log.info("--prefetch %d: not used with --workers %d (each worker takes whole pairs)", prefetch, workers)
        return PoolExecutor(workers)
    prefetch = resolve_prefetch(prefetch, cfg, method)
    if prefetch >= 1:
        return PipelinedExecutor(prefetch)
    return SerialExecutor()


__all__ = [
    "AUTO_SERIAL_CORES", "CONNECT_TIMEOUT_S", "DEFAULT_PREFETCH", "LARGEST_FIRST_LIMIT", "MAX_PREFETCH", "MAX_WORKERS",
    "SCHEDULER_ENV", "START_METHOD_ENV", "WORKER_TIMEOUT_S", "DaskExecutor", "Executor", "PipelinedExecutor",
    "PoolExecutor", "SerialExecutor", "available_cores", "largest_first", "make_executor", "pair_cost",
    "parse_prefetch", "parse_shard", "parse_workers", "pool_start_method", "resolve_prefetch", "select_shard",
]
