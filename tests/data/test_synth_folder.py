"""`d3stereo synth` never mixes two datasets in a folder, and refuses sizes it cannot
render (before rendering anything)."""

import json

import pytest
from click.testing import CliRunner

from d3cli.cli import main
from d3cli.data.synth import DATASET_FILE, generate_dataset
from d3cli.errors import InputError, OutputError


def test_rerun_with_the_same_seed_and_size_is_fine_another_seed_is_refused(tmp_path):
    out = tmp_path / "set"
    first = generate_dataset(out, n=1, seed=3, width=64, height=48)
    assert json.loads((out / DATASET_FILE).read_text())["seed"] == 3
    before = (first[0] / "left.png").read_bytes()
    again = generate_dataset(out, n=2, seed=3, width=64, height=48)  # same set, one pair more
    assert again[0] == first[0] and (first[0] / "left.png").read_bytes() == before
    with pytest.raises(OutputError, match=r"set: the folder is not empty \(it holds a synthetic set with seed 3 "
                                          r"and size 64x48\); give an empty or new folder"):
        generate_dataset(out, n=1, seed=4, width=64, height=48)
    with pytest.raises(OutputError, match="seed 3 and size 64x48"):
        generate_dataset(out, n=1, seed=3, width=96, height=48)


def test_a_folder_with_other_files_is_refused(tmp_path):
    (tmp_path / "mine.txt").write_text("keep me")
    with pytest.raises(OutputError, match=r"the folder is not empty \(it holds 1 other entries\)"):
        generate_dataset(tmp_path, n=1, seed=0, width=64, height=48)
    assert (tmp_path / "mine.txt").read_text() == "keep me"


@pytest.mark.parametrize("width, height", [(16, 48), (64, 16), (200000, 48), (64, 9000)])
def test_sizes_outside_32_to_8192_are_refused(tmp_path, width, height):
    with pytest.raises(InputError, match=r"synth: image size \d+x\d+ is too (small|large)"):
        generate_dataset(tmp_path / "s", n=1, seed=0, width=width, height=height)


@pytest.mark.parametrize("option", [["--width", "16"], ["--width", "200000"], ["--height", "9000"]])
def test_cli_refuses_those_sizes_before_rendering(tmp_path, option):
    result = CliRunner().invoke(main, ["synth", str(tmp_path / "s"), "--n", "1", *option])
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert "is not in the range 32<=x<=8192" in result.output
    assert not (tmp_path / "s").exists()
