"""``python -m d3cli`` is the ``d3stereo`` command (:func:`entry`, also the console script).

Nothing is imported here before :func:`entry` runs but the package's own light
``__init__`` and the standard library, so a Ctrl-C while Python imports click, numpy or
numba (the first second of a run) ends with exit 130 and one line, not a
KeyboardInterrupt traceback and death by the signal.

Before anything else :func:`entry` makes the output streams safe (:func:`safe_streams`)
and checks the environment variables numba and OpenCV read (:func:`check_environment`):
both libraries fail on a bad value with a traceback or an abort, long after the command
started.
"""

from __future__ import annotations

import codecs
import errno
import io
import os
import signal
import sys

#: Exit status after Ctrl-C (128 + SIGINT), as d3cli.cli.INTERRUPTED_EXIT.
_INTERRUPTED_EXIT = 130

#: Name of the encoding error handler of the output streams (:func:`escape_unencodable`).
ESCAPE_ERRORS = "d3stereo-escape"
#: errno values of a write whose reader is gone: a closed pipe, a hung-up terminal.
_READER_GONE = (errno.EPIPE, errno.EIO)
#: At most this many characters of a variable's value are quoted in a message.
_QUOTED = 60
#: numba's threading layers (``NUMBA_THREADING_LAYER``): the names numba knows.
_THREADING_LAYERS = ("default", "safe", "threadsafe", "forksafe", "workqueue", "omp", "tbb")
#: OpenCV's decoder limits and an example value for each (its default).
_OPENCV_LIMITS = {"OPENCV_IO_MAX_IMAGE_WIDTH": 1 << 20, "OPENCV_IO_MAX_IMAGE_HEIGHT": 1 << 20,
                  "OPENCV_IO_MAX_IMAGE_PIXELS": 1 << 30}


def escape_unencodable(exc: UnicodeEncodeError):
    """Encoding error handler of the output streams: what a stream's encoding cannot write
    is shown escaped instead of ending the command.

    A file name whose bytes are not valid in the locale's encoding reaches Python as lone
    surrogates (``os.fsdecode``): those bytes are shown as UTF-8 where they are UTF-8 (a
    name with ``é`` under ``LC_ALL=C``) and as ``\\xNN`` where they are not (a Latin-1 byte);
    any other character the encoding lacks is shown as ``\\uNNNN``-style escapes.
    """
    if not isinstance(exc, UnicodeEncodeError):
        raise exc
    text = exc.object[exc.start:exc.end]
    try:
        text = text.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")
    except UnicodeEncodeError:  # a surrogate no file name decoding made
        pass
    return text.encode(exc.encoding, "backslashreplace"), exc.end


class _QuietWhenGone(io.RawIOBase):
    """Raw writer of an output file descriptor that ends quietly when its reader is gone:
    after the first EPIPE (``d3stereo configs | head -0``) or EIO (the terminal hung up),
    the descriptor is pointed at /dev/null, so the rest of the output, and Python's flush at
    exit, go nowhere instead of raising BrokenPipeError in the middle of the command."""

    def __init__(self, fd: int):
        super().__init__()
        self._fd = fd

    def writable(self) -> bool:
        return True

    def fileno(self) -> int:
        return self._fd

    def isatty(self) -> bool:
        try:
            return os.isatty(self._fd)
        except OSError:
            return False

    def write(self, data) -> int:
        try:
            return os.write(self._fd, data)
        except OSError as exc:
            if exc.errno not in _READER_GONE:
                raise
            _point_at_devnull(self._fd)
            return len(data)


def _point_at_devnull(fd: int) -> None:
    """Make ``fd`` refer to /dev/null (opened for writing, or reading for fd 0)."""
    null = os.open(os.devnull, os.O_RDONLY if fd == 0 else os.O_WRONLY)
    if null != fd:
        os.dup2(null, fd)
        os.close(null)


def _is_open(fd: int) -> bool:
    try:
        os.fstat(fd)
    except OSError:
        return False
    return True


def safe_streams() -> None:
    """No output stream is assumed open, and none ends the command.

    * A standard descriptor that is closed (``2>&-``) is opened on /dev/null: the command
      runs and exits by its result, and no file the command opens later takes fd 1 or 2
      (where a C library's message would land in it).
    * stdout and stderr are rebuilt on :class:`_QuietWhenGone`: a reader that went away
      (a closed pipe, a hung-up terminal) silences them; the command finishes its work.
    * Characters the locale cannot encode (a non-UTF-8 byte of a file name) are escaped
      (:func:`escape_unencodable`), never an error; an ASCII locale (``LC_ALL=C``) gets
      UTF-8, which is what Python writes there unless told otherwise.
    """
    codecs.register_error(ESCAPE_ERRORS, escape_unencodable)
    for fd in (0, 1, 2):
        if not _is_open(fd):
            _point_at_devnull(fd)
    for name, fd in (("stdout", 1), ("stderr", 2)):
        stream = getattr(sys, name)
        encoding = getattr(stream, "encoding", None) or sys.getfilesystemencoding()
        if codecs.lookup(encoding).name == "ascii":
            # The C locale: UTF-8, as Python's UTF-8 mode (its default there) and click write.
            encoding = "utf-8"
        line_buffering = getattr(stream, "line_buffering", True)
        if stream is not None:
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        writer = io.BufferedWriter(_QuietWhenGone(fd))
        setattr(sys, name, io.TextIOWrapper(writer, encoding=encoding, errors=ESCAPE_ERRORS,
                                            line_buffering=line_buffering or name == "stderr"))


def _quoted(value: str) -> str:
    """``value`` as a message quotes it: at most 60 characters, name bytes escaped."""
    if len(value) > _QUOTED:
        value = value[:_QUOTED - 3] + "..."
    return value.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")


def _whole(text: str, minimum: int) -> bool:
    """Whether ``text`` is a plain decimal number >= ``minimum`` (no sign, no spaces)."""
    return text.isascii() and text.isdigit() and int(text) >= minimum


def check_environment(environ=os.environ) -> str | None:
    """The message for the first environment variable numba or OpenCV would fail on, or None.

    Both read these at import or at the first decode, and a bad value ends the command
    there: numba with a ``ValueError`` traceback (``NUMBA_NUM_THREADS=0``, an unknown
    ``NUMBA_THREADING_LAYER``), OpenCV with an abort (exit 134) on an
    ``OPENCV_IO_MAX_IMAGE_*`` limit that is no number.  A ``NUMBA_NUM_THREADS`` that is no
    number, which numba would silently replace by its default, is refused too: the user
    meant something else.  Checked before either library is imported.
    """
    checks = [("NUMBA_NUM_THREADS", lambda v: _whole(v, 1),
               "numba needs a whole number of threads, 1 or more; set it to a number such as 4, or unset it "
               "(numba then uses one thread per core)"),
              ("NUMBA_THREADING_LAYER", lambda v: v in _THREADING_LAYERS,
               f"numba knows {', '.join(_THREADING_LAYERS[:-1])} and {_THREADING_LAYERS[-1]}; "
               "set one of these, or unset it")]
    checks += [(name, lambda v: _whole(v, 0),
                f"OpenCV needs a whole number of pixels, 0 or more (it aborts on anything else); set it to a "
                f"number such as {default}, or unset it") for name, default in _OPENCV_LIMITS.items()]
    for name, valid, fix in checks:
        value = environ.get(name)
        if value is not None and not valid(value):
            return f"environment variable {name}={_quoted(value)}: {fix}"
    return None


def entry() -> None:
    """Run the ``d3stereo`` command line; a Ctrl-C before its own handler is in place
    (while importing) exits 130 with ``Interrupted; rerun the same command to resume``."""
    try:
        safe_streams()
        problem = check_environment()
        if problem is not None:
            sys.stderr.write(f"Error: {problem}\n")
            sys.stderr.flush()
            sys.exit(1)
        from .cli import main

        main(prog_name="d3stereo")
    except KeyboardInterrupt:
        # Any later interrupt must not kill the process by the signal: ignore SIGINT, and
        # clear CPython's "unhandled KeyboardInterrupt" flag, which a KeyboardInterrupt
        # raised inside exec()'d code (dataclasses, namedtuple: run while importing) sets
        # even when caught (see d3cli.cli._end_of_command); exec() of a string clears it.
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        exec("pass")  # noqa: S102
        sys.stderr.write("Interrupted; rerun the same command to resume\n")
        sys.exit(_INTERRUPTED_EXIT)


if __name__ == "__main__":
    entry()
