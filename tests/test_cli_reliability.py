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
