"""Numbers outside a config: a manifest reads whole numbers as the config
does (``1e2`` is 100) and every integer is bounded up front, on the command line too."""

import pytest
from click.testing import CliRunner

from d3cli.cli import main
from d3cli.config import MAX_CONFIG_INT
from d3cli.data.layouts import discover
from d3cli.errors import InputError


def _manifest(tmp_path, make_pair_folder, value):
    folder = make_pair_folder(tmp_path / "pairs", "a")
    path = tmp_path / "m.yaml"
    path.write_text(f"pairs:\n  - name: x\n    left: {folder / 'left.png'}\n    right: {folder / 'right.png'}\n"
                    f"    max_disparity: {value}\n")
    return path


@pytest.mark.parametrize("text, value", [("1e2", 100), ("64.0", 64), ("32", 32), ("2e9", 2_000_000_000)])
def test_manifest_whole_numbers_in_any_spelling(tmp_path, make_pair_folder, text, value):
    (pair,) = discover([_manifest(tmp_path, make_pair_folder, text)])
    assert pair.max_disparity == value and isinstance(pair.max_disparity, int)


@pytest.mark.parametrize("text, shown", [("99999999999", "99999999999"), ("1e20", "1e+20"), ("64.5", "64.5"),
                                         ("true", "True"), ("-3", "-3")])
def test_manifest_max_disparity_out_of_bounds(tmp_path, make_pair_folder, text, shown):
    path = _manifest(tmp_path, make_pair_folder, text)
    with pytest.raises(InputError) as info:
        discover([path])
    assert str(info.value) == (f"{path} pairs[0] (x): max_disparity must be a positive integer of at most "
                               f"{MAX_CONFIG_INT}, got {shown}; e.g. max_disparity: 64")


@pytest.mark.parametrize("value", [str(2**31), str(10**20), "0"])
def test_cli_max_disparity_is_bounded_before_anything_runs(tmp_path, pairs_root, value):
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["run", str(pairs_root), "-o", str(out), "--max-disparity", value])
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert f"Error: Invalid value for --max-disparity: must be a positive number of pixels (at most {MAX_CONFIG_INT}), " \
           f"got {value[:30]}" in result.output
    assert not out.exists()
