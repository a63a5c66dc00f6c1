"""Reports: CSV/JSON/Markdown round trips, hand-computed means, side-by-side layout."""

import json
import math
import re

import numpy as np
import pytest

from d3cli.errors import OutputError
from d3cli.evaluation.report import (
    CSV_COLUMNS,
    METRIC_COLUMNS,
    format_table,
    read_pair_csv,
    side_by_side,
    summarize,
    write_pair_csv,
    write_summary,
)

FAIL_MSG = "kitti2012_f: left is 375x1242 but right is 375x1240; a stereo pair needs equal sizes"


def gt_row(pair, family, epe, peps, density, time_s, n_px=100):
    return {
        "pair": pair,
        "family": family,
        "status": "ok",
        "epe": epe,
        "pep_0.5": peps[0],
        "pep_1": peps[1],
        "pep_2": peps[2],
        "pep_3": peps[3],
        "density": density,
        "n_px": n_px,
        "time_s": time_s,
        "error": None,
    }


def make_rows():
    return [
        gt_row("kitti2012_a", "kitti2012", 1.0, (40.0, 20.0, 10.0, 5.0), 90.0, 2.0),
        gt_row("kitti2012_b", "kitti2012", 2.0, (60.0, 30.0, 20.0, 15.0), 70.0, 4.0),
        gt_row("midd_m", "middlebury2014", 0.5, (10.0, 5.0, 2.0, 1.0), 99.0, 1.0),
        {
            "pair": "road_r",
            "family": "road",
            "status": "ok",
            "mse": 10.0,
            "psnr": 38.125,
            "ssim": 0.9,
            "coverage": 95.0,
            "time_s": 3.0,
        },
        {"pair": "kitti2012_f", "family": "kitti2012", "status": "failed", "error": FAIL_MSG},
        {"pair": "road_s", "family": "road", "status": "skipped", "error": "no right image"},
    ]


# ------------------------------------------------------------------------------ CSV


def test_csv_round_trip(tmp_path):
    rows = make_rows()
    rows[0]["note"] = "extra column"
    path = write_pair_csv(tmp_path / "metrics.csv", rows)
    back = read_pair_csv(path)
    assert len(back) == len(rows)
    for original, read in zip(rows, back):
        for column in CSV_COLUMNS:
            assert read[column] == original.get(column), (original["pair"], column)
    assert back[0]["note"] == "extra column"
    assert back[1]["note"] == ""


def test_csv_header_and_cells(tmp_path):
    peps = (1.0, np.float32(0.5), 0.0, 0.0)
    rows = [gt_row("p", "synth", 0.1 + 0.2, peps, float("nan"), 1.5, n_px=np.int64(7))]
    rows[0]["psnr"] = math.inf
    path = write_pair_csv(tmp_path / "metrics.csv", rows)
    header, line = path.read_text().splitlines()
    assert header.split(",") == CSV_COLUMNS
    cells = dict(zip(CSV_COLUMNS, line.split(",")))
    assert cells["epe"] == repr(0.1 + 0.2)  # full precision
    assert cells["pep_1"] == "0.5"
    assert cells["density"] == ""  # NaN = not measured
    assert cells["psnr"] == "inf"
    assert cells["n_px"] == "7"
    assert read_pair_csv(path)[0]["psnr"] == math.inf


# -------------------------------------------------------------------------- summary


def test_summarize_means_by_hand():
    s = summarize(make_rows())
    assert s["counts"] == {"ok": 4, "failed": 1, "skipped": 1, "total": 6}
    assert list(s["families"]) == ["kitti2012", "middlebury2014", "road"]

    kitti = s["families"]["kitti2012"]
    counts = [kitti[key] for key in ("pairs", "ok", "failed", "skipped", "with_gt")]
    assert counts == [3, 2, 1, 0, 2]
    assert kitti["means"]["epe"] == pytest.approx(1.5)
    assert kitti["means"]["pep_0.5"] == pytest.approx(50.0)
    assert kitti["means"]["pep_1"] == pytest.approx(25.0)
    assert kitti["means"]["pep_2"] == pytest.approx(15.0)
    assert kitti["means"]["pep_3"] == pytest.approx(10.0)
    assert kitti["means"]["density"] == pytest.approx(80.0)
    assert kitti["means"]["time_s"] == pytest.approx(3.0)  # the failed pair is not averaged
    assert kitti["means"]["mse"] is None

    road = s["families"]["road"]
    assert (road["ok"], road["skipped"], road["with_gt"]) == (1, 1, 0)
    assert road["means"]["epe"] is None
    assert road["means"]["psnr"] == pytest.approx(38.125)

    overall = s["overall"]
    assert (overall["ok"], overall["with_gt"]) == (4, 3)
    assert overall["means"]["epe"] == pytest.approx(3.5 / 3)
    assert overall["means"]["density"] == pytest.approx((90 + 70 + 99) / 3)
    assert overall["means"]["time_s"] == pytest.approx(2.5)
    assert overall["means"]["coverage"] == pytest.approx(95.0)

    assert s["failures"] == [{"pair": "kitti2012_f", "family": "kitti2012", "error": FAIL_MSG}]
    assert s["skipped"] == [{"pair": "road_s", "family": "road", "reason": "no right image"}]


def test_nan_metrics_are_not_averaged_and_empty_family_is_other():
    rows = [
        {"pair": "a", "family": "", "status": "ok", "epe": float("nan"), "time_s": 1.0},
        {"pair": "b", "status": "ok", "epe": 2.0, "time_s": 3.0},
    ]
    s = summarize(rows)
    assert list(s["families"]) == ["other"]
    assert s["overall"]["means"]["epe"] == 2.0
    assert s["overall"]["with_gt"] == 1


def test_unknown_status_is_rejected():
    with pytest.raises(ValueError, match="status is 'done'"):
        summarize([{"pair": "a", "status": "done"}])


def test_write_summary_files(tmp_path):
    rows = make_rows()
    rows[0]["psnr"] = math.inf
    out = tmp_path / "eval" / "d3"
    extra = {"config": {"window": 5}, "gt": tmp_path, "scale": np.float32(0.5), "levels": np.arange(3)}
    json_path, md_path = write_summary(out, rows, method="d3stereo", extra=extra)

    assert json_path == out / "summary.json" and md_path == out / "summary.md"
    assert sorted(p.name for p in out.iterdir()) == ["metrics.csv", "summary.json", "summary.md"]

    data = json.loads(json_path.read_text())
    assert data["method"] == "d3stereo"
    assert data["extra"] == {"config": {"window": 5}, "gt": str(tmp_path), "scale": 0.5, "levels": [0, 1, 2]}
    expected = summarize(rows)
    expected["overall"]["means"]["psnr"] = None  # JSON has no infinity
    expected["families"]["kitti2012"]["means"]["psnr"] = None
    assert {k: v for k, v in data.items() if k not in ("method", "extra")} == expected
    assert data["families"]["kitti2012"]["means"]["epe"] == pytest.approx(1.5)

    assert [row["pair"] for row in read_pair_csv(out / "metrics.csv")] == [row["pair"] for row in rows]


def test_summary_markdown_tables_and_failures(tmp_path):
    _, md_path = write_summary(tmp_path, make_rows(), method="d3stereo")
    text = md_path.read_text()
    lines = text.splitlines()
    assert lines[0] == "# Evaluation: d3stereo"
    assert "6 pairs: 4 ok, 1 failed, 1 skipped." in lines
    for family in ("kitti2012", "middlebury2014", "road", "Overall", "Failed pairs", "Skipped pairs"):
        assert f"## {family}" in lines
    assert "0 warnings, 1 error." in lines
    # The columns every report shows (summary.shown_columns): ground-truth ones for the pairs
    # with ground truth, photometric ones (no MSE) for the road pair without; PEP 3 stays in
    # metrics.csv.
    header = (
        "| pair | status | EPE [px] | PEP 0.5 [%] | PEP 1 [%] | PEP 2 [%] | density [%] "
        "| PSNR [dB] | SSIM | coverage [%] | time [s] |"
    )
    assert header in lines
    no_photo = "| n/a | n/a | n/a |"
    no_gt = "| n/a | n/a | n/a | n/a | n/a |"
    assert f"| kitti2012_a | ok | 1.000 | 40.00 | 20.00 | 10.00 | 90.00 {no_photo} 2.00 |" in lines
    assert f"| kitti2012_f | failed {no_gt} n/a | n/a | n/a | n/a |" in lines
    assert f"| **mean** | 2 ok | 1.500 | 50.00 | 25.00 | 15.00 | 80.00 {no_photo} 3.00 |" in lines
    assert f"| road | 1 | 0 {no_gt} 38.12 | 0.9000 | 95.00 | 3.00 |" in lines
    overall = "| **overall** | 4 | 3 | 1.167 | 36.67 | 18.33 | 10.67 | 86.33 "
    assert overall + "| 38.12 | 0.9000 | 95.00 | 2.50 |" in lines
    assert lines.index("## Overall") > lines.index("## road")
    assert f"- kitti2012_f: {FAIL_MSG}" in lines
    assert "- road_s: no right image" in lines


def test_markdown_without_failures_says_none_and_hides_empty_columns(tmp_path):
    rows = [gt_row("a", "synth", 1.0, (1.0, 1.0, 1.0, 1.0), 100.0, 1.0)]
    _, md_path = write_summary(tmp_path, rows, method="sgbm")
    text = md_path.read_text()
    assert "## Failed pairs\n\nNone.\n" in text
    assert "PSNR" not in text
    assert "Skipped pairs" not in text


def test_write_summary_into_a_file_is_an_output_error(tmp_path):
    blocker = tmp_path / "taken"
    blocker.write_text("a file, not a folder")
    with pytest.raises(OutputError, match="taken"):
        write_summary(blocker, make_rows(), method="d3stereo")


def test_failed_write_leaves_no_temporary_file(tmp_path):
    (tmp_path / "metrics.csv").mkdir()  # os.replace onto a folder fails
    with pytest.raises(OutputError, match="metrics.csv"):
        write_pair_csv(tmp_path / "metrics.csv", make_rows())
    assert [p.name for p in tmp_path.iterdir()] == ["metrics.csv"]


# -------------------------------------------------------------------- side by side


def test_side_by_side_layout():
    ours = make_rows()
    sgbm = [
        gt_row("kitti2012_a", "kitti2012", 3.0, (80.0, 40.0, 20.0, 10.0), 50.0, 0.5),
        gt_row("kitti2012_b", "kitti2012", 2.0, (60.0, 30.0, 20.0, 15.0), 70.0, 0.25),
    ]
    lines = side_by_side({"d3stereo": ours, "sgbm": sgbm}).splitlines()
    assert lines[0] == "| family | metric | d3stereo | sgbm |"
    assert lines[1] == "| --- | --- | ---: | ---: |"
    assert lines[2:10] == [
        "| kitti2012 | pairs with gt | 2 | 2 |",
        "|  | EPE [px] | 1.500 | 2.500 |",
        "|  | PEP 0.5 [%] | 50.00 | 70.00 |",
        "|  | PEP 1 [%] | 25.00 | 35.00 |",
        "|  | PEP 2 [%] | 15.00 | 20.00 |",
        "|  | density [%] | 80.00 | 60.00 |",
        "|  | time [s] | 3.00 | 0.38 |",
        "| middlebury2014 | pairs with gt | 1 | 0 |",
    ]
    assert "|  | EPE [px] | 0.500 | n/a |" in lines
    family_cells = [line.split(" | ")[0][2:] for line in lines[2:] if not line.startswith("|  |")]
    assert family_cells == ["kitti2012", "middlebury2014", "road", "**overall**"]
    road = lines.index("| road | pairs with gt | 0 | 0 |")
    overall = lines.index("| **overall** | pairs with gt | 3 | 2 |")
    assert lines[road + 1 : overall] == [  # no method has ground truth here: no EPE rows
        "|  | PSNR [dB] | 38.12 | n/a |",
        "|  | SSIM | 0.9000 | n/a |",
        "|  | coverage [%] | 95.00 | n/a |",
        "|  | time [s] | 3.00 | n/a |",
    ]
    assert lines[overall + 1] == "|  | EPE [px] | 1.167 | 2.500 |"
    assert lines[-1] == "|  | time [s] | 2.50 | 0.38 |"


# ------------------------------------------------------------------------ terminal


def test_format_table_is_fixed_width():
    summary = {"method": "d3stereo", **summarize(make_rows())}
    lines = format_table(summary).splitlines()
    assert lines[0] == "d3stereo: 4 ok, 1 failed, 1 skipped of 6 pairs"
    header, *body = lines[1:6]
    assert re.split(r"\s{2,}", header) == ["family", "ok", "with gt", "EPE [px]", "PEP 0.5 [%]", "PEP 1 [%]",
                                           "PEP 2 [%]", "density [%]", "PSNR [dB]", "SSIM", "coverage [%]", "time [s]"]
    assert [line.split()[0] for line in body] == ["kitti2012", "middlebury2014", "road", "overall"]
    assert body[0].split()[:4] == ["kitti2012", "2", "2", "1.500"]
    assert body[-1].split()[3] == "1.167"
    assert len({len(line) for line in [header, *body]}) == 1  # right-aligned numbers: same width
    assert lines[6] == f"failed kitti2012_f: {FAIL_MSG}"
    assert len(lines) == 7  # no warnings: no warnings line


def test_terminal_summary_md_and_page_show_the_same_columns(tmp_path):
    from d3cli.evaluation.html import write_report_html

    rows = make_rows()
    rows[0]["d1_all"], rows[0]["a90_noc"] = 4.0, 2.5  # D1 is shown, A90 is not
    rows[1]["warnings"] = ["were left and right swapped?", "few seeds"]
    summary = {"method": "m", **summarize(rows)}
    terminal = format_table(summary).splitlines()
    terminal_heads = re.split(r"\s{2,}", terminal[1])
    _, md = write_summary(tmp_path, rows, method="m")
    md_lines = md.read_text().splitlines()
    overall = md_lines[md_lines.index("## Overall") + 2]
    md_heads = [cell.strip() for cell in overall.strip("|").split("|")]
    page = write_report_html(tmp_path, rows, title="t").read_text()
    means = page[page.index("<h2>Means per family"):page.index("</thead>", page.index("<h2>Means per family"))]
    page_heads = re.findall(r"<th[^>]*>([^<]*)</th>", means)
    expected = ["family", "ok", "with gt", "EPE [px]", "PEP 0.5 [%]", "PEP 1 [%]", "PEP 2 [%]", "D1 (all) [%]",
                "density [%]", "PSNR [dB]", "SSIM", "coverage [%]", "time [s]"]
    assert terminal_heads == md_heads == page_heads == expected
    # The per-pair tables too: summary.md's family tables and the page's pair table.
    pair_md = next(line for line in md_lines if line.startswith("| pair | status |"))
    pairs = page[page.index('<h2 id="pairs">'):page.index("</thead>", page.index('<h2 id="pairs">'))]
    assert [c.strip() for c in pair_md.strip("|").split("|")][2:] == re.findall(r"<th[^>]*>([^<]*)</th>", pairs)[3:]
    # The same means in all three: kitti2012's D1 is the one pair's 4.00.
    assert terminal[2].split()[:9] == ["kitti2012", "2", "2", "1.500", "50.00", "25.00", "15.00", "4.00", "80.00"]
    assert "| kitti2012 | 2 | 2 | 1.500 | 50.00 | 25.00 | 15.00 | 4.00 | 80.00 | n/a | n/a | n/a | 3.00 |" in md_lines
    assert ("<tr><td class=\"t\">kitti2012</td><td>2</td><td>2</td><td>1.500</td><td>50.00</td><td>25.00</td>"
            "<td>15.00</td><td>4.00</td><td>80.00</td>") in page
    # The warnings: counted in the terminal, beside the pair in summary.md, counted at its top.
    assert terminal[-1] == ("2 warnings on 1 pair: kitti2012_b (each pair's warnings are in report.html and "
                            "its result.json)")
    assert any(line.startswith("| kitti2012_b | ok, 2 warnings | 2.000 |") for line in md_lines)
    assert "2 warnings on 1 pair, 1 error. Each warning is listed under Warnings below." in md_lines
    # Definitions: the shown columns, no other.
    defined = [line.split("**")[1] for line in md_lines[md_lines.index("## Definitions"):] if line.startswith("- **")]
    assert defined == expected[3:]


def test_one_pair_is_one_pair(tmp_path):
    rows = [gt_row("a", "synth", 1.0, (1.0, 1.0, 1.0, 1.0), 100.0, 1.0)]
    summary = summarize(rows)
    assert format_table(summary).splitlines()[0] == "1 ok, 0 failed, 0 skipped of 1 pair"
    _, md = write_summary(tmp_path, rows, method="m")
    assert "1 pair: 1 ok, 0 failed, 0 skipped." in md.read_text().splitlines()
    assert "No warnings, no errors." in md.read_text().splitlines()
    rows += [gt_row("b", "synth", 1.0, (1.0, 1.0, 1.0, 1.0), 100.0, 1.0)]
    rows[1]["warnings"] = ["one"]
    assert format_table(summarize(rows)).splitlines()[-1].startswith("1 warning on 1 pair: b ")
    _, md = write_summary(tmp_path, rows, method="m")
    assert "2 pairs: 2 ok, 0 failed, 0 skipped." in md.read_text().splitlines()
    assert "| b | ok, 1 warning | 1.000 | 1.00 | 1.00 | 1.00 | 100.00 | 1.00 |" in md.read_text().splitlines()


def test_metric_columns_order():
    assert METRIC_COLUMNS[:6] == ["epe", "pep_0.5", "pep_1", "pep_2", "pep_3", "density"]


def test_huge_values_are_written_in_exponent_notation(tmp_path):
    from d3cli.evaluation.html import write_report_html

    rows = [{"pair": "a", "family": "k", "status": "ok", "epe": 3e38, "pep_1": 100.0, "time_s": 1.0}]
    _, md = write_summary(tmp_path, rows, method="m")
    assert "| a | ok | 3.000e+38 | 100.00 | 1.00 |" in md.read_text().splitlines()
    page = write_report_html(tmp_path, rows, title="t").read_text()
    assert '<td data-v="3e+38">3.000e+38</td>' in page and "<b>a</b> EPE 3.000e+38 px<br>" in page
