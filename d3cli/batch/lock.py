"""One run per output folder: the lock file, and the writability probe.

``OUT/.d3stereo.lock`` (created with O_EXCL, holding pid and host) makes a second run
fail with a clear error; a lock left by a run that no longer exists on this host is
taken over with a warning.
"""

from __future__ import annotations

import json
import logging
import os
import socket
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

from ..errors import OutputError, where_what_fix

log = logging.getLogger(__name__)

LOCK_FILE = ".d3stereo.lock"

#: A lock file that cannot be read is taken as stale only when older than this (seconds):
#: a run that has just created it may not have written its pid yet.
LOCK_GRACE_S = 5.0


def ensure_writable(out_dir: str | os.PathLike) -> Path:
    """Create ``out_dir`` (with parents) and prove it is writable with a probe file.

    Raises
    ------
    OutputError
        Naming the folder, when it cannot be created or written.
    """
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=out, prefix=".d3stereo-probe-")
        os.close(fd)
        os.remove(probe)
    except OSError as exc:
        reason = exc.strerror or str(exc)
        raise OutputError(
            where_what_fix(str(out), f"cannot write to the output folder ({reason})",
                           "choose another folder with -o or fix its permissions")
        ) from None
    return out


def _pid_alive(pid: int) -> bool:
    """True when process ``pid`` exists on this host (or when that cannot be told)."""
    if pid <= 0:
        return False
    if os.name == "nt":  # os.kill(pid, 0) would terminate the process there
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # EPERM: it exists, owned by someone else
        return True
    return True


def _read_lock(path: Path) -> dict | None:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or not isinstance(data.get("pid"), int):
        return None
    return data


def _lock_is_stale(path: Path, holder: dict | None) -> bool:
    if holder is None:
        try:
            age = time.time() - path.stat().st_mtime
        except OSError:
            return True  # gone already
        return age > LOCK_GRACE_S
    if holder.get("host") != socket.gethostname():
        return False  # another machine's process cannot be checked from here
    return not _pid_alive(holder["pid"])


def acquire_lock(out: Path, name: str = LOCK_FILE) -> Path:
    """Create ``out/<name>`` (default ``.d3stereo.lock``; O_EXCL) holding this process's pid and host.

    ``--shard I/N`` runs take a lock of their own (:func:`shard_lock_name`), so shards
    share one output folder while two runs of the same shard still exclude each other.

    A lock whose process is gone (same host) or that is unreadable and older than
    :data:`LOCK_GRACE_S` is taken over with a warning.

    Returns
    -------
    Path
        The lock file, for :func:`release_lock`.

    Raises
    ------
    OutputError
        ``OUT: another d3stereo run (pid N) is writing here; wait for it or use another
        -o folder``, or when the lock cannot be created.
    """
    path = out / name
    for attempt in range(2):
        try:
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:
            holder = _read_lock(path)
            if attempt == 0 and _lock_is_stale(path, holder):
                who = f"pid {holder['pid']} on {holder.get('host')}" if holder else "an unreadable lock"
                log.warning("%s: taking over the stale lock of a run that is gone (%s)", path, who)
                path.unlink(missing_ok=True)
                continue
            pid = holder["pid"] if holder else "unknown"
            host = "" if holder is None or holder.get("host") == socket.gethostname() else f" on {holder.get('host')}"
            raise OutputError(where_what_fix(str(out), f"another d3stereo run (pid {pid}{host}) is writing here",
                                             "wait for it or use another -o folder")) from None
        except OSError as exc:
            raise OutputError(where_what_fix(str(path), f"cannot create the lock file ({exc.strerror or exc})",
                                             "choose another folder with -o or fix its permissions")) from None
        holder = {"pid": os.getpid(), "host": socket.gethostname(),
                  "started": datetime.now(timezone.utc).isoformat(timespec="seconds")}
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            json.dump(holder, fh)
        return path
    raise OutputError(where_what_fix(str(out), "another d3stereo run took the lock over at the same moment",
                                     "wait for it or use another -o folder"))


def shard_lock_name(index: int, total: int) -> str:
    """Lock file name of shard ``index`` of ``total``."""
    return f".d3stereo-shard-{index}-of-{total}.lock"


def release_lock(path: Path) -> None:
    """Remove the lock file when it is still this process's (not one taken over since)."""
    holder = _read_lock(path)
    if holder is not None and holder.get("pid") == os.getpid() and holder.get("host") == socket.gethostname():
        try:
            path.unlink()
        except OSError as exc:
            log.warning("%s: could not remove the lock file (%s); delete it by hand", path, exc)
