"""An output folder that overlaps the inputs is refused before anything is written or
removed (a ground truth named disp.png was once replaced by the prediction)."""

import hashlib

import pytest
from click.testing import CliRunner

from d3cli.cli import main


def _digest(root):
    return {p.relative_to(root): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(root.rglob("*"))
            if p.is_file()}


@pytest.mark.parametrize("where", ["root", "pair-itself"])
def test_out_overlapping_the_input_is_refused_and_nothing_changes(tmp_path, make_pair_folder, where):
    root = tmp_path / "pairs"
    folder = make_pair_folder(root, "a")
    (folder / "disp_gt.pfm").rename(folder / "disp.png")  # a ground truth named like an output
    (folder / "SOURCE.txt").unlink()
    make_pair_folder(root, "b", seed=1)
    before = _digest(root)
    out = {"root": root, "pair-itself": folder}[where]
    inputs = [root] if where != "pair-itself" else [folder]
    result = CliRunner().invoke(main, ["run", *map(str, inputs), "-o", str(out), "--method", "sgbm", "--eval"])
    assert result.exit_code == 1 and "Traceback" not in result.output
    errors = [line for line in result.output.splitlines() if line.startswith("Error:")]
    assert errors == [f"Error: {out}: the output folder holds input files of pair a ({folder / 'left.png'}); "
                      "choose an output folder outside the input data with -o (a new folder beside the inputs "
                      "is fine)"]
    assert _digest(root) == before


def test_a_new_output_folder_inside_a_pair_folder_leaves_the_inputs_alone(tmp_path, make_pair_folder):
    """No input lies inside OUT, so nothing of the user's can be written over (it was
    refused as "into or next to its own input files")."""
    root = tmp_path / "pairs"
    folder = make_pair_folder(root, "a")
    (folder / "disp_gt.pfm").rename(folder / "disp.png")
    (folder / "SOURCE.txt").unlink()
    make_pair_folder(root, "b", seed=1)
    before = _digest(root)
    result = CliRunner().invoke(main, ["run", str(root), "-o", str(folder / "out"), "--method", "sgbm", "--eval"])
    assert result.exit_code == 0, result.output
    assert {k: v for k, v in _digest(root).items() if k.parts[:2] != ("a", "out")} == before
    assert (folder / "out" / "a" / "disp.png").is_file()


def test_a_separate_output_folder_is_fine(tmp_path, make_pair_folder):
    make_pair_folder(tmp_path / "pairs", "a")
    result = CliRunner().invoke(main, ["run", str(tmp_path / "pairs"), "-o", str(tmp_path / "out"),
                                       "--method", "sgbm"])
    assert result.exit_code == 0, result.output
