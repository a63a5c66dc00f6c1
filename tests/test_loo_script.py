"""scripts/loo.py: the leave-one-out choice and its table, on hand-made grid folders."""

from __future__ import annotations

import csv
import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def loo():
    spec = importlib.util.spec_from_file_location("loo_script", ROOT / "scripts" / "loo.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def write_run(folder: Path, config: dict, pep1: dict) -> Path:
    """A 'd3stereo run --eval' folder: run.json with ``config``, metrics.csv with PEP1 per pair
    (EPE = PEP1 / 10, PEP0.5 = 2 PEP1, PEP2 = PEP1 / 2) and one pair without ground truth."""
    folder.mkdir(parents=True)
    (folder / "run.json").write_text(json.dumps({"config": config}))
    with open(folder / "metrics.csv", "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(["pair", "family", "status", "epe", "pep_0.5", "pep_1", "pep_2", "time_s"])
        for pair, value in pep1.items():
            writer.writerow([pair, "middlebury2006", "ok", value / 10, value * 2, value, value / 2, 1.0])
        writer.writerow(["road-pair", "road", "ok", "", "", "", "", 1.0])
    return folder


def config(pkrn=2.0, gap=0.05):
    return {"seeds": {"pkrn_min": pkrn, "every_level": True}, "diffusion": {"max_gap": gap}}


@pytest.fixture
def grid(tmp_path):
    # pkrn 1.5 and 2.5 both have a lower mean PEP1 (9.667) than the shipped 2.0 (10) on all
    # three pairs, yet chosen on the other two pairs each loses on the left-out one
    write_run(tmp_path / "shipped", config(), {"a": 10, "b": 10, "c": 10})
    write_run(tmp_path / "seeds.pkrn_min=1.5", config(pkrn=1.5), {"a": 4, "b": 14, "c": 11})
    write_run(tmp_path / "seeds.pkrn_min=2.5", config(pkrn=2.5), {"a": 12, "b": 8, "c": 9})
    # max_gap 0.1 equals the shipped run everywhere: the tie goes to the shipped value
    write_run(tmp_path / "diffusion.max_gap=0.1", config(gap=0.1), {"a": 10, "b": 10, "c": 10})
    return tmp_path


def test_each_pair_gets_the_value_best_on_the_others(loo, grid):
    shipped = loo.read_run(grid / "shipped")
    runs = [loo.read_run(grid / name) for name in ("seeds.pkrn_min=1.5", "seeds.pkrn_min=2.5")]
    points = loo.build_axes(shipped, runs)["seeds.pkrn_min"]
    assert [value for value, _ in points] == ["2.0", "1.5", "2.5"]
    result = loo.leave_one_out(points, ["a", "b", "c"], "pep_1")
    # a: others b, c -> 2.5 (8.5 < 10 < 12.5); b: a, c -> 1.5 (7.5); c: a, b -> 1.5 (9.0)
    assert result["chosen"] == {"a": "2.5", "b": "1.5", "c": "1.5"}
    assert result["means"]["pep_1"] == pytest.approx((12 + 14 + 11) / 3)
    assert result["means"]["epe"] == pytest.approx((1.2 + 1.4 + 1.1) / 3)


def test_the_table_puts_leave_one_out_beside_the_shipped_means(loo, grid, capsys):
    assert loo.main([str(p) for p in sorted(grid.iterdir())]) == 0
    out = capsys.readouterr().out
    assert "middlebury: 3 pairs; each value chosen on the mean pep_1 of the other 2" in out
    assert ("| seeds.pkrn_min | 2.0 | 1.000 / 20.00 / 10.00 / 5.00 | 1.233 / 24.67 / 12.33 / 6.17 "
            "| 1.5: 2, 2.5: 1 |") in out
    assert "| diffusion.max_gap | 0.05 | 1.000 / 20.00 / 10.00 / 5.00 | 1.000 / 20.00 / 10.00 / 5.00 | 0.05: 3 |" in out
    assert "| seeds.pkrn_min | 1.5 | 0.967 / 19.33 / 9.67 / 4.83 | 1 / 3 | 1.00 |" in out
    assert "road" not in out  # pairs without ground truth take no part


def test_a_run_changing_two_keys_is_refused(loo, grid, capsys):
    write_run(grid / "both", config(pkrn=1.5, gap=0.1), {"a": 1, "b": 1, "c": 1})
    with pytest.raises(SystemExit) as info:
        loo.main([str(p) for p in sorted(grid.iterdir())])
    assert str(info.value) == ("Error: both: differs from the shipped run in diffusion.max_gap, seeds.pkrn_min; "
                               "change one key per run, or name keys varied together with --axis")
    assert loo.main([str(p) for p in sorted(grid.iterdir())] + ["--axis", "seeds.pkrn_min,diffusion.max_gap"]) == 0
    assert "| seeds.pkrn_min / diffusion.max_gap | 2.0 / 0.05 |" in capsys.readouterr().out


def test_a_folder_without_metrics_names_itself(loo, tmp_path):
    (tmp_path / "shipped").mkdir()
    with pytest.raises(SystemExit) as info:
        loo.main([str(tmp_path / "shipped")])
    assert str(info.value).startswith(f"Error: {tmp_path / 'shipped'}: not a finished 'd3stereo run --eval' folder")
