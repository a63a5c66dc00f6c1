"""Atomic writes (temporary sibling, then ``os.replace``) and full-disk detection."""

from __future__ import annotations

import errno
import logging
import os
from pathlib import Path
from typing import Callable

from ...errors import OutputError, where_what_fix

log = logging.getLogger(__name__)


def atomic_write(path: str | os.PathLike, write_fn: Callable[[Path], object]) -> Path:
    """Write a file atomically.

    ``write_fn(tmp)`` writes a temporary file in the same folder whose name keeps the
    extension (``.disp.png.tmp-<pid>.png``, so format-by-extension writers work); it is
    then renamed over ``path`` with :func:`os.replace`.  The temporary file is removed
    when anything fails.

    Parameters
    ----------
    path : str or path-like
        Final file name; its folder must exist.
    write_fn : callable
        Called with the temporary path; must create that file.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    OutputError
        The folder is missing or not writable, or the write failed with an OS error.
    """
    path = Path(path)
    folder = path.parent
    if not folder.is_dir():
        what = "output folder is a file" if folder.exists() else "output folder does not exist"
        raise OutputError(where_what_fix(str(folder), what, "create it or choose another output folder"))
    if not os.access(folder, os.W_OK):
        raise OutputError(
            where_what_fix(str(folder), "output folder is not writable", "fix its permissions or choose another one")
        )
    tmp = folder / f".{path.name}.tmp-{os.getpid()}{path.suffix}"
    try:
        write_fn(tmp)
        if not tmp.is_file():
            raise OutputError(where_what_fix(str(path), "the writer produced no file", "report this as a bug"))
        os.replace(tmp, path)
    except OSError as exc:
        _remove_quietly(tmp)
        raise _write_error(path, exc) from None
    except BaseException:  # KeyboardInterrupt included: no temporary file stays behind
        _remove_quietly(tmp)
        raise
    return path


#: errno values that mean "the disk (or the quota) is full".
DISK_FULL_ERRNOS = frozenset({errno.ENOSPC, getattr(errno, "EDQUOT", errno.ENOSPC)})


def _write_error(path: Path, exc: OSError) -> OutputError:
    """OutputError for a failed write; carries ``errno`` so a batch can stop on a full disk."""
    if exc.errno in DISK_FULL_ERRNOS:
        fix = "free disk space, then rerun the same command (finished pairs are kept and skipped)"
    else:
        fix = "check free space and permissions"
    error = OutputError(where_what_fix(str(path), f"cannot write ({exc.strerror or exc})", fix))
    error.errno = exc.errno
    return error


def is_disk_full(exc: BaseException) -> bool:
    """True when ``exc`` (an OSError or an OutputError from a write) means the disk is full."""
    return getattr(exc, "errno", None) in DISK_FULL_ERRNOS


def _remove_quietly(path: Path) -> None:
    try:
        path.unlink()
    except FileNotFoundError:
        pass
    except OSError as exc:  # the original error matters more than this one
        log.warning("could not remove temporary file %s: %s", path, exc)
