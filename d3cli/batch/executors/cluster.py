"""``--scheduler``: the pairs of a batch as tasks on a ``dask.distributed`` cluster.

Before any pair runs the scheduler must answer a plain ``identity`` request within
:data:`CONNECT_TIMEOUT_S` seconds (:func:`probe_scheduler`): distributed's own client
waits forever for a listener that accepts and never answers, and a listener sending
random bytes makes its handshake try to allocate exabytes.  Only then is a client made,
and it is always closed by d3stereo (left to its ``__del__`` it prints ``Exception
ignored in: Client.__del__`` 10 s after the error line).  distributed's log lines are
held back while d3stereo is its client (shown with ``-vv``): its errors reach the user
as d3stereo's own ``Error:`` lines.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import logging
import os
import tempfile
import time
from pathlib import Path
from typing import Callable, Iterator, Sequence

from ... import __version__
from ...errors import ConfigError, D3Error, OutputError, where_what_fix
from .. import warmup
from .base import largest_first

log = logging.getLogger(__name__)

#: Environment variable naming the scheduler when --scheduler is not given (Dask's own name).
SCHEDULER_ENV = "DASK_SCHEDULER_ADDRESS"
#: Seconds to wait for the scheduler to answer, and for a first worker to join.
CONNECT_TIMEOUT_S = 5
WORKER_TIMEOUT_S = 30


def _one_line(exc: BaseException, limit: int = 200) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text[:limit]}" if text else type(exc).__name__


async def _ask_identity(address: str, timeout: float):
    """Connect to ``address`` and ask it who it is (the scheduler's ``identity`` handler)."""
    from distributed.comm import connect
    from distributed.security import Security

    # The client's TLS settings from the dask config, as Client would use them (tls://).
    comm = await connect(address, timeout=timeout, **Security().get_connection_args("client"))
    try:
        await comm.write({"op": "identity", "reply": True})
        return await comm.read()
    finally:
        comm.abort()


def _run_coroutine(coro):
    """Run ``coro`` to its end in a fresh event loop (in a thread when this one runs a loop)."""
    try:
        asyncio.get_running_loop()
    except RuntimeError:
        return asyncio.run(coro)
    with concurrent.futures.ThreadPoolExecutor(1) as pool:  # a notebook's loop is running here
        return pool.submit(asyncio.run, coro).result()


def probe_scheduler(address: str, timeout: float = CONNECT_TIMEOUT_S) -> None:
    """Check that a Dask scheduler answers at ``address`` within ``timeout`` seconds.

    Parameters
    ----------
    address : str
        ``tcp://HOST:PORT`` (any scheme distributed knows).
    timeout : float
        Seconds for connecting and the answer together.

    Raises
    ------
    ConfigError
        ``--scheduler ADDRESS: scheduler unreachable (<why>); <fix>`` for a malformed
        address, nothing listening, no answer in time, or an answer that is not a Dask
        scheduler's.
    """
    try:
        reply = _run_coroutine(asyncio.wait_for(_ask_identity(address, timeout), timeout))
    except (asyncio.TimeoutError, TimeoutError):
        why = f"no answer within {timeout:g} s"
    except Exception as exc:  # noqa: BLE001 - a malformed address, a refused connection, garbage bytes
        why = _one_line(exc)
    else:
        if isinstance(reply, dict) and reply.get("type") == "Scheduler":
            return
        why = "the program listening there is not a Dask scheduler"
    raise ConfigError(where_what_fix(
        f"--scheduler {address}", f"scheduler unreachable ({why})",
        f"start one with `dask scheduler` or fix the address (also ${SCHEDULER_ENV})"))


def _quiet_distributed():
    """Hold back distributed's log lines (unless debugging); returns the function undoing it."""
    logger = logging.getLogger("distributed")
    if logging.getLogger().getEffectiveLevel() <= logging.DEBUG:
        return lambda: None
    level = logger.level
    logger.setLevel(logging.CRITICAL + 1)
    return lambda: logger.setLevel(level)


def _client(client_class, address: str, timeout: float):
    """A connected ``client_class`` (distributed's Client); a ConfigError naming the address
    when it fails, with the half-made client closed."""
    made = []

    class _Tracked(client_class):  # keeps hold of a client whose constructor fails, to close it
        def __init__(self, *args, **kwargs):
            made.append(self)
            super().__init__(*args, **kwargs)

    try:
        return _Tracked(address, timeout=timeout, set_as_default=False)
    except Exception as exc:  # noqa: BLE001 - whatever distributed raises: one Error line
        for client in made:
            _close_client(client, timeout)
        raise ConfigError(where_what_fix(
            f"--scheduler {address}", f"scheduler unreachable ({_one_line(exc)})",
            f"start one with `dask scheduler` or fix the address (also ${SCHEDULER_ENV})")) from None


def _close_client(client, timeout: float) -> None:
    try:
        client.close(timeout=timeout)
    except Exception as exc:  # noqa: BLE001 - closing after an error must not hide that error
        log.debug("closing the Dask client: %s", exc)


def _worker_identity() -> dict:
    """Runs on each Dask worker: the d3stereo it imports (proves it is importable)."""
    import d3cli

    return {"version": d3cli.__version__, "path": str(Path(d3cli.__file__).resolve().parent)}


def _worker_probe(out: str) -> str:
    """Runs on each Dask worker: create and delete a file in OUT; returns '' or the reason."""
    try:
        fd, probe = tempfile.mkstemp(dir=out, prefix=".d3stereo-worker-probe-")
        os.close(fd)
        os.remove(probe)
    except OSError as exc:
        return exc.strerror or str(exc)
    return ""


class DaskExecutor:
    """Pairs as tasks on a ``dask.distributed`` cluster reached at ``address``.

    Parameters
    ----------
    address : str
        Scheduler address, e.g. ``tcp://10.0.0.5:8786``.
    out : Path
        Output folder, absolute; must be the same path on every worker (shared filesystem).
    connect_timeout, worker_timeout : float, keyword-only
        Seconds to wait for the scheduler, and for a first worker.
    """

    mode = "dask"

    def __init__(self, address: str, out: Path, *, connect_timeout: float = CONNECT_TIMEOUT_S,
                 worker_timeout: float = WORKER_TIMEOUT_S):
        self.address, self.out = address, Path(out)
        self.connect_timeout, self.worker_timeout = connect_timeout, worker_timeout
        self.client = None
        self._quiet = None
        self.current = None
        self.workers: dict = {}
        self.gpu_slots = 0  # GPUs the workers declare (``dask worker --resources GPU=1``)

    def describe(self) -> dict:
        return {"mode": self.mode, "scheduler": self.address, "workers": len(self.workers),
                "threads": sum(self.workers.values()), "gpus": self.gpu_slots}

    def __enter__(self):
        try:
            from distributed import Client
        except ImportError:
            raise ConfigError("--scheduler needs dask.distributed: pip install 'd3stereo[distributed]'") from None
        self._quiet = _quiet_distributed()
        try:
            probe_scheduler(self.address, self.connect_timeout)
            self.client = _client(Client, self.address, self.connect_timeout)
            self._check_workers()
        except BaseException:
            self._close()
            raise
        return self

    def __exit__(self, *exc):
        self._close()
        return False

    def _close(self) -> None:
        """Close the client (never left to its ``__del__``, which prints a traceback 10 s
        after an error) and give distributed's loggers their level back."""
        try:
            if self.client is not None:
                _close_client(self.client, self.connect_timeout)
                self.client = None
        finally:
            if self._quiet is not None:
                self._quiet()
                self._quiet = None

    def _check_workers(self) -> None:
        """No worker, d3stereo missing or of another version, OUT not writable: ConfigError/OutputError."""
        where = f"--scheduler {self.address}"
        try:
            self.client.wait_for_workers(1, timeout=self.worker_timeout)
        except (TimeoutError, OSError):
            raise ConfigError(where_what_fix(where, f"no worker joined within {self.worker_timeout:.0f} s",
                                             "start workers with `dask worker ADDRESS`")) from None
        self.workers = dict(self.client.nthreads())
        # Workers that declare a GPU resource (one worker per GPU, docs/gpu.md) get one pair
        # per GPU at a time: a worker's threads would otherwise share its device.
        declared = self.client.scheduler_info().get("workers", {})
        self.gpu_slots = int(sum(float(info.get("resources", {}).get("GPU", 0)) for info in declared.values()))
        found = self.client.run(_worker_identity, on_error="return")
        for worker, identity in sorted(found.items()):
            if isinstance(identity, BaseException):
                raise ConfigError(where_what_fix(
                    where, f"worker {worker} cannot import d3stereo ({type(identity).__name__}: {identity})",
                    "install the same d3stereo on every worker (or set PYTHONPATH there)"))
            if identity["version"] != __version__:
                raise ConfigError(where_what_fix(
                    where, f"worker {worker} has d3stereo {identity['version']}, this client {__version__}",
                    "install the same version on the workers and here"))
        probes = self.client.run(_worker_probe, str(self.out), on_error="return")
        for worker, reason in sorted(probes.items()):
            if isinstance(reason, BaseException) or reason:
                raise OutputError(where_what_fix(
                    str(self.out), f"worker {worker} cannot write the output folder ({reason})",
                    "use -o on a filesystem shared by the client and every worker, writable by them"))

    def drain(self) -> list:
        """Pairs finished after an interruption: none (tasks in flight are cancelled)."""
        return []

    def warm(self, cfg, method) -> float:
        """Compile (or load the cache) on every worker at once; the slowest worker's seconds."""
        times = self.client.run(warmup.warm_jit, cfg, method)
        return max(times.values(), default=0.0)

    def imap(self, task: Callable, pairs: Sequence) -> Iterator:
        """Yield ``(pair, result)`` as tasks complete, largest pairs first, with at most
        2 x worker threads in flight; where workers declare GPUs, each pair holds one GPU
        (``resources={"GPU": 1}``) and 2 x GPUs are in flight."""
        from distributed import as_completed
        from distributed.client import FutureCancelledError
        from distributed.scheduler import KilledWorker

        slots = self.gpu_slots or sum(self.client.nthreads().values())
        window = max(2, 2 * slots)
        restrict = {"resources": {"GPU": 1}} if self.gpu_slots else {}
        todo = iter(largest_first(pairs))  # a large pair submitted last would run alone at the end
        pending = {}

        def submit_next():
            pair = next(todo, None)
            if pair is None:
                return None
            # pure=False: a rerun must compute again, never reuse a result the scheduler still holds;
            # retries=0: deterministic failures come back as records, only a dead worker reschedules.
            future = self.client.submit(task, pair, pure=False, retries=0,
                                        key=f"d3stereo-{pair.name}-{time.time_ns()}", **restrict)
            pending[future.key] = (future, pair)
            return future

        first = [f for f in (submit_next() for _ in range(window)) if f is not None]
        if not first:
            return
        completed = as_completed(first, loop=self.client.loop)
        try:
            for future in completed:
                _, pair = pending.pop(future.key)
                self.current = pair  # the pair an exception belongs to
                try:
                    result = future.result()
                except KilledWorker:
                    raise D3Error(f"{pair.name}: the workers running it died several times (out of memory?); "
                                  "finished pairs are complete, rerun the same command to resume") from None
                except FutureCancelledError:
                    raise D3Error(f"{pair.name}: the task was cancelled on the cluster; rerun to resume") from None
                self.current = None
                future.release()
                following = submit_next()
                if following is not None:
                    completed.add(following)
                yield pair, result
        finally:
            if pending:  # Ctrl-C or an error: nothing queued keeps running for nobody
                self.client.cancel([future for future, _ in pending.values()])
                completed.clear()
