"""Signals during a batch: Ctrl-C, SIGTERM and SIGHUP end it cleanly, never half-way through a record.

SIGHUP (the terminal or the ssh session closed) is handled like SIGTERM (a scheduler
cancelling the job, ``kill``): the batch stops as on Ctrl-C, run.json records it, and the
exit status is the shell's for that signal, 129 or 143 (:data:`TERMINATING`).

:func:`sigterm_as_interrupt` makes SIGTERM and SIGHUP end the batch like Ctrl-C;
:func:`signals_deferred` holds them back while the lock is taken or the kernels load;
:func:`signals_held` ignores them while run.json records an interruption;
:func:`interrupts_unwrapped` lets a Ctrl-C wrapped in another exception stop the batch;
:func:`terminate_after_batch` makes a SIGTERM or SIGHUP after the batch still exit 143 or
129, recorded.
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

from ..errors import Terminated, interrupt_behind, raise_hung_up, raise_terminated

#: The signals that end a batch like Ctrl-C, with the exit status a shell reports for each
#: (128 + the signal's number).
TERMINATING = {signal.SIGTERM: 128 + signal.SIGTERM, signal.SIGHUP: 128 + signal.SIGHUP}
#: Every signal that stops a batch: Ctrl-C and :data:`TERMINATING`.
STOP_SIGNALS = (signal.SIGINT, *TERMINATING)


def signal_name(exc: BaseException) -> str:
    """The signal behind a :class:`~d3cli.errors.Terminated`: ``SIGHUP`` or ``SIGTERM``."""
    return getattr(exc, "signal_name", "SIGTERM")


def exit_status(name: str) -> int:
    """The exit status after the signal named ``name`` (``SIGTERM``: 143, ``SIGHUP``: 129)."""
    return 128 + int(getattr(signal, name))


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
    """Ignore SIGINT, SIGTERM and SIGHUP for the duration (in the main thread; elsewhere a no-op).

    Used while run.json records an interruption: a second Ctrl-C (people press it twice)
    would otherwise interrupt the handler of the first and leave no run.json.  The
    handlers are restored afterwards, so a later Ctrl-C still works.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {sig: signal.signal(sig, signal.SIG_IGN) for sig in STOP_SIGNALS}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler if handler is not None else signal.SIG_DFL)


@contextlib.contextmanager
def signals_deferred():
    """Hold SIGINT/SIGTERM/SIGHUP back for the duration and deliver them at its end.

    Only signals whose handler is a Python function (Ctrl-C's KeyboardInterrupt, our
    SIGTERM and SIGHUP handlers) are held; in the main thread only.  A signal that came meanwhile
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

    for sig in STOP_SIGNALS:
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


def terminate_after_batch(run_json, done: str) -> None:
    """From the end of a batch to the exit of the process, make SIGTERM and SIGHUP record
    themselves in ``run_json`` (``interrupted: true``, ``stop_reason``) and end the process
    with 143 or 129 after printing ``Terminated (SIGTERM): <done>``, as the README promises.

    Ignored there instead, a signal that comes while the summary lines are printed or
    Python shuts down would give exit 0 and a run.json saying nothing happened.  The
    handler exits at once (``os._exit``): the batch is
    written and recorded, nothing is left to clean up.  An ``atexit`` hook gives a signal
    that came after the command returned one more chance to be handled.
    """
    if threading.current_thread() is not threading.main_thread():
        return

    def handler(signum, frame):
        for sig in TERMINATING:  # a second one must not cut this short
            signal.signal(sig, signal.SIG_IGN)
        name = signal.Signals(signum).name
        try:
            mark_terminated(run_json, name)
            for stream, text in ((sys.stderr, f"Terminated ({name}): {done}\n"), (sys.stdout, "")):
                try:  # a closed stream, a hung-up terminal: the status still says it
                    stream.write(text)
                    stream.flush()
                except (AttributeError, OSError, ValueError):
                    pass
        finally:
            os._exit(TERMINATING[signum])

    handler.after_batch = True  # the CLI leaves this handler in place at its end
    for sig in TERMINATING:
        signal.signal(sig, handler)
    atexit.register(_ignore_sigterm_from_now)


def _ignore_sigterm_from_now() -> None:
    """Shutdown hook of :func:`terminate_after_batch`: its bytecode gives a pending SIGTERM
    or SIGHUP its handler (exit 143 or 129), then both are ignored for the rest of the
    shutdown (exit 0, everything written).  CPython's finalisation puts a Python-level handler back to the
    default action, so a SIGTERM there would kill the process (status -15, nothing said;
    tests/test_adversarial.py, seed 5, in a fresh environment); an ignored one stays ignored."""
    for sig in TERMINATING:
        signal.signal(sig, signal.SIG_IGN)


def mark_terminated(run_json, name: str = "SIGTERM") -> None:
    """Record in a finished batch's ``run_json`` that the signal ``name`` (SIGTERM, SIGHUP)
    ended the process after it."""
    from .outputs import write_json

    try:
        data = json.loads(Path(run_json).read_text(encoding="utf-8"))
        data.update(interrupted=True, stop_reason=f"terminated ({name}) after the batch had finished")
        write_json(Path(run_json), data)
    except Exception:  # noqa: BLE001 - the exit status still says it; never a traceback from a handler
        pass


def sigterm_as_interrupt():
    """Make SIGTERM (a scheduler cancelling the job, ``kill``) and SIGHUP (the terminal or
    the ssh session closed) end the batch like Ctrl-C.

    Returns the previous handlers, for :func:`restore_handlers`, or None where signals
    cannot be set (not the main thread).
    """
    if threading.current_thread() is not threading.main_thread():
        return None
    return {signal.SIGTERM: signal.signal(signal.SIGTERM, raise_terminated),
            signal.SIGHUP: signal.signal(signal.SIGHUP, raise_hung_up)}


def restore_handlers(previous) -> None:
    """Put back the handlers :func:`sigterm_as_interrupt` returned (None: nothing to do)."""
    for sig, handler in (previous or {}).items():
        signal.signal(sig, handler if handler is not None else signal.SIG_DFL)
