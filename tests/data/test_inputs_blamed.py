"""Readers apply one documented rule per format, and their messages blame what the user gave.

* ``.npy`` and ``.pfm`` maps are read by one rule (non-finite = no value), so the same
  prediction scores the same in either format;
* ground truth whose disparities are wider than the image (a KITTI x256 PNG read with
  ``gt_scale: 1``) fails that pair's evaluation naming the file and gt_scale, instead of
  an EPE of a thousand pixels;
* a working folder deeper than PATH_MAX is one ``Error:`` line, not ``OSError``;
* OpenCV's size limit set in the environment is named; a calib.txt whose baseline is 0
  is named with that value (not "add calib.txt"); a float TIFF with negative samples is
  named, not its pair.
"""

from __future__ import annotations

import errno
import json
import os
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from d3cli.cli import main
from d3cli.data import formats as io
from d3cli.data.layouts import discover, load_ground_truth, resolve_max_disparity
from d3cli.errors import InputError
from tests.helpers import textured_pair, write_png


def invoke(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def _kitti_png(path: Path, disparity: np.ndarray) -> None:
    """KITTI's encoding: uint16 value = disparity x 256, 0 = no ground truth."""
    stored = np.where(np.isfinite(disparity), np.round(disparity * 256.0), 0).astype(np.uint16)
    assert cv2.imwrite(str(path), stored)


# ----------------------------------------------------------------------------- one rule for .npy and .pfm
def test_npy_and_pfm_are_read_by_one_rule(tmp_path):
    values = np.array([[1.5, 0.0, np.nan], [-2.0, np.inf, 40.0]], np.float32)
    np.save(tmp_path / "d.npy", values)
    io.write_pfm(tmp_path / "d.pfm", values)
    from_npy, from_pfm = io.read_disparity(tmp_path / "d.npy"), io.read_disparity(tmp_path / "d.pfm")
    np.testing.assert_array_equal(from_npy, from_pfm)
    # Non-finite is "no value"; 0 and negative values are values.
    np.testing.assert_array_equal(from_npy, [[1.5, 0.0, np.inf], [-2.0, np.inf, 40.0]])


def test_the_same_prediction_scores_the_same_as_npy_and_pfm(tmp_path, pairs_root):
    """A map whose estimate is 0 on some pixels: the .npy reader took those as "no estimate"
    (EPE 0.833 / density 79 % against 0.938 / 100 % for the same map as .pfm)."""
    from d3cli.batch.scoring import evaluate_predictions

    pairs = discover(pairs_root)
    scores = {}
    for suffix in (".npy", ".pfm"):
        pred = tmp_path / f"pred{suffix}"
        pred.mkdir()
        for name in "abc":
            disparity = io.read_pfm(pairs_root / name / "disp_gt.pfm")
            disparity = np.where(np.isfinite(disparity), disparity, 0.0).astype(np.float32)
            disparity[:, -10:] = 0.0  # an estimate of 0 px: a value, scored as one
            if suffix == ".npy":
                np.save(pred / f"{name}.npy", disparity)
            else:
                io.write_pfm(pred / f"{name}.pfm", disparity)
        rows = evaluate_predictions(pred, pairs, report_dir=tmp_path / f"report{suffix}", progress=False)
        scores[suffix] = [(row["pair"], row["status"], row["epe"], row["density"]) for row in rows]
    assert scores[".npy"] == scores[".pfm"]
    assert all(density == 100.0 for *_, density in scores[".npy"])


# ----------------------------------------------------------------------------- ground truth against the image
def _kitti_scaled_pair(root: Path, name: str = "p1", shift: int = 6) -> Path:
    """A pair folder whose disp_gt.png is KITTI's x256 encoding but has no SOURCE.txt (gt_scale 1)."""
    folder = root / name
    folder.mkdir(parents=True)
    left, right, gt = textured_pair(shift, (48, 96))
    write_png(folder / "left.png", left)
    write_png(folder / "right.png", right)
    _kitti_png(folder / "disp_gt.png", gt)
    return folder


def test_ground_truth_wider_than_the_image_names_the_file_and_gt_scale(tmp_path):
    _kitti_scaled_pair(tmp_path / "data")
    pair = discover(tmp_path / "data")[0]
    expected = ("p1: ground truth disp_gt.png holds disparities up to 1536 px, more than the image width "
                "(96 px) allows; it is read with gt_scale 1: set gt_scale to the scale the file was written "
                "with (256 for KITTI PNGs) in SOURCE.txt or the manifest")
    with pytest.raises(InputError) as info:
        load_ground_truth(pair, (48, 96))
    assert str(info.value) == expected
    with pytest.raises(InputError) as info:
        resolve_max_disparity(pair, 96)
    assert str(info.value) == expected
    # The same file with its scale reads as it should.
    (tmp_path / "data" / "p1" / "SOURCE.txt").write_text("gt_scale: 256\n")
    gt, _ = load_ground_truth(discover(tmp_path / "data")[0], (48, 96))
    assert np.nanmax(np.where(np.isfinite(gt), gt, np.nan)) == 6.0


def test_a_run_scores_no_ground_truth_wider_than_the_image(tmp_path):
    _kitti_scaled_pair(tmp_path / "data")
    out = tmp_path / "out"
    result = invoke("run", tmp_path / "data", "-o", out, "--method", "sgbm", "--eval")
    assert "Traceback" not in result.output
    stored = json.loads((out / "p1" / "result.json").read_text())
    assert stored["metrics"] is None  # was EPE 1020 with no word
    assert stored["evaluation_error"].startswith("p1: ground truth disp_gt.png holds disparities up to 1536 px")
    assert (out / "p1" / "disp.pfm").is_file()  # the map itself is kept


# ----------------------------------------------------------------------------- paths longer than the system allows
def _deep_working_folder(root: Path, depth: int = 25) -> str:
    """Step (relative chdirs) into a folder whose absolute path is longer than PATH_MAX;
    returns the folder to go back to."""
    back = os.getcwd()
    os.chdir(root)
    for _ in range(depth):
        os.mkdir("d" * 200)
        os.chdir("d" * 200)
    return back


def test_a_working_folder_deeper_than_path_max_is_one_error(tmp_path):
    back = _deep_working_folder(tmp_path)
    try:
        os.makedirs("in/p1")
        left, right, _ = textured_pair(4)
        ok = [cv2.imwrite(f"in/p1/{side}.png", image) for side, image in (("left", left), ("right", right))]
        assert all(ok)
        long_path = os.path.abspath("in")
        assert len(os.fsencode(long_path)) > 4096
        with pytest.raises(InputError) as info:
            discover(["in"])
        assert str(info.value) == (f"in: its absolute path is {len(os.fsencode(long_path))} bytes long, more than "
                                   "the system allows (4096); run d3stereo from a shallower folder, or move the "
                                   "data to a shorter path")
        result = invoke("run", "in", "-o", "out", "--method", "sgbm")
        assert result.exit_code == 1
        assert result.output == f"Error: {info.value}\n"
    finally:
        os.chdir(back)


def test_a_name_longer_than_the_system_allows_is_one_error(tmp_path):
    name = str(tmp_path / ("x" * 300))
    with pytest.raises(InputError) as info:
        discover([name])
    shown = f"{name[:60]}...{name[-57:]}"  # a long path: its start and end
    assert str(info.value) == f"{shown}: a name in this path is longer than the system allows (255 bytes); give a shorter name"


def test_any_other_os_error_during_discovery_names_the_input(tmp_path, monkeypatch):
    folder = tmp_path / "in"
    folder.mkdir()

    def refuse(self, *args, **kwargs):
        raise OSError(errno.EIO, "Input/output error", str(self))

    monkeypatch.setattr(Path, "stat", refuse)
    with pytest.raises(InputError) as info:
        discover([folder])
    assert str(info.value) == f"{folder}: cannot read it (Input/output error); check the path and the disk"


# ----------------------------------------------------------------------------- OpenCV's limits from the environment
def test_opencv_width_limit_from_the_environment_is_named(tmp_path, monkeypatch):
    monkeypatch.setenv("OPENCV_IO_MAX_IMAGE_WIDTH", "50")
    write_png(tmp_path / "img.png", np.zeros((48, 96), np.uint8))
    with pytest.raises(InputError) as info:
        io.read_image(tmp_path / "img.png")
    assert str(info.value) == (f"{tmp_path / 'img.png'}: image of 96x48 pixels is wider than "
                               "OPENCV_IO_MAX_IMAGE_WIDTH=50 (set in the environment) lets OpenCV decode; "
                               "raise or unset OPENCV_IO_MAX_IMAGE_WIDTH")


def test_opencv_height_limit_from_the_environment_is_named(tmp_path, monkeypatch):
    monkeypatch.setenv("OPENCV_IO_MAX_IMAGE_HEIGHT", "40")
    write_png(tmp_path / "img.png", np.zeros((48, 30), np.uint8))
    with pytest.raises(InputError) as info:
        io.read_image(tmp_path / "img.png")
    assert str(info.value) == (f"{tmp_path / 'img.png'}: image of 30x48 pixels is taller than "
                               "OPENCV_IO_MAX_IMAGE_HEIGHT=40 (set in the environment) lets OpenCV decode; "
                               "raise or unset OPENCV_IO_MAX_IMAGE_HEIGHT")


def test_opencv_pixel_limit_from_the_environment_is_named(tmp_path, monkeypatch):
    monkeypatch.setenv("OPENCV_IO_MAX_IMAGE_PIXELS", "1000")
    write_png(tmp_path / "img.png", np.zeros((48, 30), np.uint8))
    with pytest.raises(InputError) as info:
        io.read_image(tmp_path / "img.png")
    assert str(info.value) == (f"{tmp_path / 'img.png'}: image of 30x48 pixels has more pixels than "
                               "OPENCV_IO_MAX_IMAGE_PIXELS=1000 (set in the environment) lets OpenCV decode; "
                               "raise or unset OPENCV_IO_MAX_IMAGE_PIXELS")


def test_a_run_names_the_variable_its_pairs_fail_on(tmp_path, make_pair_folder, monkeypatch):
    monkeypatch.setenv("OPENCV_IO_MAX_IMAGE_WIDTH", "50")
    make_pair_folder(tmp_path / "data", "p1")
    out = tmp_path / "out"
    result = invoke("run", tmp_path / "data", "-o", out, "--method", "sgbm")
    assert result.exit_code == 1
    assert "OPENCV_IO_MAX_IMAGE_WIDTH=50 (set in the environment)" in json.loads(
        (out / "run.json").read_text())["failed"][0]["error"]


# ----------------------------------------------------------------------------- calib.txt values
@pytest.mark.parametrize("text, what", [
    ("f: 500\nbaseline: 0\n", "baseline 0 must be > 0"),
    ("f: 500\nbaseline: -0.12\n", "baseline -0.12 must be > 0"),
    ("f: 0\nbaseline: 0.12\n", "f 0 must be > 0"),
    ("cam0=[0 0 10; 0 0 10; 0 0 1]\nbaseline=100\n", "f 0 must be > 0"),
    ("cam0=[500 0 10; 0 500 10; 0 0 1]\nbaseline=0\n", "baseline 0 must be > 0"),
    ("cam0=[500 0 10; 0 500 10; 0 0 1]\nbaseline=-193.001\n", "baseline -193.001 must be > 0"),  # millimetres
])
def test_a_camera_value_of_zero_in_calib_is_named(tmp_path, text, what):
    path = tmp_path / "calib.txt"
    path.write_text(text)
    with pytest.raises(InputError) as info:
        io.read_calib(path)
    assert str(info.value) == (f"{path}: {what}; write the camera's value there, or remove the line "
                               "and set it in the camera section of the config")
    assert io.read_calib(path, camera=False)  # the disparity range alone needs no camera


def test_swapped_projection_matrices_are_named(tmp_path):
    path = tmp_path / "calib.txt"
    path.write_text("P0: 700 0 600 -378 0 700 180 0 0 0 1 0\nP1: 700 0 600 0 0 700 180 0 0 0 1 0\n")
    with pytest.raises(InputError) as info:
        io.read_calib(path)
    assert str(info.value) == (f"{path}: the baseline from P0 and P1 is -0.54, must be > 0; P0 must be the "
                               "left camera's matrix and P1 the right one's")


def test_a_point_cloud_with_a_zero_baseline_names_calib_txt(tmp_path, make_pair_folder):
    folder = make_pair_folder(tmp_path / "data", "p1")
    (folder / "calib.txt").write_text("f: 500\nbaseline: 0\n")
    out = tmp_path / "out"
    plain = invoke("run", tmp_path / "data", "-o", out, "--method", "sgbm")
    assert plain.exit_code == 0, plain.output  # the map needs no camera
    result = invoke("run", tmp_path / "data", "-o", out, "--method", "sgbm", "--pointcloud")
    assert "add calib.txt" not in result.output
    assert f"{folder / 'calib.txt'}: baseline 0 must be > 0" in result.output


# ----------------------------------------------------------------------------- float images
def test_negative_float_samples_name_the_file(tmp_path, make_pair_folder):
    folder = tmp_path / "data" / "p1"
    folder.mkdir(parents=True)
    left, right, _ = textured_pair(4)
    assert cv2.imwrite(str(folder / "left.tif"), left.astype(np.float32) - 300.0)
    assert cv2.imwrite(str(folder / "right.tif"), right.astype(np.float32))
    low = float(left.min()) - 300.0
    with pytest.raises(InputError) as info:
        io.read_image(folder / "left.tif")
    assert str(info.value) == (f"{folder / 'left.tif'}: negative intensities (down to {low:g}) in a float "
                               "image; give intensities >= 0 (0-1, 0-255 or integer counts)")
    out = tmp_path / "out"
    result = invoke("run", tmp_path / "data", "-o", out, "--method", "sgbm")
    assert result.exit_code == 1
    assert f"failed: p1: {info.value}" in result.output


def test_an_opencv_size_assertion_names_the_variables_set(tmp_path, monkeypatch):
    """A header Pillow cannot size, refused by OpenCV itself under a limit the user set."""
    monkeypatch.setenv("OPENCV_IO_MAX_IMAGE_PIXELS", "1000")
    write_png(tmp_path / "img.png", np.zeros((4, 6), np.uint8))

    def refuse(data, flags):
        raise cv2.error("OpenCV(4.9.0) loadsave.cpp:77: error: (-215:Assertion failed) "
                        "pixels <= CV_IO_MAX_IMAGE_PIXELS in function 'validateInputImageSize'\n")

    monkeypatch.setattr(cv2, "imdecode", refuse)
    with pytest.raises(InputError) as info:
        io.read_image(tmp_path / "img.png")
    assert str(info.value) == (f"{tmp_path / 'img.png'}: cannot decode image (OpenCV: (-215:Assertion failed) "
                               "pixels <= CV_IO_MAX_IMAGE_PIXELS in function 'validateInputImageSize'); "
                               "raise or unset OPENCV_IO_MAX_IMAGE_PIXELS=1000 (set in the environment)")
