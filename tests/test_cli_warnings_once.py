"""Each warning of a pair reaches the user once."""

import subprocess
import sys

import pytest


@pytest.mark.parametrize("method", ["pt-sgm", "d3stereo"])
def test_pt_fallback_warning_is_printed_once(tmp_path, make_pair_folder, method):
    make_pair_folder(tmp_path / "pairs", "a", shift=6, size=(64, 128))  # random texture: no road plane
    done = subprocess.run([sys.executable, "-m", "d3cli", "run", str(tmp_path / "pairs"), "-o", str(tmp_path / "o"),
                           "--method", method, "--set", "pt.enabled=true", "--max-disparity", "24"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    text = done.stdout + done.stderr
    assert text.count("perspective transformation skipped") == 1, text
