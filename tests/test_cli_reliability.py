"""Command-line values refused before any work: infinite colour ranges like NaN ones."""

import pytest
from click.testing import CliRunner

from d3cli.cli import main


@pytest.mark.parametrize("text", ["1:inf", "nan:3", "0:nan", "-inf:3"])
def test_color_range_must_be_finite(tmp_path, text):
    result = CliRunner().invoke(main, ["run", str(tmp_path), "-o", str(tmp_path / "out"), "--color-range", text])
    assert result.exit_code == 2
    assert (f"Invalid value for --color-range: needs 0 <= MIN < MAX, both finite, got '{text}'"
            in result.output)
    assert not (tmp_path / "out").exists()


def test_eval_into_the_ground_truth_folder_is_one_error_line(tmp_path, pairs_root):
    from d3cli.data import formats

    pred = tmp_path / "pred"
    pred.mkdir()
    for name in "abc":
        formats.write_pfm(pred / f"{name}.pfm", formats.read_pfm(pairs_root / name / "disp_gt.pfm"))
    before = sorted(p.name for p in pairs_root.rglob("*"))
    result = CliRunner().invoke(main, ["eval", str(pred), "--gt", str(pairs_root), "-o", str(pairs_root)])
    assert result.exit_code == 1
    assert result.output == (f"Error: {pairs_root}: the report folder holds the folder of pair a's files "
                             f"{pairs_root / 'a'}; give -o a new folder that holds no input and lies inside none "
                             "(predictions and ground truth are only read)\n")
    assert sorted(p.name for p in pairs_root.rglob("*")) == before
