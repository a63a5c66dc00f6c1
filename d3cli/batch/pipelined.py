"""A batch in one process whose reading and writing overlap the computing (``--prefetch N``).

Made for one GPU, whose kernels take a fraction of a pair's time while the host reads,
decodes, encodes and writes: here a reader thread reads and decodes the next pairs while
the current one computes, and a writer thread encodes and writes the finished ones
behind it.  Each pair runs the very code of the serial executor, cut into its three
stages by the generator :func:`d3cli.batch.runner._pair_stages`:

1. read (reader thread): the resume check (fingerprints, a skipped pair's reuse), the
   images, the disparity range, the memory check;
2. compute (the calling thread, always the same one: numba's parallel CPU kernels and
   the CUDA context are used from one thread only, as in the serial executor);
3. write (writer thread): maps, scores, panel, result.json, extras, the staging folder
   renamed into place.

So the per-pair files are the serial executor's, byte for byte (result.json's timings
aside), and so are its failure rules: a pair that fails at any stage is recorded and the
next one runs; a full disk or Ctrl-C ends the batch.

Bounds: at most ``prefetch`` pairs are read ahead of the one computing (the reader
takes the next pair once a computed one is in the writer's queue) and at most
``write_behind`` computed pairs wait for the writer, so at most
``prefetch + write_behind + 2`` pairs are in memory (one computing, one being written).

Ctrl-C (or SIGTERM) reaches the calling thread: the pair computing is dropped (nothing of
it was written) and so are the pairs read ahead; the writer finishes the pairs already
computed (at most ``write_behind + 1``, each written whole and counted as done,
:meth:`PipelinedExecutor.drain`), so, as in a serial batch, every pair before the one
interrupted is complete.

Results are yielded in input order (one writer, first in first out).
"""

from __future__ import annotations

import queue
import threading
from typing import Callable, Iterator, Sequence

#: Pairs read ahead by default (``--prefetch auto`` on a GPU): one is enough to hide a
#: read shorter than a compute, the second absorbs one slow read (a cold file cache).
DEFAULT_PREFETCH = 2

#: Computed pairs that may wait for the writer before the compute thread blocks.
DEFAULT_WRITE_BEHIND = 2

#: How often (seconds) a waiting thread checks whether the batch is stopping.
_POLL_S = 0.05

_END = object()  # end of a queue


class PipelinedExecutor:
    """One pair computing here while the next are read and the previous written behind.

    Parameters
    ----------
    prefetch : int
        Pairs read ahead of the one computing (>= 1).
    write_behind : int, optional, keyword-only
        Computed pairs that may wait for the writer (>= 1).
    """

    mode = "pipelined"

    def __init__(self, prefetch: int = DEFAULT_PREFETCH, *, write_behind: int = DEFAULT_WRITE_BEHIND):
        if prefetch < 1 or write_behind < 1:
            raise ValueError("prefetch and write_behind must be at least 1")
        self.prefetch, self.write_behind = prefetch, write_behind
        self.current = None  # the pair an exception belongs to, for run.json
        self._threads: list[threading.Thread] = []
        self._stop = threading.Event()
        self._done: queue.Queue = queue.Queue()  # ("done" | "error", pair, result | exception) from the writer
        self._finished: list = []  # (pair, result) written after a stop, for drain()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self._shutdown()
        return False

    def describe(self) -> dict:
        return {"mode": self.mode, "workers": 1, "prefetch": self.prefetch, "write_behind": self.write_behind}

    def warm(self, cfg, method) -> float:
        """Compile or load the kernels before the first pair, as the serial executor does."""
        from . import executors  # its warm_jit: one name for every executor of this process

        return executors.warm_jit(cfg, method)

    def drain(self) -> list:
        """``(pair, result)`` of the pairs the writer finished after an interruption (it
        writes the pairs computed before it); call after leaving the ``with`` block."""
        finished, self._finished = self._finished, []
        return finished

    # ------------------------------------------------------------------ the three threads
    def imap(self, task: Callable, pairs: Sequence) -> Iterator:
        """Yield ``(pair, result)`` in input order; ``task(pair, staged=True)`` must return
        the pair's stage generator (:func:`d3cli.batch.runner._pair_task`)."""
        pairs = list(pairs)
        self._stop.clear()
        # A slot per pair read and not yet handed to the writer: the one computing and
        # ``prefetch`` ahead.
        slots = threading.Semaphore(self.prefetch + 1)
        read_q: queue.Queue = queue.Queue()  # bounded by ``slots``
        write_q: queue.Queue = queue.Queue(maxsize=self.write_behind)
        self._threads = [
            threading.Thread(target=self._reader, args=(task, pairs, slots, read_q), name="d3stereo-reader",
                             daemon=True),
            threading.Thread(target=self._writer, args=(write_q,), name="d3stereo-writer", daemon=True),
        ]
        for thread in self._threads:
            thread.start()
        try:
            for _ in pairs:
                item = self._compute(_get(read_q, self._stop))
                while not _offer(write_q, item):  # the writer is behind: hand back what it finished
                    yield from self._ready()
                slots.release()  # its images are the writer's now: the reader may read the next pair
                yield from self._ready()
            while not _offer(write_q, _END):
                yield from self._ready()
            yield from self._ready(until_end=True)
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
        """This thread: the pair's second stage; returns what goes to the writer."""
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
        """Writer thread: each pair's last stage, in the order computed.  After a pair
        that ends the batch (a full disk, Ctrl-C inside a write) the pairs still queued
        are dropped (nothing of them was written); when the calling thread stops the batch,
        those already queued are written first."""
        failed = False
        while True:
            item = _get(write_q, self._stop)
            if item is None:
                return
            if item is _END:
                self._done.put(_END)
                return
            kind, pair, payload = item
            if failed:
                if kind == "stages":
                    payload.close()
                continue
            if kind == "stages":
                kind, pair, payload = _advance(pair, payload)
            if kind == "stages":  # pragma: no cover - a pair's generator has three stages
                kind, payload = "error", RuntimeError(f"{pair.name}: a fourth stage")
            failed = kind == "error"
            self._done.put((kind, pair, payload))

    # ------------------------------------------------------------------ helpers
    def _ready(self, *, until_end: bool = False) -> Iterator:
        """Yield ``(pair, result)`` of the pairs the writer has finished; with ``until_end``
        wait for all of them.  The exception of a write that ends the batch is raised
        in its turn (after the pairs written before it; :attr:`current` names its pair).
        """
        while True:
            try:
                item = self._done.get(timeout=_POLL_S) if until_end else self._done.get_nowait()
            except queue.Empty:
                if until_end:
                    continue
                return
            if item is _END:
                return
            kind, pair, payload = item
            if kind == "error":
                self.current = pair
                raise payload
            yield pair, payload

    def _shutdown(self) -> None:
        """Stop and join the threads; keep what the writer finished (:meth:`drain`)."""
        self._stop.set()
        for thread in self._threads:
            thread.join()
        self._threads = []
        while True:
            try:
                item = self._done.get_nowait()
            except queue.Empty:
                break
            if item is not _END and item[0] == "done":
                self._finished.append(item[1:])


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
