"""An output folder that overlaps the inputs is refused before anything is written or
removed (a ground truth named disp.png was once replaced by the prediction)."""

import hashlib

import pytest
from click.testing import CliRunner

from d3cli.cli import main


def _digest(root):
    return {p.relative_to(root): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(root.rglob("*"))
            if p.is_file()}


@pytest.mark.parametrize("where", ["root", "inside-pair", "pair-itself"])
def test_out_overlapping_the_input_is_refused_and_nothing_changes(tmp_path, make_pair_folder, where):
    root = tmp_path / "pairs"
    folder = make_pair_folder(root, "a")
    (folder / "disp_gt.pfm").rename(folder / "disp.png")  # a ground truth named like an output
    (folder / "SOURCE.txt").unlink()
    make_pair_folder(root, "b", seed=1)
    before = _digest(root)
    out = {"root": root, "inside-pair": folder / "out", "pair-itself": folder}[where]
    inputs = [root] if where != "pair-itself" else [folder]
    result = CliRunner().invoke(main, ["run", *map(str, inputs), "-o", str(out), "--method", "sgbm", "--eval"])
    assert result.exit_code == 1 and "Traceback" not in result.output
    errors = [line for line in result.output.splitlines() if line.startswith("Error:")]
    assert len(errors) == 1 and "would write its outputs into or next to its own input files" in errors[0]
    assert "choose an output folder outside the input data with -o" in errors[0]
    assert _digest(root) == before


def test_a_separate_output_folder_is_fine(tmp_path, make_pair_folder):
    make_pair_folder(tmp_path / "pairs", "a")
    result = CliRunner().invoke(main, ["run", str(tmp_path / "pairs"), "-o", str(tmp_path / "out"),
                                       "--method", "sgbm"])
    assert result.exit_code == 0, result.output
