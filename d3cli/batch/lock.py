"""One writer per output folder: the lock files, and the writability probe.

Every command that writes into ``OUT`` (``run``, ``run --shard I/N``, ``eval -o OUT``)
takes ``OUT/.d3stereo.lock`` first (:func:`acquire_lock`), with an ``flock`` held until
it ends:

* a plain run and an eval take it exclusively: nothing else writes OUT meanwhile;
* ``--shard I/N`` takes it shared, so the shards of one batch (the same N) write into one
  OUT at the same time (the point of splitting a batch over a cluster's jobs), and then
  takes its own ``OUT/.d3stereo-shard-I-of-N.lock`` exclusively: two runs of one shard
  exclude each other.  A shard of another split (another N) is refused: its pairs are
  not disjoint from the running ones'.

Each exclusive lock file holds the pid, host, start and command of its writer; a writer
that is refused is named from these records (the shards' records when the folder is
shared).  Taking a lock is one atomic step: ``flock(LOCK_NB)`` succeeds or fails whole,
so two runs can never both take over a stale lock.

The records also guard where ``flock`` does not (a run killed with its lock file left
behind; a file system without locks across hosts).  A record nobody holds is taken over
with a warning when it names a run of this host that is gone (pid not running, or
running but started at another time: a reused pid); one from another host, or from a
live pid of this host, is never taken over: the error says to check that no run is
writing, then rerun with ``--break-lock``.  A plain run or eval checks the shard lock
files in OUT the same way, a shard those of other splits.  A lock name that is a
symbolic link, a hard link or not a regular file is refused, never followed or written
(it is not a lock file of d3stereo).  ``--break-lock`` still never takes a lock that a
running d3stereo holds.
"""

from __future__ import annotations

import errno
import json
import logging
import os
import re
import socket
import stat
import tempfile
import time
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
#: A shard's own lock file: ``.d3stereo-shard-I-of-N.lock`` (:func:`shard_lock_name`).
_SHARD_LOCK = re.compile(r"\.d3stereo-shard-(\d+)-of-(\d+)\.lock")
#: The writer a record without a command names (written by an earlier d3stereo run).
_DEFAULT_COMMAND = "d3stereo run"

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
    """The record in the lock file ``path``; None when there is none, or when ``path`` is
    not a regular file (never opened then: a FIFO would block)."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0))
    except OSError:
        return None
    try:
        return _read_holder(fd) if stat.S_ISREG(os.fstat(fd).st_mode) else None
    finally:
        os.close(fd)


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
    """The lock of one output folder, held (an open file with an flock) until released.

    Attributes
    ----------
    path : Path
        The lock file (``OUT/.d3stereo.lock`` for the folder).
    fd : int
        Its open descriptor, which holds the flock; -1 once released.
    shared : bool
        Held shared (by a shard of a batch) rather than exclusively.
    inner : Lock or None
        A shard's own lock, held inside the folder's and released before it.
    """

    path: Path
    fd: int = -1
    shared: bool = False
    inner: "Lock | None" = None

    def __fspath__(self) -> str:
        return os.fspath(self.path)


def _flock(fd: int, path: Path, *, exclusive: bool = True, warn: bool = True) -> bool:
    """Take an exclusive (or shared), non-blocking flock; False when another open file holds
    one that conflicts."""
    if fcntl is None:
        return True
    try:
        fcntl.flock(fd, (fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH) | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    except OSError as exc:
        if exc.errno in (errno.EWOULDBLOCK, errno.EACCES, errno.EAGAIN):
            return False
        # A file system without locks (some network mounts): the record checks alone remain.
        if warn:
            log.warning("%s: file locks unsupported here (%s); only the pid/host record guards this folder",
                        path, exc.strerror or exc)
    return True


def _writer(holder: dict) -> str:
    """``d3stereo eval (pid 12 on node7)``: the command and process a lock record names."""
    command = holder.get("command")
    if not isinstance(command, str) or not command.isprintable() or not command.startswith("d3stereo "):
        command = _DEFAULT_COMMAND  # a record of an earlier d3stereo, or not one of ours
    host = "" if holder.get("host") == socket.gethostname() else f" on {holder.get('host')}"
    return f"{command[:60]} (pid {holder['pid']}{host})"


def _refuse(out: Path, holders: list, *, held: bool) -> OutputError:
    """The error of a folder another writer has: ``held`` when a running d3stereo holds the
    flock (--break-lock would not help), else a record that may name a running one."""
    if held:
        if len(holders) > 1:  # the shards of a batch; a hundred of them are not all named
            names = [_writer(holder) for holder in holders[:3]]
            if len(holders) > 3:
                names.append(f"{len(holders) - 3} more")
            return OutputError(where_what_fix(str(out), f"{', '.join(names[:-1])} and {names[-1]} are writing here",
                                              "wait for them or use another -o folder"))
        who = _writer(holders[0]) if holders else f"{_DEFAULT_COMMAND} (pid unknown)"
        return OutputError(where_what_fix(str(out), f"another {who} is writing here",
                                          "wait for it or use another -o folder"))
    return OutputError(where_what_fix(str(out), f"the folder is locked by a {_writer(holders[0])} "
                                                "that may still be running", BREAK_HINT))


def _open_lock_file(path: Path, *, create: bool = True) -> int:
    """Open (by default create) the lock file itself: never through a symbolic link, never
    a FIFO, a device or a file with other names (a link ``OUT/.d3stereo.lock`` to a user's
    file must not have the lock record written into that file)."""
    flags = os.O_RDWR | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0) | (os.O_CREAT if create else 0)
    try:
        fd = os.open(path, flags, 0o644)
    except OSError as exc:
        if os.path.islink(path):
            raise OutputError(where_what_fix(
                str(path), f"is a symbolic link (to {os.readlink(path)}), not a lock file of d3stereo",
                "remove the link (what it points to is left alone) and rerun")) from None
        if not create and exc.errno == errno.ENOENT:
            raise
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


def _still_named(fd: int, path: Path) -> bool:
    """True when ``path`` still names the open file ``fd`` (a releasing run unlinks it)."""
    try:
        return os.path.samestat(os.fstat(fd), os.stat(path))
    except FileNotFoundError:
        return False


def _shard_locks(out: Path) -> list[tuple[int, int, Path]]:
    """``(I, N, path)`` of every shard lock file in ``out``."""
    try:
        names = os.listdir(out)
    except OSError:
        return []
    found = []
    for name in names:
        match = _SHARD_LOCK.fullmatch(name)
        if match:
            found.append((int(match[1]), int(match[2]), out / name))
    return sorted(found)


def _holders(out: Path, path: Path, fd: int) -> list:
    """The records of whoever holds ``path`` (opened as ``fd``): its own record, or, for
    the folder's lock shared by shards (no record of its own), the records of the shard
    locks whose process may be running.  Read without taking their flock: a shard taking
    its own lock at that moment must not find it taken by this look."""
    holder = _read_holder(fd)
    if holder is not None or path.name != LOCK_FILE:
        return [holder] if holder is not None else []
    holders = []
    for _index, _total, shard_path in _shard_locks(out):
        record = _read_lock(shard_path)
        if record is not None and _why_not_stale(record) is not None:
            holders.append(record)
    return holders


def _take(out: Path, path: Path, *, exclusive: bool, command: str, break_lock: bool) -> Lock:
    """Take the lock file ``path`` of ``out`` exclusively (recording this process in it) or
    shared (its record, if any, must name a writer that is gone: it is cleared)."""
    attempts = 20
    for attempt in range(attempts):
        fd = _open_lock_file(path)
        try:
            if not _flock(fd, path, exclusive=exclusive):
                holders = _holders(out, path, fd)
                if holders or attempt == attempts - 1:
                    raise _refuse(out, holders, held=True)
                # Nobody named yet: a writer between its flock and its record, or the last
                # shard releasing the folder's lock.  Asked again in a moment.
                os.close(fd)
                fd = -1
                time.sleep(0.05)
                continue
            # A run that released (unlinked) the file between our open and flock leaves us
            # holding a lock on a file that no longer has this name: try again.
            if not _still_named(fd, path):
                os.close(fd)
                fd = -1
                continue
            # A record nobody holds: its writer ended without removing it (killed), or it
            # writes on a file system whose flock does not reach here.
            holder = _read_holder(fd)
            if holder is not None:
                _take_over(out, path, holder, break_lock=break_lock)
            elif _size(fd) > 0:
                log.warning("%s: taking over an unreadable lock file that no run holds", path)
            if _size(fd) > 0:
                os.ftruncate(fd, 0)
            if exclusive:
                record = {"pid": os.getpid(), "host": socket.gethostname(), "pid_start": _pid_start(os.getpid()),
                          "started": datetime.now(timezone.utc).isoformat(timespec="seconds"), "command": command}
                os.lseek(fd, 0, os.SEEK_SET)
                os.write(fd, json.dumps(record).encode("utf-8"))
                os.fsync(fd)
            return Lock(path, fd, shared=not exclusive)
        except BaseException:
            if fd >= 0:
                os.close(fd)  # also drops the flock
            raise
    raise OutputError(where_what_fix(str(out), "the lock file keeps being replaced by other runs",
                                     "wait for them or use another -o folder"))


def _take_over(out: Path, path: Path, holder: dict, *, break_lock: bool) -> None:
    """Accept the record ``holder`` of a lock file nobody holds as stale (with a warning),
    or refuse it: see the module docstring."""
    why = _why_not_stale(holder)
    if why is not None and not break_lock:
        raise _refuse(out, [holder], held=False)
    if why is not None:
        log.warning("%s: --break-lock: taking over the lock of %s", path, why)
    else:
        log.warning("%s: taking over the stale lock of a run that is gone (pid %s on %s)",
                    path, holder["pid"], holder.get("host"))


def _clear_shard_locks(out: Path, *, keep_total: int | None, break_lock: bool) -> None:
    """Refuse the shard locks in ``out`` that a running shard holds, or whose record may
    name one, and remove the others (records of shards that are gone); shards of
    ``keep_total`` (this shard's own split) are left alone."""
    for _index, total, path in _shard_locks(out):
        if total == keep_total:
            continue
        try:
            fd = _open_lock_file(path, create=False)
        except FileNotFoundError:
            continue  # released meanwhile
        try:
            if not _flock(fd, path, warn=False):
                raise _refuse(out, _holders(out, path, fd), held=True)
            if not _still_named(fd, path):
                continue
            holder = _read_holder(fd)
            if holder is not None:
                _take_over(out, path, holder, break_lock=break_lock)
            path.unlink()  # while holding its flock: no shard takes a name being removed
        finally:
            os.close(fd)


def acquire_lock(out: Path, *, shard: tuple[int, int] | None = None, command: str = _DEFAULT_COMMAND,
                 break_lock: bool = False) -> Lock:
    """Take ``out``'s lock for a command writing into it: see the module docstring.

    Parameters
    ----------
    out : Path
        The output folder (must exist).
    shard : (int, int), optional, keyword-only
        ``(I, N)`` of ``--shard I/N``: the folder's lock shared with the other shards of N,
        and shard I's own lock exclusively.  None (a plain run, an eval): the folder's lock
        exclusively.
    command : str, keyword-only
        What this writer is, recorded and named to a writer refused meanwhile:
        ``d3stereo run``, ``d3stereo run --shard 1/4``, ``d3stereo eval``.
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
        -o folder`` (``d3stereo eval``, ``d3stereo run --shard I/N``; several shards:
        ``... and ... are writing here; wait for them ...``) when a running writer holds
        it; ``OUT: the folder is locked by a d3stereo run (pid N on HOST) that may still
        be running; ... --break-lock ...`` when a record cannot be proven stale; or when a
        lock file cannot be created.
    """
    main = _take(out, out / LOCK_FILE, exclusive=shard is None, command=command, break_lock=break_lock)
    try:
        if shard is not None:
            main.inner = _take(out, out / shard_lock_name(*shard), exclusive=True, command=command,
                               break_lock=break_lock)
        # Taken before this check, so that of two shards of different splits starting
        # together at least one sees the other's lock.
        _clear_shard_locks(out, keep_total=shard[1] if shard else None, break_lock=break_lock)
    except BaseException:
        release_lock(main)
        raise
    return main


def shard_lock_name(index: int, total: int) -> str:
    """Lock file name of shard ``index`` of ``total``."""
    return f".d3stereo-shard-{index}-of-{total}.lock"


def release_lock(lock) -> None:
    """Remove the lock file (while still holding its flock, so no run takes a name being
    removed) and drop the flock; a shard's own lock first, then the folder's.

    The folder's lock shared by shards is removed by the last of them (the one that can
    take it exclusively).  ``lock`` is the :class:`Lock` of :func:`acquire_lock`; given a
    bare path (a lock of an older version), the file is removed when its record is this
    process's.
    """
    if not isinstance(lock, Lock):
        path = Path(lock)
        holder = _read_lock(path)
        if holder is not None and holder.get("pid") == os.getpid() and holder.get("host") == socket.gethostname():
            path.unlink(missing_ok=True)
        return
    try:
        if lock.inner is not None:
            release_lock(lock.inner)
            lock.inner = None
    finally:
        _release(lock)


def _release(lock: Lock) -> None:
    if lock.fd < 0:
        return
    try:
        if lock.shared:
            # The other shards still hold it shared: the exclusive flock fails and the file
            # stays (the shared flock may be gone with it: it is being released anyway).
            ours = _flock(lock.fd, lock.path, warn=False) and _read_holder(lock.fd) is None
        else:
            holder = _read_holder(lock.fd)
            ours = (holder is not None and holder.get("pid") == os.getpid()
                    and holder.get("host") == socket.gethostname())
        if ours:
            try:
                if _still_named(lock.fd, lock.path):
                    lock.path.unlink()
            except FileNotFoundError:
                pass
            except OSError as exc:
                log.warning("%s: could not remove the lock file (%s); delete it by hand", lock.path, exc)
    finally:
        os.close(lock.fd)
        lock.fd = -1
