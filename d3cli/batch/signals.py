"""Signals during a batch: Ctrl-C and SIGTERM end it cleanly, never half-way through a record.

:func:`sigterm_as_interrupt` makes a scheduler's SIGTERM end the batch like Ctrl-C;
:func:`signals_deferred` holds both back while the lock is taken or the kernels load;
:func:`signals_held` ignores them while run.json records an interruption;
:func:`interrupts_unwrapped` lets a Ctrl-C wrapped in another exception stop the batch;
:func:`terminate_after_batch` makes a SIGTERM after the batch still exit 143, recorded.
"""

from __future__ import annotations

import atexit
import contextlib
import json
import os
import signal
import sys
import threading
from pathlib import Path

from ..errors import interrupt_behind, raise_terminated


@contextlib.contextmanager
def interrupts_unwrapped():
    """Let a Ctrl-C that surfaced wrapped in another exception (a numba kernel's
    ``SystemError``, e.g. during the JIT warm-up before the first pair) stop the batch as
    the KeyboardInterrupt it is."""
    try:
        yield
    except KeyboardInterrupt:
        raise
    except Exception as exc:
        interrupt = interrupt_behind(exc)
        if interrupt is None:
            raise
        raise interrupt from None


@contextlib.contextmanager
def signals_held():
    """Ignore SIGINT and SIGTERM for the duration (in the main thread; elsewhere a no-op).

    Used while run.json records an interruption: a second Ctrl-C (people press it twice)
    would otherwise interrupt the handler of the first and leave no run.json.  The
    handlers are restored afterwards, so a later Ctrl-C still works.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {sig: signal.signal(sig, signal.SIG_IGN) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler if handler is not None else signal.SIG_DFL)


@contextlib.contextmanager
def signals_deferred():
    """Hold SIGINT/SIGTERM back for the duration and deliver them at its end.

    Only signals whose handler is a Python function (Ctrl-C's KeyboardInterrupt, our
    SIGTERM handler) are held; in the main thread only.  A signal that came meanwhile
    is delivered once the block is done, by calling its own handler; a handler the block
    itself set for the signal stays in place and the held signal is dropped (the block
    decided what that signal means now).
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending = []
    held = {}

    def hold(signum, frame):
        pending.append(signum)

    for sig in (signal.SIGINT, signal.SIGTERM):
        handler = signal.getsignal(sig)
        if callable(handler):
            held[sig] = handler
            signal.signal(sig, hold)
    try:
        yield
    finally:
        for sig in list(held):
            if signal.getsignal(sig) is hold:
                signal.signal(sig, held[sig])
            else:  # the block set a handler of its own (e.g. SIGINT ignored): it stays, and rules
                del held[sig]
        pending = [sig for sig in pending if sig in held]
        if pending:
            # Also when the block failed: the workers of a pool killed by the same SIGTERM
            # made it fail ("could not start"), and the interrupt is what happened.
            held[pending[0]](pending[0], None)


def terminate_after_batch(run_json, message: str, *, exit_status: int = 143) -> None:
    """From the end of a batch to the exit of the process, make SIGTERM record itself in
    ``run_json`` (``interrupted: true``, ``stop_reason``) and end the process with
    ``exit_status`` after printing ``message``, as the README promises (143).

    Ignored there instead, a SIGTERM that comes while the summary lines are printed or
    Python shuts down would give exit 0 and a run.json saying nothing happened.  The
    handler exits at once (``os._exit``): the batch is
    written and recorded, nothing is left to clean up.  An ``atexit`` hook gives a signal
    that came after the command returned one more chance to be handled.
    """
    if threading.current_thread() is not threading.main_thread():
        return

    def handler(signum, frame):
        signal.signal(signal.SIGTERM, signal.SIG_IGN)  # a second one must not cut this short
        try:
            mark_terminated(run_json)
            sys.stderr.write(message + "\n")
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(exit_status)

    handler.after_batch = True  # the CLI leaves this handler in place at its end
    signal.signal(signal.SIGTERM, handler)
    atexit.register(_ignore_sigterm_from_now)


def _ignore_sigterm_from_now() -> None:
    """Shutdown hook of :func:`terminate_after_batch`: its bytecode gives a pending SIGTERM
    its handler (exit 143), then SIGTERM is ignored for the rest of the shutdown (exit 0,
    everything written).  CPython's finalisation puts a Python-level handler back to the
    default action, so a SIGTERM there would kill the process (status -15, nothing said;
    tests/test_adversarial.py, seed 5, in a fresh environment); an ignored one stays ignored."""
    signal.signal(signal.SIGTERM, signal.SIG_IGN)


def mark_terminated(run_json) -> None:
    """Record in a finished batch's ``run_json`` that SIGTERM ended the process after it."""
    from .outputs import write_json

    try:
        data = json.loads(Path(run_json).read_text(encoding="utf-8"))
        data.update(interrupted=True, stop_reason="terminated (SIGTERM) after the batch had finished")
        write_json(Path(run_json), data)
    except Exception:  # noqa: BLE001 - the exit status still says it; never a traceback from a handler
        pass


def sigterm_as_interrupt():
    """Make SIGTERM (a scheduler cancelling the job, ``kill``) end the batch like Ctrl-C.

    Returns the previous handler, or None where signals cannot be set (not the main thread).
    """
    if threading.current_thread() is not threading.main_thread():
        return None
    return signal.signal(signal.SIGTERM, raise_terminated)
