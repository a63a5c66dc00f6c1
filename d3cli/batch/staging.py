"""A pair's folder appears whole or not at all, and a rerun checks what it would skip.

A pair is written into a hidden sibling of its folder, ``OUT/.<pair>.partial-XXXX``
(:func:`new_staging`), and only once everything is there (maps, evaluation, panel, extras,
``result.json``) it replaces ``OUT/<pair>`` in one rename (:func:`publish`).  A run killed
at any moment (SIGKILL, SIGTERM to a pool's workers, a full disk) thus leaves either the
old folder or the new one, never a mix; its staging folder is removed by the next run over
the same pairs (:func:`clean_leftovers`).

``result.json`` records the size and SHA-256 of every file of the pair
(:func:`file_records`); before a rerun skips a pair as complete it checks them
(:func:`changed_files`), so a truncated or replaced output is computed again, not kept.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import errno
import hashlib
import logging
import os
import secrets
from pathlib import Path
from typing import Iterable

from ..errors import OutputError, where_what_fix

log = logging.getLogger(__name__)

#: Marks a pair's staging folder: ``.<pair>.partial-XXXX`` beside ``<pair>``.
PARTIAL = ".partial-"
#: renameat2's flag swapping two names atomically (Linux >= 3.15).
_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


def new_staging(target: Path) -> Path:
    """Create and return an empty staging folder for ``target`` (a pair's folder), beside it.

    Raises
    ------
    OutputError
        When it cannot be created (its ``errno`` kept: a full disk ends the batch).
    """
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        return _new_folder(target.parent, f".{target.name}{PARTIAL}")
    except OSError as exc:
        error = OutputError(where_what_fix(str(target), f"cannot create the pair's folder ({exc.strerror or exc})",
                                           "free disk space or fix the permissions of the output folder, then rerun"))
        error.errno = exc.errno
        raise error from None


def _new_folder(parent: Path, prefix: str) -> Path:
    """A new empty folder ``parent/<prefix><random>`` with the usual permissions (umask;
    ``tempfile.mkdtemp`` would make it private, and the pair folder with it)."""
    for _ in range(100):
        folder = parent / f"{prefix}{secrets.token_hex(4)}"
        try:
            folder.mkdir()
        except FileExistsError:
            continue
        return folder
    raise FileExistsError(errno.EEXIST, "no free staging folder name", str(parent / prefix))


def _exchange(a: Path, b: Path) -> bool:
    """Swap the names ``a`` and ``b`` in one step (renameat2); False where unsupported."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError):  # not Linux / glibc < 2.28
        return False
    if renameat2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    code = ctypes.get_errno()
    if code in (errno.ENOSYS, errno.EINVAL, errno.ENOTSUP, errno.EOPNOTSUPP):
        return False  # a file system without the flag: the two-step fallback
    raise OSError(code, os.strerror(code), str(b))


def publish(staging: Path, target: Path, ours: Iterable[str]) -> None:
    """Put the complete pair folder ``staging`` in place of ``target``.

    Files in an existing ``target`` that d3stereo did not write (names not in ``ours``)
    are moved into the new folder first, so they stay.  A ``target`` that is a symbolic
    link is replaced, never written through.  The old folder ends at the staging name and
    is removed.
    """
    ours = set(ours)
    if target.is_dir() and not target.is_symlink():
        for entry in os.listdir(target):
            if entry not in ours and not (staging / entry).exists() and ".tmp-" not in entry:
                os.rename(target / entry, staging / entry)
    if os.path.lexists(target):
        if not _exchange(staging, target):
            # Two renames: a kill between them leaves no folder (recomputed by the next run).
            old = _new_folder(target.parent, f".{target.name}{PARTIAL}old-")
            os.rename(target, old / "old")
            os.rename(staging, target)
            staging = old
        discard(staging, ours)
    else:
        os.rename(staging, target)


def discard(folder: Path, ours: Iterable[str]) -> None:
    """Remove a staging folder (or a replaced pair folder moved to a staging name): the files
    d3stereo wrote, then the folder when empty; anything else stays, with a warning."""
    if folder.is_symlink() or not folder.is_dir():
        if os.path.lexists(folder):
            os.unlink(folder)  # a link that stood where a pair folder goes: the link only
        return
    ours = set(ours)
    for entry in os.listdir(folder):
        path = folder / entry
        if entry == "old":
            discard(path, ours)
        elif entry in ours or ".tmp-" in entry:
            try:
                path.unlink()
            except OSError as exc:
                log.warning("%s: could not remove (%s)", path, exc)
    try:
        folder.rmdir()
    except OSError:
        log.warning("%s: left in place: it holds files d3stereo did not write", folder)


def named_as_target(exc: BaseException, staging: Path, target: Path) -> BaseException:
    """``exc`` with the staging folder's path replaced by the pair folder's in its message:
    the user knows ``OUT/p1``, not the hidden folder it is written in first."""
    text = str(exc)
    if str(staging) not in text:
        return exc
    renamed = type(exc)(text.replace(str(staging), str(target)))
    renamed.__dict__.update(exc.__dict__)  # errno (a full disk ends the batch), notes
    return renamed


def clean_leftovers(out: Path, names: Iterable[str], ours: Iterable[str]) -> int:
    """Remove the staging folders that killed runs left for the pairs ``names`` in ``out``.

    Only those pairs' staging folders: shards share OUT and may be writing others.
    Returns the number removed.
    """
    names = set(names)
    ours = tuple(ours)
    removed = 0
    try:
        entries = os.listdir(out)
    except OSError:
        return 0
    for entry in entries:
        if not entry.startswith(".") or PARTIAL not in entry:
            continue
        if entry[1:entry.rindex(PARTIAL)] in names:
            discard(out / entry, ours)
            removed += 1
    if removed:
        log.info("%s: removed %d unfinished pair folder(s) of an interrupted run", out, removed)
    return removed


def _sha256(path: Path) -> str:
    with open(path, "rb") as fh:
        return hashlib.file_digest(fh, "sha256").hexdigest()


def file_records(folder: Path, names: Iterable[str]) -> dict:
    """``{name: {"size": bytes, "sha256": hex}}`` of the files ``names`` present in ``folder``."""
    records = {}
    for name in names:
        path = folder / name
        if path.is_file():
            records[name] = {"size": path.stat().st_size, "sha256": _sha256(path)}
    return records


def changed_files(folder: Path, records) -> str | None:
    """Why the files of ``folder`` are not the ones ``records`` describes, or None when they are.

    Sizes are compared first (cheap), then SHA-256.
    """
    if not isinstance(records, dict) or not records:
        return "result.json records no file sizes and hashes (written by an earlier d3stereo)"
    for name, record in records.items():
        path = folder / name
        try:
            size = path.stat().st_size if path.is_file() else None
        except OSError:
            size = None
        if size is None:
            return f"{name} is missing"
        if not isinstance(record, dict) or size != record.get("size"):
            return f"{name} has {size} bytes, {record.get('size') if isinstance(record, dict) else '?'} when written"
    for name, record in records.items():
        if _sha256(folder / name) != record.get("sha256"):
            return f"{name} changed since it was written (SHA-256 differs)"
    return None
