"""Property tests: file and folder names of every kind reach discovery and the readers
without a traceback.

Names are drawn with non-ASCII letters, spaces, quotes, leading dashes and dots, bytes
that are not UTF-8 (kept by the file system as surrogate escapes), and lengths up to and
beyond what the file system allows (255 bytes a name, 4096 a path).  Every call either
works (the pair is found and read, with its ground truth) or raises a D3Error subclass
whose message is one line: never another exception.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from d3cli.data import formats as io
from d3cli.data.layouts import discover, load_ground_truth, load_pair_images
from d3cli.errors import D3Error
from tests.helpers import textured_pair

SETTINGS = settings(max_examples=int(os.environ.get("D3_HYPOTHESIS_EXAMPLES", "30")), deadline=None,
                    derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

#: Pieces of names: letters of other scripts, spaces, quotes, shell characters, a byte
#: that is not UTF-8 (Latin-1 'é' as a surrogate escape), an emoji.
PIECES = ["a", "Z", "0", " ", "  ", "é", "ß", "日本", "Ω", "😀", "'", '"', "$x", "*", "?", "[1]", "-", ".", "~",
          "\udce9", "\t", "%s", "\\", "name"]
NAME_MAX = 255


@st.composite
def names(draw) -> str:
    """A file-name component: short or very long, never '/', NUL, '.' or '..'."""
    long = draw(st.sampled_from(["short", "short", "short", "near the limit", "too long"]))
    name = "".join(draw(st.lists(st.sampled_from(PIECES), min_size=1, max_size=12)))
    if long == "near the limit":
        name = (name * (NAME_MAX // max(len(os.fsencode(name)), 1) + 1))
        while len(os.fsencode(name)) > NAME_MAX - 8:  # room for a suffix like ".png"
            name = name[:-1]
    elif long == "too long":
        name = name + "x" * (NAME_MAX + draw(st.integers(1, 200)))
    if name in ("", ".", ".."):
        name = "x" + name
    return name


def _fits(name: str, suffix: str = "") -> bool:
    return 0 < len(os.fsencode(name + suffix)) <= NAME_MAX


def _one_line_error(exc: D3Error) -> None:
    text = str(exc)
    assert text and "\n" not in text.replace("\\n", ""), text


def _write_views(folder: Path, left_name: str = "left.png", right_name: str = "right.png") -> None:
    left, right, _ = textured_pair(3, (16, 24))
    io.write_image(folder / left_name, left)
    io.write_image(folder / right_name, right)


@SETTINGS
@given(names(), st.sampled_from(["npy", "pfm", "png"]))
def test_pair_folders_of_any_name_are_found_and_read(name, gt_format):
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / "data"
        root.mkdir()
        folder = root / name
        if not _fits(name):
            try:
                discover([folder])
            except D3Error as exc:
                _one_line_error(exc)
            return
        folder.mkdir()
        _write_views(folder)
        disparity = np.full((16, 24), 3.0, np.float32)
        if gt_format == "npy":
            np.save(folder / "disp_gt.npy", disparity)
        elif gt_format == "pfm":
            io.write_pfm(folder / "disp_gt.pfm", disparity)
        else:
            io.write_kitti_png(folder / "disp_gt.png", disparity)
            (folder / "SOURCE.txt").write_text("gt_scale: 256\n")
        try:
            pairs = discover([root])
            assert len(pairs) == 1
            left, right = load_pair_images(pairs[0])
            gt, _ = load_ground_truth(pairs[0], left.shape)
        except D3Error as exc:
            _one_line_error(exc)
            return
        assert left.shape == right.shape == (16, 24)
        assert np.all(gt == 3.0)
        assert pairs[0].name and "/" not in pairs[0].name


@SETTINGS
@given(names(), names())
def test_two_image_files_of_any_name_are_a_pair(left_name, right_name):
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        files = [folder / f"{left_name}.png", folder / f"{right_name}.png"]
        try:
            if _fits(left_name, ".png") and _fits(right_name, ".png") and left_name != right_name:
                _write_views(folder, files[0].name, files[1].name)
                (pair,) = discover(files)
                left, right = load_pair_images(pair)
                assert left.shape == right.shape
            else:
                discover(files)
        except D3Error as exc:
            _one_line_error(exc)


@SETTINGS
@given(names(), st.sampled_from([".npy", ".pfm", ".png", ".txt"]))
def test_readers_take_files_of_any_name(name, suffix):
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"{name}{suffix}"
        disparity = np.full((4, 5), 2.5, np.float32)
        try:
            if not _fits(name, suffix):
                io.read_disparity(path)
                return
            if suffix == ".npy":
                np.save(path, disparity)
            elif suffix == ".pfm":
                io.write_pfm(path, disparity)
            elif suffix == ".png":
                io.write_kitti_png(path, disparity)
            else:
                path.write_text("f: 500\nbaseline: 0.1\nndisp: 64\n")
                assert io.read_calib(path)["ndisp"] == 64
                return
            scale = 256.0 if suffix == ".png" else 1.0
            np.testing.assert_array_equal(io.read_disparity(path, scale=scale), disparity)
        except D3Error as exc:
            _one_line_error(exc)


@SETTINGS
@given(st.integers(1, 30), names())
def test_inputs_nested_beyond_the_path_limit_are_one_error(depth, name):
    """Absolute paths of any length (up to several times PATH_MAX) and a last name of any kind."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp, *["d" * 200] * depth, name)
        try:
            discover([path])
        except D3Error as exc:
            _one_line_error(exc)
            if len(os.fsencode(str(path))) > 4096:  # longer than the system allows: shown by its ends
                assert len(str(exc)) < 1000
