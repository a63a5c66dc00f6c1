"""Only d3stereo's own lines on stderr: libpng's and OpenCV's messages about a corrupt
image, and Python warnings from libraries, stay off the terminal (logged at DEBUG)."""

import logging
import os
import subprocess
import sys
import warnings

import cv2
import numpy as np
import pytest

from d3cli.cli import route_library_warnings
from d3cli.data import formats
from d3cli.errors import InputError

from ..helpers import textured_pair, write_png


def corrupt_png(path, seed=0):
    """A PNG with a valid header and a damaged IDAT chunk (libpng prints an error)."""
    ok, buffer = cv2.imencode(".png", textured_pair(4, seed=seed)[0])
    data = bytearray(buffer.tobytes())
    start = data.find(b"IDAT") + 6
    for k in range(start, start + 24):
        data[k] ^= 0x5A
    path.write_bytes(bytes(data))
    return path


def ihdr_not_first(path):
    ok, buffer = cv2.imencode(".png", textured_pair(4)[0])
    data = bytearray(buffer.tobytes())
    data[12:16] = b"IXXX"
    path.write_bytes(bytes(data))
    return path


def _without_cli_handlers(monkeypatch):
    """Drop the terminal handler a CLI test earlier in this process left on the root logger
    (with ``-v`` it prints DEBUG); pytest's capture handlers stay.  A command sets up its
    own handlers on every run."""
    root = logging.getLogger()
    monkeypatch.setattr(root, "handlers", [h for h in root.handlers if type(h).__module__.startswith("_pytest")])


# libpng's line is caught and logged; OpenCV's own log is silenced at its source.
@pytest.mark.parametrize("make, n_logged", [(corrupt_png, 1), (ihdr_not_first, 0)], ids=["idat", "ihdr"])
def test_decoder_messages_are_logged_not_printed(tmp_path, capfd, caplog, monkeypatch, make, n_logged):
    _without_cli_handlers(monkeypatch)
    path = make(tmp_path / "left.png")
    with caplog.at_level(logging.DEBUG, logger="d3cli"):
        with pytest.raises(InputError, match=r"left\.png: cannot read image \(corrupt or not an image\)"):
            formats.read_image(path)
    assert capfd.readouterr().err == ""
    said = [r.getMessage() for r in caplog.records if "decoder:" in r.getMessage()]
    assert len(said) == n_logged and all(line.startswith(f"{path}: decoder: libpng error: ") for line in said)


def test_library_warnings_go_to_the_debug_log(capsys, caplog, monkeypatch):
    # an earlier test's capture may have been undone by pytest's own warning recorder:
    # start from logging's initial state, as a command does
    logging.captureWarnings(False)
    _without_cli_handlers(monkeypatch)
    route_library_warnings(verbose=False)
    try:
        with caplog.at_level(logging.DEBUG):
            with warnings.catch_warnings():
                warnings.simplefilter("always")
                np.float32(3e38) * np.float32(10)  # RuntimeWarning: overflow encountered
        assert capsys.readouterr().err == ""
        debug = [r for r in caplog.records if "overflow" in r.getMessage()]
        assert [r.levelname for r in debug] == ["DEBUG"]
    finally:
        logging.captureWarnings(False)


def test_eval_of_a_corrupt_image_prints_only_its_own_lines(tmp_path, make_pair_folder):
    pair = make_pair_folder(tmp_path / "gt", "a", shift=4)
    corrupt_png(pair / "left.png")
    pred = tmp_path / "pred"
    pred.mkdir()
    formats.write_pfm(pred / "a.pfm", np.full((48, 96), 4.0, np.float32))
    env = {**os.environ, "PYTHONPATH": os.getcwd()}
    proc = subprocess.run([sys.executable, "-m", "d3cli", "eval", str(pred), "--gt", str(tmp_path / "gt"),
                           "-o", str(tmp_path / "rep"), "-q"], capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 1
    lines = proc.stderr.splitlines()
    assert lines == [f"failed: pred/a: {pair / 'left.png'}: cannot read image (corrupt or not an image); "
                     "give an 8/16-bit PNG, JPEG, PPM/PGM or TIFF file",
                     f"Error: 1 of 1 pair failed (see {tmp_path / 'rep' / 'summary.json'})"]
