"""One run per output folder: the lock file, and the writability probe.

``OUT/.d3stereo.lock`` holds the pid, host and start of the run writing into ``OUT``,
and the run keeps an exclusive ``flock`` on it until it ends (:class:`Lock`).  Taking
the lock is one atomic step: ``flock(LOCK_EX | LOCK_NB)`` succeeds for one process
only, so two runs can never both take over a stale lock.  A lock file nobody holds
(its run was killed) is taken over with a warning when its record names a run of this
host that is gone (pid not running, or running but started at another time: a reused
pid).  A record from another host, or from a live pid of this host, is never taken
over: the error says to check that no run is writing, then rerun with ``--break-lock``.
A lock name that is a symbolic link, a hard link or not a regular file is refused, never
followed or written (it is not a lock file of d3stereo).
``--break-lock`` still never takes a lock that a running d3stereo holds.
"""

from __future__ import annotations

import errno
import json
import logging
import os
import socket
import stat
import tempfile
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows: the record checks alone
    fcntl = None

from ..errors import OutputError, where_what_fix

log = logging.getLogger(__name__)

LOCK_FILE = ".d3stereo.lock"

#: What to do about a lock that is not provably stale.
BREAK_HINT = ("if no d3stereo run is writing there (e.g. it was killed on another machine), "
              "rerun with --break-lock; else wait for it or use another -o folder")


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


def _pid_start(pid: int) -> str | None:
    """Start time of process ``pid`` (clock ticks since boot, Linux), None where unknown.

    With the pid it identifies a process: a pid reused by another process starts later.
    """
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as fh:
            stat = fh.read()
        return stat[stat.rindex(")") + 2:].split()[19]  # field 22, after "pid (comm)"
    except (OSError, ValueError, IndexError):
        return None


def _read_holder(fd: int) -> dict | None:
    try:
        os.lseek(fd, 0, os.SEEK_SET)
        data = json.loads(os.read(fd, 1 << 16).decode("utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or not isinstance(data.get("pid"), int):
        return None
    return data


def _read_lock(path: Path) -> dict | None:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or not isinstance(data.get("pid"), int):
        return None
    return data


def _why_not_stale(holder: dict) -> str | None:
    """None when the record of a lock file nobody holds names a run that is gone, else who it names."""
    if holder.get("host") != socket.gethostname():
        return f"pid {holder['pid']} on {holder.get('host')}"  # cannot be checked from here
    if not _pid_alive(holder["pid"]):
        return None
    start = _pid_start(holder["pid"])
    if holder.get("pid_start") is not None and start is not None and start != holder["pid_start"]:
        return None  # the pid now belongs to another process
    return f"pid {holder['pid']}"


def _size(fd: int) -> int:
    try:
        return os.fstat(fd).st_size
    except OSError:
        return 0


@dataclass
class Lock:
    """The lock of one output folder, held (open file with an exclusive flock) until released.

    Attributes
    ----------
    path : Path
        The lock file.
    fd : int
        Its open descriptor, which holds the flock; -1 once released.
    """

    path: Path
    fd: int = -1

    def __fspath__(self) -> str:
        return os.fspath(self.path)


def _flock(fd: int, path: Path) -> bool:
    """Take an exclusive, non-blocking flock; False when another process holds it."""
    if fcntl is None:
        return True
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    except OSError as exc:
        if exc.errno in (errno.EWOULDBLOCK, errno.EACCES, errno.EAGAIN):
            return False
        # A file system without locks (some network mounts): the record checks alone remain.
        log.warning("%s: file locks unsupported here (%s); only the pid/host record guards this folder",
                    path, exc.strerror or exc)
    return True


def _refuse(out: Path, holder: dict | None, *, held: bool) -> OutputError:
    pid = holder["pid"] if holder else "unknown"
    host = "" if holder is None or holder.get("host") == socket.gethostname() else f" on {holder.get('host')}"
    if held:  # a live d3stereo holds it right now: --break-lock would not help
        return OutputError(where_what_fix(str(out), f"another d3stereo run (pid {pid}{host}) is writing here",
                                          "wait for it or use another -o folder"))
    return OutputError(where_what_fix(str(out), f"the folder is locked by a d3stereo run (pid {pid}{host}) "
                                                "that may still be running", BREAK_HINT))


def _open_lock_file(path: Path) -> int:
    """Open (create) the lock file itself: never through a symbolic link, never a FIFO,
    a device or a file with other names (a link ``OUT/.d3stereo.lock`` to a user's file
    had the lock record written into that file)."""
    flags = os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0)
    try:
        fd = os.open(path, flags, 0o644)
    except OSError as exc:
        if os.path.islink(path):
            raise OutputError(where_what_fix(
                str(path), f"is a symbolic link (to {os.readlink(path)}), not a lock file of d3stereo",
                "remove the link (what it points to is left alone) and rerun")) from None
        raise OutputError(where_what_fix(str(path), f"cannot create the lock file ({exc.strerror or exc})",
                                         "choose another folder with -o or fix its permissions")) from None
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode) or st.st_nlink > 1:
        os.close(fd)
        what = "is not a regular file" if not stat.S_ISREG(st.st_mode) else \
            f"has {st.st_nlink} names (a hard link to another file)"
        raise OutputError(where_what_fix(str(path), f"{what}, not a lock file of d3stereo",
                                         "remove it (nothing else is touched) and rerun"))
    return fd


def acquire_lock(out: Path, name: str = LOCK_FILE, *, break_lock: bool = False) -> Lock:
    """Take ``out/<name>`` (default ``.d3stereo.lock``) for this process: see the module docstring.

    ``--shard I/N`` runs take a lock of their own (:func:`shard_lock_name`), so shards
    share one output folder while two runs of the same shard still exclude each other.

    Parameters
    ----------
    out : Path
        The output folder (must exist).
    name : str
        Lock file name.
    break_lock : bool, keyword-only
        Take over a lock file nobody holds even when its record names another host or a
        live pid (``--break-lock``, after checking that no run writes there).

    Returns
    -------
    Lock
        Held until :func:`release_lock`.

    Raises
    ------
    OutputError
        ``OUT: another d3stereo run (pid N) is writing here; wait for it or use another
        -o folder`` when a run holds the lock; ``OUT: the folder is locked by a d3stereo
        run (pid N on HOST) that may still be running; ... --break-lock ...`` when the
        record cannot be proven stale; or when the lock cannot be created.
    """
    path = out / name
    for _attempt in range(20):
        fd = _open_lock_file(path)
        try:
            if not _flock(fd, path):
                holder = _read_holder(fd)
                raise _refuse(out, holder, held=True)
            # A run that released (unlinked) the file between our open and flock leaves us
            # holding a lock on a file that no longer has this name: try again.
            try:
                same = os.path.samestat(os.fstat(fd), os.stat(path))
            except FileNotFoundError:
                same = False
            if not same:
                os.close(fd)
                fd = -1
                continue
            holder = _read_holder(fd)
            if holder is not None:  # nobody holds the flock: its run ended, or it predates flock
                why = _why_not_stale(holder)
                if why is not None and not break_lock:
                    raise _refuse(out, holder, held=False)
                if why is not None:
                    log.warning("%s: --break-lock: taking over the lock of %s", path, why)
                else:
                    log.warning("%s: taking over the stale lock of a run that is gone (pid %s on %s)",
                                path, holder["pid"], holder.get("host"))
            elif _size(fd) > 0:
                log.warning("%s: taking over an unreadable lock file that no run holds", path)
            record = {"pid": os.getpid(), "host": socket.gethostname(), "pid_start": _pid_start(os.getpid()),
                      "started": datetime.now(timezone.utc).isoformat(timespec="seconds")}
            os.ftruncate(fd, 0)
            os.lseek(fd, 0, os.SEEK_SET)
            os.write(fd, json.dumps(record).encode("utf-8"))
            os.fsync(fd)
            return Lock(path, fd)
        except BaseException:
            if fd >= 0:
                os.close(fd)  # also drops the flock
            raise
    raise OutputError(where_what_fix(str(out), "the lock file keeps being replaced by other runs",
                                     "wait for them or use another -o folder"))


def shard_lock_name(index: int, total: int) -> str:
    """Lock file name of shard ``index`` of ``total``."""
    return f".d3stereo-shard-{index}-of-{total}.lock"


def release_lock(lock) -> None:
    """Remove the lock file (while still holding its flock, so no run takes a name being
    removed) and drop the flock.

    ``lock`` is the :class:`Lock` of :func:`acquire_lock`; given a bare path (a lock of
    an older version), the file is removed when its record is this process's.
    """
    if not isinstance(lock, Lock):
        path = Path(lock)
        holder = _read_lock(path)
        if holder is not None and holder.get("pid") == os.getpid() and holder.get("host") == socket.gethostname():
            path.unlink(missing_ok=True)
        return
    if lock.fd < 0:
        return
    try:
        holder = _read_holder(lock.fd)
        if holder is not None and holder.get("pid") == os.getpid() and holder.get("host") == socket.gethostname():
            try:
                if os.path.samestat(os.fstat(lock.fd), os.stat(lock.path)):
                    lock.path.unlink()
            except FileNotFoundError:
                pass
            except OSError as exc:
                log.warning("%s: could not remove the lock file (%s); delete it by hand", lock.path, exc)
    finally:
        os.close(lock.fd)
        lock.fd = -1
