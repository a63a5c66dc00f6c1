"""scripts/ablation.py: Table I(b) (8 rows) / I(a) (9 rows) with the paper's figures, then
the additions, on two tiny synthetic pairs."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "scripts" / "ablation.py"


def run(*args):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, str(SCRIPT), *map(str, args)], capture_output=True, text=True,
                          timeout=600, env=env, cwd=ROOT)


@pytest.fixture(scope="module")
def pairs(tmp_path_factory, make_pair_folder_module):
    root = tmp_path_factory.mktemp("ablation")
    for i, name in enumerate("ab"):
        make_pair_folder_module(root, name, shift=4 + 2 * i, seed=i)
    return root


@pytest.fixture(scope="module")
def make_pair_folder_module():
    from tests.helpers import textured_pair, write_png

    def make(root, name, *, shift, seed):
        from d3cli.data.formats import write_pfm

        folder = Path(root) / name
        folder.mkdir(parents=True)
        left, right, disp = textured_pair(shift, (48, 96), seed=seed)
        write_png(folder / "left.png", left)
        write_png(folder / "right.png", right)
        write_pfm(folder / "disp_gt.pfm", disp)
        (folder / "SOURCE.txt").write_text("provenance: test\ngt_scale: 1\ngt_invalid: inf\n")

    return make


def table_rows(stdout):
    return [line for line in stdout.splitlines() if line.startswith("|")]


def test_table_b_has_the_header_the_eight_switch_rows_and_the_additions(pairs):
    proc = run(pairs, "--table", "b")
    assert proc.returncode == 0, proc.stderr[-3000:]
    rows = table_rows(proc.stdout)
    assert rows[0].startswith("| PRC | RBF | ARS | PEP0.5 % | PEP1 % | PEP2 % | EPE px | time s/pair | paper PEP1 |")
    body = rows[2:]
    switches = [tuple(cell.strip() == "x" for cell in row.split("|")[1:4]) for row in body[:8]]
    # the paper's order: none, PRC, RBF, ARS, PRC+RBF, RBF+ARS, PRC+ARS, all
    assert switches == [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (0, 1, 1), (1, 0, 1), (1, 1, 1)]
    assert body[0].rstrip().endswith("| 34.3 | 24 | 4.07 | 1.11 |")  # the paper's baseline row
    assert body[7].rstrip().endswith("| 24.9 | 17.1 | 2.97 | 1.58 |")
    labels = [row.split("|")[1].strip() for row in body[8:]]
    assert labels == ["+ occlusion check", "+ max_gap 0", "+ seeds.every_level", "+ band search",
                      "+ symmetric candidates", "+ semi-global smoothing", "+ no RBF at full resolution",
                      "+ finishing smoothing", "+ all additions (defaults)"]
    for row in body:
        cells = [c.strip() for c in row.split("|")[1:-1]]
        assert len(cells) == len(rows[0].split("|")) - 2
        epe = float(cells[6])
        assert 0 <= epe < 10


def test_table_a_without_additions_has_nine_rows_and_a_bad_config_stops_first(pairs):
    proc = run(pairs, "--table", "a", "--no-additions", "--set", "pyramid.levels=2")
    assert proc.returncode == 0, proc.stderr[-3000:]
    rows = table_rows(proc.stdout)
    assert rows[0].startswith("| PT | PRC | RBF | ARS |") and len(rows) == 2 + 9
    bad = run(pairs, "--set", "inheritance.candidates=diagonal")
    assert bad.returncode != 0 and "inheritance.candidates" in bad.stderr and "one of symmetric, paper" in bad.stderr


def test_all_additions_on_the_full_method_give_the_defaults(monkeypatch):
    """The last row is labelled "(defaults)": paper.yaml + every switch + every addition must
    be the default config, key for key (a new default would otherwise go unmeasured)."""
    import importlib.util

    from d3cli.config import load_config

    monkeypatch.syspath_prepend(str(ROOT / "scripts"))  # ablation.py imports benchmark.py beside it
    spec = importlib.util.spec_from_file_location("ablation_script", SCRIPT)
    ablation = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(ablation)
    names = ablation.TABLES["b"][0]
    full = load_config(ablation.PAPER_CONFIG, ablation.switch_overrides(names, (1,) * len(names)) + ablation.ALL_ADDITIONS)
    assert full == load_config(None)
