"""Where the compiled kernels live, and whether any are there: the standard library only.

A first run compiles the kernels for a minute or more.  The command line asks
:func:`is_cold` before it imports numba (about a second of imports), so the notice
(:func:`compile_notice`) comes at once; :mod:`d3cli.kernels.compile_cache` picks the same folder
with :func:`choose_cache_dir` before anything compiles.  The seconds and kernel count of
the last cold compile are kept beside the cache (:func:`record_compile`) for the next
estimate.  A compile cut short by Ctrl-C keeps what it compiled in the cache and records
how far it got (:func:`record_interrupted`): the next run says it compiles the rest, and
how long that should take (:func:`resume_point`).  May import: the standard library only
(it runs before numba is imported).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import sys
from pathlib import Path

log = logging.getLogger(__name__)

#: The kernels package folder.
HERE = Path(__file__).resolve().parent
#: Name of the file, in the kernels folder's cache, recording the last cold compile per
#: method: ``{"d3stereo": {"seconds": 77.0, "kernels": 95}}``; after an interrupted one
#: also what it left in the cache: ``"done": {"seconds": 21.0, "kernels": 46}``.
COMPILE_RECORD = "compile.json"
#: A cold compile where no record exists yet: seconds on a quiet 2-core machine and
#: top-level kernel functions compiled, as :func:`record_compile` records them for the
#: bundled samples with the default config and with road.yaml (numba 0.68: 251 functions,
#: 120-140 s in a fresh virtual environment; a loaded machine takes two or three times as long).
COLD_ESTIMATE = {"seconds": 120.0, "kernels": 251}
#: Level of the compile notice and progress lines: above WARNING, so a default logging
#: setup (the CLI without -v, a script's last-resort handler) shows them; -q hides them.
NOTICE = logging.WARNING + 1
logging.addLevelName(NOTICE, "NOTE")
#: Whether this process has logged the compile notice (the command line does it before its
#: imports; the warm-up then does not repeat it).
announced = False


def choose_cache_dir(root: Path = HERE) -> str:
    """The ``NUMBA_CACHE_DIR`` a run uses: the user's, else "" (the ``__pycache__`` beside
    each kernels module) when the package can be written, else
    ``$XDG_CACHE_HOME/d3stereo/numba`` (default ``~/.cache/d3stereo/numba``)."""
    chosen = os.environ.get("NUMBA_CACHE_DIR", "")
    if chosen:
        return chosen
    cache = root / "__pycache__"
    if os.access(cache if cache.is_dir() else root, os.W_OK):
        return ""
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return str(base / "d3stereo" / "numba")


def current_cache_dir() -> str:
    """numba's ``CACHE_DIR`` once numba is imported, else what :func:`choose_cache_dir` gives."""
    numba_config = sys.modules.get("numba.core.config")
    if numba_config is not None:
        return numba_config.CACHE_DIR
    return choose_cache_dir()


def module_cache_folder(py_file: Path, cache_dir: str | None = None) -> Path:
    """Where numba keeps the cache of the module ``py_file`` (as numba's cache locators
    name it: ``<CACHE_DIR>/<folder>_<sha1 of the folder path>``, else ``__pycache__``)."""
    cache_dir = current_cache_dir() if cache_dir is None else cache_dir
    if not cache_dir:
        return py_file.parent / "__pycache__"
    folder = os.path.dirname(os.path.abspath(py_file))
    subpath = f"{os.path.split(folder)[-1]}_{hashlib.sha1(folder.encode()).hexdigest()}"
    return Path(cache_dir) / subpath


def cache_folder(root: Path = HERE, cache_dir: str | None = None) -> Path:
    """The kernels package's own cache folder (stamp and compile record)."""
    return module_cache_folder(root / "pixel.py", cache_dir)


def cache_root(cache_dir: str | None = None) -> str:
    """Where the compiled kernels go: ``NUMBA_CACHE_DIR``, else the kernels package folder
    (a ``__pycache__`` folder in each of its folders)."""
    cache_dir = current_cache_dir() if cache_dir is None else cache_dir
    return cache_dir or str(HERE)


def is_cold(root: Path = HERE, cache_dir: str | None = None) -> bool:
    """True when no kernel module has a usable cached function: everything will compile.

    A module counts as cached when its cache folder holds an index file (``*.nbi``) of
    this Python newer than the module's source (numba drops an index older than its
    source).

    Parameters
    ----------
    root : Path
        The kernels folder.
    cache_dir : str or None
        ``NUMBA_CACHE_DIR`` ("" for ``__pycache__``; None: the one this run uses).
    """
    cache_dir = current_cache_dir() if cache_dir is None else cache_dir
    tag = f".py{sys.version_info.major}{sys.version_info.minor}.nbi"
    for module in root.rglob("*.py"):
        folder = module_cache_folder(module, cache_dir)
        if not folder.is_dir():
            continue
        source_time = module.stat().st_mtime
        if any(index.stat().st_mtime >= source_time for index in folder.glob(f"{module.stem}.*{tag}")):
            return False
    return True


def _compile_records(root: Path = HERE, cache_dir: str | None = None) -> dict:
    """The contents of :data:`COMPILE_RECORD` (``{}`` where missing or unreadable)."""
    try:
        record = json.loads((cache_folder(root, cache_dir) / COMPILE_RECORD).read_text())
    except (OSError, ValueError):
        return {}
    return record if isinstance(record, dict) else {}


def _write_compile_record(method: str, entry: dict, root: Path = HERE, cache_dir: str | None = None) -> None:
    """Store ``entry`` as ``method``'s record (best effort: a cache folder that cannot be
    written keeps the old one)."""
    path = cache_folder(root, cache_dir) / COMPILE_RECORD
    record = _compile_records(root, cache_dir)
    record[method] = entry
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{COMPILE_RECORD}.{os.getpid()}")
        tmp.write_text(json.dumps(record, sort_keys=True) + "\n", encoding="utf-8")
        os.replace(tmp, path)  # whole or not at all: another process may read it meanwhile
    except OSError:
        pass


def compile_estimate(method: str, root: Path = HERE, cache_dir: str | None = None) -> dict:
    """``{"seconds": s, "kernels": n}`` of the last cold compile of ``method`` on this
    machine, else :data:`COLD_ESTIMATE`."""
    try:
        entry = _compile_records(root, cache_dir)[method]
        return {"seconds": float(entry["seconds"]), "kernels": int(entry["kernels"])}
    except (ValueError, KeyError, TypeError):
        return dict(COLD_ESTIMATE)


def record_compile(method: str, seconds: float, kernels: int, root: Path = HERE,
                   cache_dir: str | None = None) -> None:
    """Store a whole cold compile's seconds and kernel count for the next estimate (best
    effort: a cache folder that cannot be written keeps the old estimate); an interrupted
    compile's record (:func:`record_interrupted`) is dropped: nothing is left to compile."""
    _write_compile_record(method, {"seconds": round(seconds, 1), "kernels": kernels}, root, cache_dir)


def record_interrupted(method: str, seconds: float, kernels: int, root: Path = HERE,
                       cache_dir: str | None = None) -> None:
    """Store how far an interrupted compile of ``method`` got: ``seconds`` spent and
    ``kernels`` functions compiled (and cached) since the cache was last cold.

    The estimate of a whole compile stays, unless these seconds plus the estimate's share
    of the functions still to compile exceed it (a slower machine than the estimate's).
    """
    estimate = compile_estimate(method, root, cache_dir)
    left = max(estimate["kernels"] - kernels, 0)
    whole = max(estimate["seconds"], seconds + estimate["seconds"] * left / max(estimate["kernels"], 1))
    _write_compile_record(method, {"seconds": round(whole, 1), "kernels": max(estimate["kernels"], kernels),
                                   "done": {"seconds": round(seconds, 1), "kernels": kernels}}, root, cache_dir)


def resume_point(method: str, root: Path = HERE, cache_dir: str | None = None) -> dict | None:
    """``{"seconds": s, "kernels": n}`` an interrupted compile of ``method`` spent and left
    in the cache (:func:`record_interrupted`); None when there is none, or when the cache
    is cold again (emptied, or every module edited since: nothing of it is left)."""
    try:
        done = _compile_records(root, cache_dir)[method]["done"]
        done = {"seconds": float(done["seconds"]), "kernels": int(done["kernels"])}
    except (ValueError, KeyError, TypeError):
        return None
    return None if is_cold(root, cache_dir) else done


def remaining_seconds(estimate: dict, done: dict) -> float:
    """Seconds a compile that ``done`` (``{"seconds", "kernels"}``) got part way through
    should still take: the estimate less the seconds spent, or the estimate's share of the
    functions left, whichever is longer (the first functions are the quick ones), and at
    least a tenth of the estimate."""
    share = max(estimate["kernels"] - done["kernels"], 0) / max(estimate["kernels"], 1)
    return max(estimate["seconds"] - done["seconds"], estimate["seconds"] * share, estimate["seconds"] / 10)


def compile_notice(method: str, done: dict | None = None) -> str:
    """``compiling the kernels for this machine, once (about 120 s); cached in DIR``: the
    seconds of this machine's last cold compile of ``method``, else :data:`COLD_ESTIMATE`.
    After an interrupted compile (``done``, from :func:`resume_point`): ``compiling the
    rest of the kernels for this machine, once (about 110 s; 46 of about 251 were compiled
    by an interrupted run); cached in DIR``."""
    estimate = compile_estimate(method)
    if done is None:
        return (f"compiling the kernels for this machine, once (about {estimate['seconds']:.0f} s); "
                f"cached in {cache_root()}")
    return (f"compiling the rest of the kernels for this machine, once (about "
            f"{remaining_seconds(estimate, done):.0f} s; {done['kernels']} of about {estimate['kernels']} "
            f"were compiled by an interrupted run); cached in {cache_root()}")


def announce(method: str) -> bool:
    """Log :func:`compile_notice` (level :data:`NOTICE`) when ``method`` runs the kernels
    and the cache is cold, or holds an interrupted compile (:func:`resume_point`); once
    per process.

    Returns
    -------
    bool
        Whether this run compiles the kernels, all or the rest (the notice was logged,
        now or earlier).
    """
    global announced
    if announced:
        return True
    cold = is_cold()
    done = None if cold else resume_point(method)
    if not cold and done is None:
        return False
    announced = True
    log.log(NOTICE, compile_notice(method, done))
    return True
