"""scripts/results_tables.py: summaries, tables and marker blocks, on hand-made rows (no data)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def rt():
    spec = importlib.util.spec_from_file_location("results_tables_script", ROOT / "scripts" / "results_tables.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("results_tables_script", module)
    spec.loader.exec_module(module)
    return module


def scores(epe, pep05, pep1, pep2, density=100.0):
    return {"epe": epe, "pep_0.5": pep05, "pep_1": pep1, "pep_2": pep2, "density": density}


@pytest.fixture
def rows():
    # a: d3 best everywhere; b: SGBM beats d3 on PEP1, ELAS ties d3 on PEP2
    return [
        {"pair": "a", "family": "kitti2012", "d3": scores(1.0, 20, 10, 5), "sgbm": scores(2.0, 30, 12, 6),
         "elas": scores(1.5, 25, 11, 7)},
        {"pair": "b", "family": "kitti2015", "d3": scores(2.0, 20, 10, 5), "sgbm": scores(3.0, 30, 9, 6, 90.0),
         "elas": scores(2.5, 25, 11, 5)},
    ]


def test_family_summary_means_every_metric(rt, rows):
    summary = rt.family_summary(rows, ["d3", "sgbm"])
    assert summary["d3"] == {"n": 2, "epe": 1.5, "pep_0.5": 20, "pep_1": 10, "pep_2": 5, "density": 100.0}
    assert summary["sgbm"]["pep_1"] == 10.5 and summary["sgbm"]["density"] == 95.0


def test_wins_count_strictly_lower_pairs_and_the_best_peer(rt, rows):
    counts = rt.wins(rows, "d3", ["sgbm", "elas"])
    assert counts["sgbm"] == {"epe": 2, "pep_0.5": 2, "pep_1": 1, "pep_2": 2}
    assert counts["elas"]["pep_2"] == 1  # a tie is no win
    assert counts["best"] == {"epe": 2, "pep_0.5": 2, "pep_1": 1, "pep_2": 1}


def test_peer_better_names_the_pair_the_peer_and_both_values(rt, rows):
    found = rt.peer_better(rows, "d3", ["sgbm", "elas"])
    assert found["pep_1"] == [("b", "sgbm", 9, 10)]
    assert found["epe"] == [] and found["pep_2"] == []  # ties are not better


def test_margin_text_is_relative_for_epe_and_in_points_for_pep(rt, rows):
    summary = rt.family_summary(rows, ["d3", "sgbm", "elas"])
    text = rt.margin_text(summary)
    assert text.startswith("EPE 25.0 % below ELAS's")  # ELAS 2.0 against 1.5
    assert "PEP1 0.50 points below SGBM's" in text
    worse = {"d3": dict(summary["d3"], pep_2=8.0), "sgbm": summary["sgbm"]}
    assert "PEP2 2.00 points above SGBM's" in rt.margin_text(worse)


def test_family_table_bolds_the_lowest_and_marks_carried_rows(rt, rows):
    family = rt.FAMILIES[1]
    summary = rt.family_summary(rows, ["d3", "sgbm", "elas"])
    table = rt.render_family_table([(family, summary, {"elas"})])
    lines = table.splitlines()
    assert lines[0].startswith("| family | pairs | method | EPE |")
    assert lines[2].startswith("| KITTI | 2 | d3stereo (`-c kitti`) | **1.500** |")
    assert lines[3].startswith("| | | SGBM | 2.500 |") and "**10.50**" not in lines[3]
    assert "ELAS †" in lines[4]
    readme = rt.render_family_table([(family, summary, set())], readme=True).splitlines()
    assert readme[0] == "| family | pairs | method | EPE [px] | PEP1 [%] | PEP2 [%] | density [%] |"
    assert len(readme) == 5 and readme[3].count("|") == 8


def test_carried_rows_read_back_what_the_table_wrote(rt, rows):
    family = rt.FAMILIES[0]
    summary = rt.family_summary(rows, ["d3", "sgbm", "elas"])
    table = rt.render_family_table([(family, summary, {"sgbm"})])
    back = rt.carried_rows(table + "\n\nMachine: x.")
    assert set(back) == {("Middlebury", "d3stereo (defaults)"), ("Middlebury", "SGBM"), ("Middlebury", "ELAS")}
    assert back[("Middlebury", "SGBM")] == pytest.approx({"n": 2, "epe": 2.5, "pep_0.5": 30, "pep_1": 10.5,
                                                          "pep_2": 6, "density": 95.0})
    assert rt.carried_rows(None) == {}


def test_build_keeps_rows_of_a_skipped_peer_from_the_previous_table(rt, rows):
    previous = rt.build({"kitti": rows}, {}, None, "CPU, 2 vCPUs")["middlebury-kitti"]
    without_elas = [{k: v for k, v in row.items() if k != "elas"} for row in rows]
    blocks = rt.build({"kitti": without_elas}, {"elas": "pyelas missing"}, previous, "CPU, 2 vCPUs")
    table = blocks["middlebury-kitti"]
    assert "| | | ELAS † | 2.000 |" in table and "pyelas missing" in table
    assert "ELAS" not in blocks["wins"].split("\n\n")[0]  # no per-pair data for a carried peer
    assert "Without ELAS (not run)." in blocks["wins"]
    assert "Machine: CPU, 2 vCPUs." in blocks["results-table"]


def test_per_set_table_has_a_row_group_per_data_set(rt, rows):
    table = rt.render_per_set([(rt.FAMILIES[1], rows, ["sgbm"])]).splitlines()
    assert table[2] == "| kitti2012 | 1 | d3stereo (`-c kitti`) | **1.000** | **10.00** | **5.00** |"
    assert table[5] == "| | | SGBM | 3.000 | **9.00** | 6.00 |"


def test_road_table_bolds_the_lowest_error_and_gives_the_time(rt):
    def road(epe, time):
        return scores(epe, 5, 2, 1) | {"pep_3": 0.5, "time": time}

    rows = [{"pair": "p", "family": "road", "d3stereo+pt": road(0.1, 1.0), "d3stereo": road(0.2, 4.0),
             "sgbm": road(1.5, 0.1), "pt-sgm": road(0.3, 0.1)}]
    table = rt.render_road_table(rows).splitlines()
    assert table[2] == ("| d3stereo, PT on (PT-D3Stereo) | **0.100** | **5.00** | **2.00** | **1.00** | **0.50** | "
                        "100.0 | 1.00 |")
    assert table[3].startswith("| d3stereo, PT off | 0.200 |") and table[3].endswith("| 4.00 |")
    blocks = rt.build({"road": rows}, {}, None, "CPU, 2 vCPUs")
    assert set(blocks) == {"road-synth"} and "--n 12 --seed 0" in blocks["road-synth"]


def test_photometric_table_bolds_the_highest_psnr_and_ssim_and_the_lowest_mse(rt):
    def photo(psnr, ssim, mse):
        return {"psnr": psnr, "ssim": ssim, "mse": mse, "coverage": 90.0}

    rows = [{"pair": "k", "family": "road", "d3stereo+pt": photo(24.0, 0.86, 400), "sgbm": photo(22.0, 0.90, 600)}]
    table = rt.render_photometric_table(rows).splitlines()
    assert table[0].startswith("| method (1 pair) | PSNR dB |")
    assert table[2] == "| d3stereo, PT on (PT-D3Stereo) | **24.00** | 0.860 | **400** | 90.0 |"
    assert table[3] == "| SGBM | 22.00 | **0.900** | 600 | 90.0 |"
    assert set(rt.build({"road-photo": rows}, {}, None, "m")) == {"road-photometric"}


def test_road_check_table_gives_the_summary_the_families_and_the_maps(rt):
    check = {"summary": {"pairs": 63, "gt_potholes": 84, "found": 82, "recall": 82 / 84, "false_defects_per_pair": 0.05,
                         "max_false_defects_in_a_pair": 2, "duplicates": 6, "median_depth_error": 0.073,
                         "median_area_error": 0.066, "median_volume_error": 0.081},
             "families": [{"family": "cone", "gt": 10, "found": 9, "recall": 0.9, "depth": 0.054, "signed_depth": -0.01,
                           "area": 0.12, "volume": 0.121},
                          {"family": "overall", "gt": 84, "found": 82, "recall": 82 / 84, "depth": 0.073,
                           "signed_depth": 0.025, "area": 0.066, "volume": 0.081}],
             "maps": {"n": 63, "epe": 0.1181, "pep_0.5": 7.2277, "pep_1": 2.2014, "pep_2": 0.2398}}
    lines = rt.render_road_check(check).splitlines()
    assert lines[2] == "| 63 | 84 | 97.6 % (82/84) | 0.05 (2) | 6 | 7.3 % | +2.5 % | 6.6 % | 8.1 % |"
    assert "| cone | 10 | 9 | 90 % | 5.4 % | -1.0 % | 12.0 % | 12.1 % |" in lines
    assert lines[-1] == "The 63 maps (`--eval`), mean EPE / PEP0.5 / PEP1 / PEP2: 0.118 / 7.23 / 2.20 / 0.24."
    assert set(rt.build({"road-check": check}, {}, None, "m")) == {"road-check"}


def test_replace_block_swaps_only_the_marked_text(rt):
    text = "intro\n<!-- table:wins:begin -->\nold\nlines\n<!-- table:wins:end -->\noutro\n"
    new = rt.replace_block(text, "wins", "new")
    assert new == "intro\n<!-- table:wins:begin -->\nnew\n<!-- table:wins:end -->\noutro\n"
    assert rt.get_block(new, "wins") == "new"
    readme = "<!-- results-table:begin -->\n<!-- results-table:end -->"
    assert rt.get_block(rt.replace_block(readme, "results-table", "t"), "results-table") == "t"
    assert rt.get_block("nothing", "wins") is None
    with pytest.raises(ValueError, match="markers"):
        rt.replace_block("no markers here", "peer-better", "x")


def test_machine_text_names_cpu_count_and_versions(rt):
    text = rt.machine_text("AMD EPYC", 2, {"Python": "3.11.7", "numpy": "2.4.6", "pyelas": None})
    assert text == "AMD EPYC, 2 vCPUs; Python 3.11.7, numpy 2.4.6"


def test_the_script_s_own_names_need_no_package_and_a_missing_peer_is_skipped(rt, monkeypatch):
    import dataclasses

    from d3cli.config import methods as declarations

    monkeypatch.setattr(declarations, "METHOD_SPECS", tuple(
        dataclasses.replace(s, requires=("d3stereo_no_such_module",)) if s.name == "elas" else s
        for s in declarations.METHOD_SPECS))
    ok, skipped = rt.installed_methods(("d3", "sgbm", "elas"))
    assert ok == ["d3", "sgbm"] and list(skipped) == ["elas"]
    assert "d3stereo_no_such_module" in skipped["elas"]
