"""What a batch did: :class:`BatchResult` for the caller, ``run.json`` on disk."""

from __future__ import annotations

import platform
import sys
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

from .. import __version__
from .fingerprint import package_versions
from .outputs import write_json
from .signals import signals_deferred


@dataclass
class BatchResult:
    """What a batch did.

    Attributes
    ----------
    out_dir : Path
        The output folder.
    rows : list of dict
        One row per pair for :mod:`d3cli.evaluation.report` (``pair``, ``family``, ``status``,
        metric keys, ``time_s``, ``error``).
    n_failed : int
        Number of pairs that failed.
    run_json : Path
        Path of ``run.json``.
    summary : dict or None
        :func:`d3cli.evaluation.report.summarize` of the rows when evaluating, else None.
    n_computed, n_skipped : int
        Pairs computed by this run, and pairs kept as complete from an earlier run
        (``ok`` and ``skipped`` in run.json); in the rows and the summary both are ``ok``.
    recorded : bool
        True once run.json records the batch complete (its last act).
    """

    out_dir: Path
    rows: list = field(default_factory=list)
    n_failed: int = 0
    run_json: Path | None = None
    summary: dict | None = None
    n_computed: int = 0
    n_skipped: int = 0
    recorded: bool = False

    def counts_line(self) -> str:
        """``N ok (C computed, S skipped as complete), F failed of T pairs``: run.json's counts."""
        return (f"{self.n_computed + self.n_skipped} ok ({self.n_computed} computed, {self.n_skipped} skipped "
                f"as complete), {self.n_failed} failed of {self.n_pairs} pair{'' if self.n_pairs == 1 else 's'}")

    @property
    def n_pairs(self) -> int:
        return len(self.rows)

    @property
    def failures(self) -> list[tuple[str, str]]:
        """(pair, error message) of each failed pair."""
        return [(r["pair"], r.get("error", "")) for r in self.rows if r["status"] == "failed"]


def write_run_json(batch: BatchResult, records, *, cfg, method, max_disparity, started,
                   config_source, interrupted, n_total=None, stopped_at=None, stop_reason=None,
                   execution=None, compile_s=None, shard=None, device=None) -> None:
    """Write ``batch.run_json``: versions, settings, counts and one record per pair.

    ``records`` are the run.json records of the pairs done so far (``status`` ok, skipped
    or failed); ``interrupted``, ``stopped_at`` and ``stop_reason`` say why a batch ended
    early.  Written atomically.
    """
    failed = [{"pair": r["pair"], "error": r["error"]} for r in records if r["status"] == "failed"]
    data = {
        "d3stereo": __version__,
        "started": started,
        "finished": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "interrupted": interrupted,
        "method": method,
        "backend": cfg.run.backend,
        "backends_used": sorted({r["backend"] for r in records if r.get("backend")}),
        "max_disparity_override": max_disparity,
        "config_source": config_source,
        "config": cfg.to_dict(),
        "versions": package_versions(),
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "n_pairs": len(records),
        "n_total": len(records) if n_total is None else n_total,
        "stopped_at": stopped_at,
        "stop_reason": stop_reason,
        "n_failed": len(failed),
        "n_computed": sum(r["status"] == "ok" for r in records),
        "n_skipped": sum(r["status"] == "skipped" for r in records),  # complete from an earlier run
        # Seconds spent compiling numba kernels up front; not part of any pair's wall time.
        "compile_s": compile_s,
        "execution": execution or {"mode": "serial", "workers": 1},
        # A CUDA batch in this process: kernel time over wall time, launches and copies per
        # pair (d3cli.batch.device); null otherwise.
        "device": device,
        "shard": list(shard) if shard else None,
        "pairs": records,
        "failed": failed,
    }
    write_json(batch.run_json, data)


def record_complete(batch: BatchResult, records, meta: dict, on_recorded=None) -> None:
    """Write run.json as complete and mark ``batch.recorded``, with Ctrl-C/SIGTERM held back
    so that the two happen together: an interrupt after this is one after a finished batch
    (the runner ignores a Ctrl-C then), one before it is recorded in run.json as an
    interruption.  ``on_recorded`` runs inside the same held block (the CLI ignores Ctrl-C
    from there on)."""
    with signals_deferred():
        write_run_json(batch, records, **meta, interrupted=False)
        batch.recorded = True
        if on_recorded is not None:
            on_recorded()
