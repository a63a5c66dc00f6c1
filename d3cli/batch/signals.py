"""Signals during a batch: Ctrl-C and SIGTERM end it cleanly, never half-way through a record.

:func:`sigterm_as_interrupt` makes a scheduler's SIGTERM end the batch like Ctrl-C;
:func:`signals_deferred` holds both back while the lock is taken or the kernels load;
:func:`signals_held` ignores them while run.json records an interruption;
:func:`interrupts_unwrapped` lets a Ctrl-C wrapped in another exception stop the batch.
"""

from __future__ import annotations

import contextlib
import signal
import threading

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
    is delivered once the block is done, by calling its own handler.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending = []
    held = {}
    for sig in (signal.SIGINT, signal.SIGTERM):
        handler = signal.getsignal(sig)
        if callable(handler):
            held[sig] = handler
            signal.signal(sig, lambda signum, frame: pending.append(signum))
    try:
        yield
    finally:
        for sig, handler in held.items():
            signal.signal(sig, handler)
    if pending:
        held[pending[0]](pending[0], None)


def sigterm_as_interrupt():
    """Make SIGTERM (a scheduler cancelling the job, ``kill``) end the batch like Ctrl-C.

    Returns the previous handler, or None where signals cannot be set (not the main thread).
    """
    if threading.current_thread() is not threading.main_thread():
        return None
    return signal.signal(signal.SIGTERM, raise_terminated)
