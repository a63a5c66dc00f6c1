"""scripts/benchmark.py: the per-pair win count and per-pair tables, on hand-made results."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("benchmark_script", ROOT / "scripts" / "benchmark.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("benchmark_script", module)
    spec.loader.exec_module(module)
    return module


def scores(epe, pep05, pep1, pep2, time=1.0):
    return {"epe": epe, "pep_0.5": pep05, "pep_1": pep1, "pep_2": pep2, "time": time}


@pytest.fixture
def rows():
    # pair x: d3 beats both peers on every metric; y: SGBM beats d3 on PEP1, ELAS ties d3 on
    # PEP2; z (another family): ELAS beats d3 on EPE
    return [
        {"pair": "x", "family": "kitti2012", "d3": scores(1.0, 20, 10, 5), "sgbm": scores(2.0, 30, 12, 6),
         "elas": scores(1.5, 25, 11, 7)},
        {"pair": "y", "family": "kitti2012", "d3": scores(1.0, 20, 10, 5), "sgbm": scores(2.0, 30, 9, 6),
         "elas": scores(1.5, 25, 11, 5)},
        {"pair": "z", "family": "kitti2015", "d3": scores(1.0, 20, 10, 5), "sgbm": scores(2.0, 30, 12, 6),
         "elas": scores(0.5, 25, 11, 7)},
    ]


def test_wins_are_counted_per_metric_against_each_peer_and_the_best(bench, rows):
    counts = bench.win_counts(rows)
    assert counts["kitti2012"]["n"] == 2
    assert counts["kitti2012"]["wins"]["sgbm"] == {"epe": 2, "pep_0.5": 2, "pep_1": 1, "pep_2": 2}
    assert counts["kitti2012"]["wins"]["elas"] == {"epe": 2, "pep_0.5": 2, "pep_1": 2, "pep_2": 1}
    assert counts["kitti2012"]["wins"]["best peer"] == {"epe": 2, "pep_0.5": 2, "pep_1": 1, "pep_2": 1}
    assert counts["overall"]["wins"]["best peer"] == {"epe": 2, "pep_0.5": 3, "pep_1": 2, "pep_2": 2}


def test_the_win_table_reads_wins_over_pairs(bench, rows):
    lines = bench.markdown_wins(rows).splitlines()
    assert lines[0] == "| family | pairs | d3stereo better than | EPE | PEP0.5 % | PEP1 % | PEP2 % |"
    assert lines[2] == "| kitti2012 | 2 | SGBM | 2 / 2 | 2 / 2 | 1 / 2 | 2 / 2 |"
    assert lines[4] == "| | | the best peer on the pair | 2 / 2 | 2 / 2 | 1 / 2 | 1 / 2 |"
    assert lines[-1] == "| | | the best peer on the pair | 2 / 3 | 3 / 3 | 2 / 3 | 2 / 3 |"


def test_the_per_pair_table_marks_the_best(bench, rows):
    table = bench.markdown_per_pair(rows, keys=("pep_1",))
    assert table.splitlines()[0] == "| PEP1 % | pair | d3stereo | SGBM | ELAS |"
    assert "| kitti2012 | y | 10.00 | **9.00** | 11.00 |" in table


def test_no_win_table_without_a_peer(bench, rows):
    assert bench.markdown_wins([{k: v for k, v in r.items() if k not in ("sgbm", "elas")} for r in rows]) == ""
