"""A batch in one process whose reading and writing overlap the computing (``--prefetch N``).

Made for one GPU, whose kernels take a fraction of a pair's time while the host reads,
decodes, encodes and writes: here a reader thread reads and decodes the next pairs while
the current one computes, and writer threads encode and write the finished ones behind
it (several on a machine with many cores: the PNGs, the panel and the scores of a 720p
pair take longer than its kernels).  Each pair runs the very code of the serial
executor, cut into its three stages by the generator :func:`d3cli.batch.runner._pair_stages`:

1. read (reader thread): the resume check (fingerprints, a skipped pair's reuse), the
   images, the disparity range, the memory check;
2. compute (the calling thread, always the same one: numba's parallel CPU kernels and
   the CUDA context are used from one thread only, as in the serial executor);
3. write (writer threads): maps, scores, panel, result.json, extras, the staging
   folder renamed into place.

So the per-pair files are the serial executor's, byte for byte (result.json's timings
aside), and so are its failure rules: a pair that fails at any stage is recorded and the
next one runs; a full disk or Ctrl-C ends the batch.

Bounds: at most ``prefetch`` pairs are read ahead of the one computing (the reader
takes the next pair once a computed one is in the writers' queue) and at most
``write_behind`` computed pairs wait for a writer, so at most
``prefetch + write_behind + writers + 1`` pairs are in memory (one computing, one being
written by each writer).

Ctrl-C (or SIGTERM) reaches the calling thread: the pair computing is dropped (nothing of
it was written) and so are the pairs read ahead; the writers finish the pairs already
computed (at most ``write_behind + writers``, each written whole and counted as done,
:meth:`PipelinedExecutor.drain`), so, as in a serial batch, every pair before the one
interrupted is complete.  A full disk met by a writer ends the batch at that pair; with
several writers a later pair being written at the same time may still complete (whole:
a rerun skips it).

Results are yielded in input order, whichever writer finished first.
"""

from __future__ import annotations

import queue
import threading
from typing import Callable, Iterator, Sequence

from .. import warmup
from .base import available_cores

#: Pairs read ahead by default (``--prefetch auto`` on a GPU): one is enough to hide a
#: read shorter than a compute, the second absorbs one slow read (a cold file cache).
DEFAULT_PREFETCH = 2

#: Computed pairs that may wait for a writer before the compute thread blocks (at least
#: one per writer).
DEFAULT_WRITE_BEHIND = 2

#: Most writer threads chosen by default (:func:`default_writers`).
MAX_DEFAULT_WRITERS = 4


def default_writers() -> int:
    """Writer threads of a pipelined batch by default: one per 4 cores, 1 to
    :data:`MAX_DEFAULT_WRITERS`.

    The compute thread keeps numba's threads for the host steps; PNG encoding and the
    panel release the GIL, so a few writers run in parallel (on 16 cores: 4).
    """
    return max(1, min(MAX_DEFAULT_WRITERS, available_cores() // 4))


#: How often (seconds) a waiting thread checks whether the batch is stopping.
_POLL_S = 0.05

_END = object()  # end of a queue


class PipelinedExecutor:
    """One pair computing here while the next are read and the previous written behind.

    Parameters
    ----------
    prefetch : int
        Pairs read ahead of the one computing (>= 1).
    writers : int, optional, keyword-only
        Writer threads (>= 1); default :func:`default_writers`.
    write_behind : int, optional, keyword-only
        Computed pairs that may wait for a writer (>= 1); default the larger of
        :data:`DEFAULT_WRITE_BEHIND` and ``writers``.
    """

    mode = "pipelined"

    def __init__(self, prefetch: int = DEFAULT_PREFETCH, *, writers: int | None = None,
                 write_behind: int | None = None):
        self.writers = default_writers() if writers is None else writers
        self.write_behind = max(DEFAULT_WRITE_BEHIND, self.writers) if write_behind is None else write_behind
        if min(prefetch, self.writers, self.write_behind) < 1:
            raise ValueError("prefetch, writers and write_behind must be at least 1")
        self.prefetch = prefetch
        self.current = None  # the pair an exception belongs to, for run.json
        self._threads: list[threading.Thread] = []
        self._stop = threading.Event()
        self._write_failed = threading.Event()  # a write ended the batch: the writers drop the rest
        # (index, "done" | "error", pair, result | exception) from the writers, in any order
        self._done: queue.Queue = queue.Queue()
        self._out: dict = {}  # the same, taken from _done, by index, until yielded in order
        self._next = 0  # index of the next pair to yield
        self._finished: list = []  # (pair, result) written after a stop, for drain()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self._shutdown()
        return False

    def describe(self) -> dict:
        return {"mode": self.mode, "workers": 1, "prefetch": self.prefetch, "writers": self.writers,
                "write_behind": self.write_behind}

    def warm(self, cfg, method) -> float:
        """Compile or load the kernels before the first pair, as the serial executor does."""
        return warmup.warm_jit(cfg, method)

    def drain(self) -> list:
        """``(pair, result)`` of the pairs the writers finished after an interruption (they
        write the pairs computed before it); call after leaving the ``with`` block."""
        finished, self._finished = self._finished, []
        return finished

    # ------------------------------------------------------------------ the threads
    def imap(self, task: Callable, pairs: Sequence) -> Iterator:
        """Yield ``(pair, result)`` in input order; ``task(pair, staged=True)`` must return
        the pair's stage generator (:func:`d3cli.batch.runner._pair_task`)."""
        pairs = list(pairs)
        self._stop.clear()
        self._write_failed.clear()
        self._out, self._next = {}, 0
        # A slot per pair read and not yet handed to the writers: the one computing and
        # ``prefetch`` ahead.
        slots = threading.Semaphore(self.prefetch + 1)
        read_q: queue.Queue = queue.Queue()  # bounded by ``slots``
        write_q: queue.Queue = queue.Queue(maxsize=self.write_behind)
        self._threads = [threading.Thread(target=self._reader, args=(task, pairs, slots, read_q),
                                          name="d3stereo-reader", daemon=True)]
        self._threads += [threading.Thread(target=self._writer, args=(write_q,), name=f"d3stereo-writer-{i}",
                                           daemon=True) for i in range(self.writers)]
        for thread in self._threads:
            thread.start()
        try:
            for index in range(len(pairs)):
                item = (index, *self._compute(_get(read_q, self._stop)))
                while not _offer(write_q, item):  # the writers are behind: hand back what they finished
                    yield from self._ready()
                slots.release()  # its images are the writers' now: the reader may read the next pair
                yield from self._ready()
            for _ in range(self.writers):
                while not _offer(write_q, _END):
                    yield from self._ready()
            yield from self._ready(until=len(pairs))
        finally:
            self._shutdown()

    def _reader(self, task: Callable, pairs: list, slots: threading.Semaphore, read_q: queue.Queue) -> None:
        """Reader thread: each pair's first stage, at most ``prefetch`` pairs ahead."""
        for pair in pairs:
            while not slots.acquire(timeout=_POLL_S):
                if self._stop.is_set():
                    return
            if self._stop.is_set():
                return
            try:
                stages = task(pair, staged=True)
            except BaseException as exc:  # noqa: BLE001 - raised by the calling thread
                read_q.put(("error", pair, exc))
                return
            item = _advance(pair, stages)
            read_q.put(item)
            if item[0] == "error":
                return

    def _compute(self, item: tuple) -> tuple:
        """This thread: the pair's second stage; returns what goes to the writers."""
        kind, pair, payload = item
        if kind == "stages":
            self.current = pair
            kind, pair, payload = _advance(pair, payload)
        if kind == "error":  # Ctrl-C, a full disk: the batch stops
            self.current = pair
            raise payload
        self.current = None
        return kind, pair, payload

    def _writer(self, write_q: queue.Queue) -> None:
        """Writer thread: the last stage of the pairs it takes from the queue.  After a
        pair that ends the batch (a full disk, Ctrl-C inside a write) the pairs still
        queued are dropped (nothing of them was written); when the calling thread stops
        the batch, those already queued are written first."""
        while True:
            item = _get(write_q, self._stop)
            if item is None or item is _END:
                return
            index, kind, pair, payload = item
            if self._write_failed.is_set():
                if kind == "stages":
                    payload.close()
                continue
            if kind == "stages":
                kind, pair, payload = _advance(pair, payload)
            if kind == "stages":  # pragma: no cover - a pair's generator has three stages
                kind, payload = "error", RuntimeError(f"{pair.name}: a fourth stage")
            if kind == "error":
                self._write_failed.set()
            self._done.put((index, kind, pair, payload))

    # ------------------------------------------------------------------ helpers
    def _ready(self, *, until: int | None = None) -> Iterator:
        """Yield ``(pair, result)`` of the pairs the writers have finished, in input order;
        with ``until``, wait until that many pairs are yielded.  The exception of a write
        that ends the batch is raised in its turn (after the pairs before it;
        :attr:`current` names its pair).
        """
        while True:
            try:
                while True:
                    item = self._done.get_nowait()
                    self._out[item[0]] = item[1:]
            except queue.Empty:
                pass
            while self._next in self._out:
                kind, pair, payload = self._out.pop(self._next)
                if kind == "error":
                    self.current = pair
                    raise payload
                self._next += 1
                yield pair, payload
            if until is None or self._next >= until:
                return
            try:
                item = self._done.get(timeout=_POLL_S)
                self._out[item[0]] = item[1:]
            except queue.Empty:
                pass

    def _shutdown(self) -> None:
        """Stop and join the threads; keep what the writers finished (:meth:`drain`)."""
        self._stop.set()
        for thread in self._threads:
            thread.join()
        self._threads = []
        while True:
            try:
                item = self._done.get_nowait()
            except queue.Empty:
                break
            self._out[item[0]] = item[1:]
        self._finished += [(pair, result) for _, (kind, pair, result) in sorted(self._out.items()) if kind == "done"]
        self._out = {}


def _offer(q: queue.Queue, item) -> bool:
    """Put ``item`` into ``q``; False when it stayed full for :data:`_POLL_S`."""
    try:
        q.put(item, timeout=_POLL_S)
    except queue.Full:
        return False
    return True


def _advance(pair, stages) -> tuple:
    """Run the next stage of ``pair``: ``("stages", pair, stages)`` when more follow,
    ``("done", pair, result)`` when the pair is finished (written, skipped or failed),
    ``("error", pair, exception)`` when it ends the batch (Ctrl-C, a full disk)."""
    try:
        next(stages)
    except StopIteration as done:
        return "done", pair, done.value
    except BaseException as exc:  # noqa: BLE001 - handed to the calling thread, which raises it
        return "error", pair, exc
    return "stages", pair, stages


def _get(q: queue.Queue, stop: threading.Event):
    """The next item of ``q``; None once ``stop`` is set (checked every :data:`_POLL_S`)."""
    while True:
        try:
            return q.get(timeout=_POLL_S)
        except queue.Empty:
            if stop.is_set():
                return None
