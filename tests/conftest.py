"""Shared fixtures: tiny synthetic stereo pairs built in tmp_path."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.helpers import textured_pair, write_png


@pytest.fixture
def make_pair_folder():
    """Factory: ``make_pair_folder(root, name="pair", shift=6, size=(48, 96), ...) -> Path``.

    Writes ``root/name/left.png``, ``right.png`` and (``gt=True``) ``disp_gt.pfm`` with a
    SOURCE.txt stating ``gt_scale: 1`` and ``gt_invalid: inf``.
    """

    def _make(root, name="pair", shift=6, size=(48, 96), *, seed=0, colour=False, gt=True):
        from d3cli.data.formats import write_pfm

        folder = Path(root) / name
        folder.mkdir(parents=True, exist_ok=True)
        left, right, disp = textured_pair(shift, size, seed=seed, colour=colour)
        write_png(folder / "left.png", left)
        write_png(folder / "right.png", right)
        if gt:
            write_pfm(folder / "disp_gt.pfm", disp)
            (folder / "SOURCE.txt").write_text(
                "provenance: synthetic test pair (tests/conftest.py)\ngt_scale: 1\ngt_invalid: inf\n"
            )
        return folder

    return _make


@pytest.fixture
def make_pair_set(make_pair_folder):
    """Factory: ``make_pair_set(root, names) -> root``, one pair folder per name, shifts
    3, 4, 5, ... and seeds 0, 1, 2, ... (every pair a different map)."""

    def _make(root, names):
        for i, name in enumerate(names):
            make_pair_folder(root, name, shift=3 + i, seed=i)
        return Path(root)

    return _make


@pytest.fixture
def pairs_root(tmp_path, make_pair_folder):
    """A folder of three small pair folders ``a``, ``b``, ``c`` (shifts 4, 6, 8)."""
    root = tmp_path / "pairs"
    for i, name in enumerate("abc"):
        make_pair_folder(root, name, shift=4 + 2 * i, seed=i)
    return root
