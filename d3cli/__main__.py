"""``python -m d3cli`` is the ``d3stereo`` command (:func:`entry`, also the console script).

Nothing is imported here before :func:`entry` runs but the package's own light
``__init__``, so a Ctrl-C while Python imports click, numpy or numba (the first second of
a run) ends with exit 130 and one line, not a KeyboardInterrupt traceback and death by
the signal.
"""

import signal
import sys

#: Exit status after Ctrl-C (128 + SIGINT), as d3cli.cli.INTERRUPTED_EXIT.
_INTERRUPTED_EXIT = 130


def entry() -> None:
    """Run the ``d3stereo`` command line; a Ctrl-C before its own handler is in place
    (while importing) exits 130 with ``Interrupted; rerun the same command to resume``."""
    try:
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
