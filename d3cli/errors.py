"""Exception hierarchy of d3stereo.

Every error a user can cause is a :class:`D3Error`.  Its message names *where*
(file, pair, dotted config key), *what* (expected vs got) and *the fix*, in the form
``<where>: <what>; <fix>``.  Only ``d3cli.cli`` turns a D3Error into the one-line
``Error: ...`` and an exit code; library code raises, never prints.

Also the interrupts: :class:`Terminated` (SIGTERM turned into a KeyboardInterrupt) and
:func:`interrupt_behind`, shared by the CLI and the batch runner, which must agree on them.
"""


class D3Error(Exception):
    """Base class of every user-facing d3stereo error."""


class ConfigError(D3Error):
    """A configuration file, key or value is invalid."""


class InputError(D3Error):
    """An input file, image, pair or dataset layout is unusable."""


class BackendUnavailable(D3Error):
    """The requested compute backend (e.g. CUDA) cannot be used on this machine."""


class OutputError(D3Error):
    """An output folder or file cannot be written."""


#: How much of an offending value an error message quotes.
QUOTE_CHARS = 60


def shorten(text: str, limit: int = QUOTE_CHARS) -> str:
    """``text`` cut to ``limit`` characters (``...`` at the end when cut), for what a
    message shows of an option as the user wrote it (``--set key=<100,000 characters>``)."""
    return text if len(text) <= limit else text[: limit - 3] + "..."


def readable(text: str) -> str:
    """``text`` that can be written as UTF-8: the bytes of a file name that reached Python
    as lone surrogates (``os.fsdecode`` of a name that is not valid in the locale's
    encoding) are shown as the UTF-8 they are (a name with ``é`` under ``LC_ALL=C``) or,
    where they are not UTF-8 (a Latin-1 byte), as a visible ``\\xNN``; any other lone
    surrogate as ``\\udNNN``.  Every text file d3stereo writes passes through it, and so does
    what the terminal cannot encode: a name written raw would make a file invalid UTF-8,
    and writing it strictly fails."""
    if text.isascii():
        return text
    try:
        return text.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")
    except UnicodeEncodeError:  # a surrogate that no file name decoding made
        return text.encode("utf-8", "backslashreplace").decode("utf-8")


def plural(n: int, word: str, words: str | None = None) -> str:
    """``1 pair``, ``2 pairs``, ``0 pairs``: a count in a message; ``words`` for an
    irregular plural."""
    return f"{n} {word if n == 1 else words or word + 's'}"


def where_what_fix(where: str, what: str, fix: str) -> str:
    """Format a message as ``<where>: <what>; <fix>`` (the house style)."""
    return f"{where}: {what}; {fix}"


class Terminated(KeyboardInterrupt):
    """SIGTERM (``kill``, ``timeout``, a job scheduler's preemption), raised by a signal handler.

    A KeyboardInterrupt, so every path that stops cleanly on Ctrl-C stops the same way;
    ``terminated`` tells the CLI to exit with 143 (128 + SIGTERM) instead of 130.  One
    class for the batch runner (SIGTERM during a batch) and the CLI (before or after it):
    with two, a SIGTERM that stopped the batch before its pairs began (taking the lock,
    starting the workers) would come out as exit 130 (``tests/test_cli_interrupts.py``).
    """

    terminated = True
    signal_name = "SIGTERM"
    exit_status = 143  # 128 + SIGTERM


class HungUp(Terminated):
    """SIGHUP (the terminal or the ssh session closed), raised by :func:`raise_hung_up`;
    handled everywhere as SIGTERM is, but named SIGHUP and ending with exit status 129."""

    signal_name = "SIGHUP"
    exit_status = 129  # 128 + SIGHUP


def raise_terminated(signum, frame):
    """SIGTERM handler: raise :class:`Terminated` (``signal.signal(SIGTERM, raise_terminated)``)."""
    raise Terminated


def raise_hung_up(signum, frame):
    """SIGHUP handler: raise :class:`HungUp`."""
    raise HungUp


def interrupt_behind(exc: BaseException | None) -> KeyboardInterrupt | None:
    """The Ctrl-C/SIGTERM behind ``exc`` (itself, or in its chain of causes and contexts,
    8 links at most), or None.

    A signal that arrives while numba runs a compiled kernel surfaces as ``SystemError:
    ... returned a result with an exception set`` with the KeyboardInterrupt as its
    context: that is an interrupt, not a failure.
    """
    for _ in range(8):
        if exc is None or isinstance(exc, KeyboardInterrupt):
            return exc
        exc = exc.__cause__ or exc.__context__
    return None
