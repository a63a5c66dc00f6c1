"""The steps of a pair, so that a bug says it is one and where it happened.

A user's mistake is a :class:`~d3cli.errors.D3Error` and names its fix.  Anything else
that escapes a step of a pair (an OpenCV assertion, a numpy MemoryError from a bad
geometry, a TypeError) is a defect of d3stereo: :func:`step` wraps it in an
:class:`InternalError` naming the step, and the pair's error reads
``p1: internal error in road report (cv2.error: ...); please report it``
(:func:`internal_message`).
"""

from __future__ import annotations

import contextlib

from ..errors import D3Error, interrupt_behind

#: Longest library message kept in a pair's error (cv2.error's run to several lines).
MESSAGE_LIMIT = 300


class InternalError(Exception):
    """An unexpected exception in step ``step`` of a pair.

    Attributes
    ----------
    step : str
        What the pair was doing (``"matching"``, ``"road report"``, ...).
    cause : BaseException
        The exception raised there.
    """

    def __init__(self, step: str, cause: BaseException):
        super().__init__(step, cause)
        self.step, self.cause = step, cause

    def __reduce__(self):  # travels back from a pool worker whole
        return (InternalError, (self.step, self.cause))

    def __str__(self) -> str:
        return f"internal error in {self.step} ({describe(self.cause)}); please report it"


def type_name(exc: BaseException) -> str:
    """``RuntimeError``, ``cv2.error``, ``MemoryError`` (for numpy's private ``_ArrayMemoryError``):
    the first public class of ``exc``, with its package unless it is a built-in."""
    cls = next((c for c in type(exc).__mro__ if not c.__qualname__.startswith("_")), type(exc))
    package = cls.__module__.split(".")[0]
    return cls.__qualname__ if package == "builtins" else f"{package}.{cls.__qualname__}"


def describe(exc: BaseException) -> str:
    """``Type: message`` of ``exc`` on one line, at most :data:`MESSAGE_LIMIT` characters."""
    text = " ".join(str(exc).split())
    if len(text) > MESSAGE_LIMIT:
        text = text[:MESSAGE_LIMIT - 3] + "..."
    return f"{type_name(exc)}: {text}" if text else type_name(exc)


@contextlib.contextmanager
def step(name: str):
    """Run a step of a pair: D3Errors and interrupts pass, anything else becomes an
    :class:`InternalError` naming ``name``."""
    try:
        yield
    except (D3Error, InternalError):
        raise
    except Exception as exc:
        if interrupt_behind(exc) is not None:
            raise  # Ctrl-C inside a numba kernel: the batch stops, the pair is not failed
        raise InternalError(name, exc) from exc


def internal_message(pair_name: str, exc: BaseException) -> str:
    """The pair's error for an unexpected exception: ``<pair>: internal error in <step>
    (<Type>: <message>); please report it``."""
    if not isinstance(exc, InternalError):
        exc = InternalError("the batch runner", exc)
    return f"{pair_name}: {exc}"
