"""Exception hierarchy of d3stereo.

Every error a user can cause is a :class:`D3Error`.  Its message names *where*
(file, pair, dotted config key), *what* (expected vs got) and *the fix*, in the form
``<where>: <what>; <fix>``.  Only ``d3cli.cli`` turns a D3Error into the one-line
``Error: ...`` and an exit code; library code raises, never prints.
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


def where_what_fix(where: str, what: str, fix: str) -> str:
    """Format a message as ``<where>: <what>; <fix>`` (the house style)."""
    return f"{where}: {what}; {fix}"
