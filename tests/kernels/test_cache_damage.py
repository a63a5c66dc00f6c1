"""A damaged kernel cache entry (an index truncated, a data file overwritten) is removed
and compiled again, with one warning line, never a traceback.

Each case runs one small project kernel (``pyramid/halve.py``) in fresh processes with a
``NUMBA_CACHE_DIR`` of its own: the package's shared cache is never touched.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]

#: Runs the kernel once and prints its result and numba's cache hits and misses, as JSON.
SCRIPT = """
import json
import numpy as np
from d3cli.kernels.pyramid import halve

out = halve.halve_area(np.arange(64, dtype=np.float32).reshape(8, 8))
stats = halve.KERNELS[0].stats
print(json.dumps({"sum": float(out.sum()), "hits": sum(stats.cache_hits.values()),
                  "misses": sum(stats.cache_misses.values())}))
"""


def _run(cache: Path) -> tuple[dict, list[str]]:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "PYTHONPATH": str(REPO)}
    proc = subprocess.run([sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    return json.loads(proc.stdout), [line for line in proc.stderr.splitlines() if line.strip()]


def _entry(cache: Path, suffix: str) -> list[Path]:
    return sorted(cache.rglob(f"halve.halve_task-*{suffix}"))


@pytest.fixture(scope="module")
def compiled(tmp_path_factory) -> Path:
    """A cache folder holding the kernel, compiled once (copied for each case)."""
    cache = tmp_path_factory.mktemp("numba-cache")
    result, stderr = _run(cache)
    assert result["misses"] == 1 and stderr == []
    return cache


@pytest.mark.parametrize("damage", [
    pytest.param(lambda index, data: index.write_bytes(index.read_bytes()[: len(index.read_bytes()) // 2]),
                 id="index-truncated"),
    pytest.param(lambda index, data: index.write_bytes(b""), id="index-empty"),
    pytest.param(lambda index, data: data.write_bytes(b"\0" * len(data.read_bytes())), id="data-overwritten"),
    pytest.param(lambda index, data: data.write_bytes(data.read_bytes()[:100]), id="data-truncated"),
])
def test_a_damaged_entry_is_compiled_again_with_one_warning(compiled, tmp_path, damage):
    import shutil

    cache = tmp_path / "cache"
    shutil.copytree(compiled, cache)
    (index,), (data,) = _entry(cache, ".nbi"), _entry(cache, ".nbc")
    intact, _ = _run(cache)
    assert intact["hits"] == 1  # the copy loads

    damage(index, data)
    result, stderr = _run(cache)
    assert result == {"sum": intact["sum"], "hits": 0, "misses": 1}
    assert len(stderr) == 1, stderr
    assert stderr[0].startswith(f"damaged kernel cache entry {index} (")
    assert stderr[0].endswith("): removed and compiled again")

    again, stderr = _run(cache)  # the fresh entry loads, silently
    assert again == {"sum": intact["sum"], "hits": 1, "misses": 0}
    assert stderr == []


def test_other_packages_keep_numbas_behaviour(tmp_path):
    """Only d3stereo's own functions are healed: another package's damaged entry still fails
    as numba makes it fail."""
    module = tmp_path / "other_pkg.py"
    module.write_text("from numba import njit\n\n@njit(cache=True)\ndef f(x):\n    return x + 1\n")
    script = "import d3cli.kernels.pyramid, other_pkg; print(other_pkg.f(1))"
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"), "PYTHONPATH": f"{REPO}{os.pathsep}{tmp_path}"}
    first = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=300)
    assert first.stdout == "2\n", first.stderr
    (index,) = (tmp_path / "cache").rglob("other_pkg.f-*.nbi")
    index.write_bytes(b"")
    second = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=300)
    assert second.returncode != 0
    assert "EOFError" in second.stderr
