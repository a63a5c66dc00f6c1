"""What every executor is and shares: the :class:`Executor` protocol, the cores this
process may use, ``--workers`` and ``--shard`` parsed, pairs ordered largest first.

Imports no other executor module (each of them imports this one).
"""

from __future__ import annotations

import os
from typing import Callable, Iterator, Protocol, Sequence

from ...data import formats as io
from ...errors import ConfigError


class Executor(Protocol):
    """Where the pairs of a batch run; a context manager the batch enters once.

    Every executor runs the same picklable per-pair task, so the per-pair files are the
    same whichever runs them (:mod:`d3cli.batch.executors`).
    """

    #: ``serial``, ``pipelined``, ``local-pool`` or ``dask``: run.json's ``executor.mode``.
    mode: str
    #: The pair in progress (the pair an exception belongs to), for run.json; None between pairs.
    current: object

    def __enter__(self) -> "Executor":
        ...

    def __exit__(self, *exc) -> bool:
        ...

    def describe(self) -> dict:
        """run.json's ``executor`` record: the mode and its settings."""
        ...

    def warm(self, cfg, method) -> float:
        """Compile or load the kernels before the first pair; the seconds it took."""
        ...

    def imap(self, task: Callable, pairs: Sequence) -> Iterator:
        """Yield ``(pair, task(pair))`` for every pair, in the executor's order."""
        ...

    def drain(self) -> list:
        """``(pair, result)`` of the pairs finished after an interruption; call after
        leaving the ``with`` block."""
        ...


#: Most ``--workers`` processes accepted (multiprocessing's semaphores overflowed on a
#: 20-digit count); a pool never has more workers than the batch has pairs.
MAX_WORKERS = 1024


def available_cores() -> int:
    """CPU cores this process may use (affinity mask where the OS has one)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # macOS, Windows
        return max(1, os.cpu_count() or 1)


#: ``--workers auto`` runs serially on this many cores or fewer (one core: a pool has
#: nothing to gain); on two quiet cores two forked workers already take about 0.8x the
#: serial wall time with the same CPU seconds (README "Scaling out", scripts/bench_scaling.py).
AUTO_SERIAL_CORES = 1


def parse_workers(value: str | int) -> int:
    """``--workers`` value -> number of worker processes (``auto``: one per core, and 1 -
    serial - on :data:`AUTO_SERIAL_CORES` core).

    Raises
    ------
    ConfigError
        When the value is neither a positive integer nor ``auto``.
    """
    if isinstance(value, int):
        n = value
    elif str(value).strip().lower() == "auto":
        cores = available_cores()
        return 1 if cores <= AUTO_SERIAL_CORES else cores
    else:
        try:
            n = int(value)
        except ValueError:
            n = 0
    if n < 1:
        raise ConfigError(f"--workers {value}: use a positive number of processes or 'auto'")
    if n > MAX_WORKERS:
        raise ConfigError(f"--workers {str(value)[:30]}: at most {MAX_WORKERS} processes; use 'auto' for one "
                          f"per core ({available_cores()} here)")
    return n


def parse_shard(value: str) -> tuple[int, int]:
    """``--shard I/N`` -> (I, N) with 1 <= I <= N.

    Raises
    ------
    ConfigError
        When the value is not of the form ``I/N`` with 1 <= I <= N.
    """
    try:
        index, total = (int(part) for part in str(value).split("/"))
    except ValueError:
        index, total = 0, 0
    if not (total >= 1 and 1 <= index <= total):
        raise ConfigError(f"--shard {value}: use I/N with 1 <= I <= N, e.g. --shard 3/8 for the third of eight")
    return index, total


def select_shard(pairs: Sequence, index: int, total: int) -> list:
    """Shard ``index`` (1-based) of ``total``: the pairs at positions index-1, index-1+total, ...
    of the pairs sorted by name.

    Every pair lands in exactly one shard, whatever order discovery returned them in.
    """
    ordered = sorted(pairs, key=lambda p: p.name)
    return [p for i, p in enumerate(ordered) if i % total == index - 1]


#: Above this many pairs the pool keeps the input order instead of reading every image
#: header to start the largest pairs first (the idle tail is then a tiny share of the run).
LARGEST_FIRST_LIMIT = 20_000


def pair_cost(pair) -> int:
    """Estimated work of a pair: pixels x disparity range (the cost volume's size).

    From the left image's header (no decoding); 0 when it cannot be read (the pair then
    fails on its own when it runs).
    """
    try:
        size = io.image_size(pair.left)
    except Exception:  # noqa: BLE001 - an estimate only: a broken file is reported by its pair
        size = None
    if not size:
        return 0
    width, height = size
    return width * height * max(1, pair.max_disparity or width // 4)


def largest_first(pairs: Sequence, *, limit: int = LARGEST_FIRST_LIMIT) -> list:
    """``pairs`` with the most expensive first (:func:`pair_cost`; ties keep their order).

    With whole pairs per worker, a large pair started last runs alone on one worker's
    threads while the others idle; started first, the small ones fill the end.  Beyond
    ``limit`` pairs the input order is kept (reading every header would cost more than
    the tail it saves).
    """
    pairs = list(pairs)
    if len(pairs) > limit:
        return pairs
    return sorted(pairs, key=pair_cost, reverse=True)
