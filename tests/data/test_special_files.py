"""Inputs that exist but are no regular files (a FIFO, /dev/zero, a folder) are named as
what they are, never read (a FIFO would block) and never taken as missing; headers that
claim huge arrays are refused before anything is allocated."""

import os
import warnings

import numpy as np
import pytest

from d3cli.data import formats, layouts as datasets
from d3cli.errors import InputError

DEVICE_FIX = "give the file itself"


def fifo(path):
    os.mkfifo(path)
    return path


def zero_link(path):
    path.symlink_to("/dev/zero")
    return path


@pytest.mark.parametrize("reader", [formats.read_image, formats.read_disparity, formats.read_pfm, formats.read_calib,
                                    formats.read_mask])
def test_a_fifo_is_named_as_one_and_never_opened(tmp_path, reader):
    path = fifo(tmp_path / "x.pfm")
    with pytest.raises(InputError) as info:
        reader(path)
    assert str(info.value) == f"{path}: not a regular file (a FIFO); {DEVICE_FIX}"


def test_a_link_to_dev_zero_is_named_as_a_device(tmp_path):
    path = zero_link(tmp_path / "disp_gt.pfm")
    with pytest.raises(InputError) as info:
        formats.read_disparity(path)
    assert str(info.value) == f"{path}: not a regular file (a link to /dev/zero, a character device); {DEVICE_FIX}"


def test_image_size_of_a_fifo_is_unknown_without_blocking(tmp_path):
    assert formats.image_size(fifo(tmp_path / "left.png")) is None


def npy_claiming(path, shape, dtype="<f4"):
    """A tiny .npy file whose header claims ``shape``."""
    header = np.lib.format.header_data_from_array_1_0(np.zeros((1, 1), dtype=dtype))
    header["shape"] = shape
    with open(path, "wb") as fh:
        np.lib.format.write_array_header_1_0(fh, header)
        fh.write(b"\0" * 64)
    return path


def test_npy_header_claiming_a_huge_array_is_refused_before_allocating(tmp_path):
    path = npy_claiming(tmp_path / "disp_gt.npy", (900000, 900000))
    with pytest.raises(InputError) as info:
        formats.read_disparity(path)
    assert str(info.value) == (f"{path}: .npy header claims a 900000x900000 array, more than "
                               f"{formats.MAX_IMAGE_PIXELS} values; give a disparity map of the images' size")


def test_npy_header_larger_than_the_file_is_truncated(tmp_path):
    path = npy_claiming(tmp_path / "disp_gt.npy", (100, 100))
    with pytest.raises(InputError) as info:
        formats.read_disparity(path)
    assert str(info.value).startswith(f"{path}: truncated .npy file: a 100x100 float32 array needs 40000 bytes, found 64")


def test_complex_npy_is_refused_without_a_numpy_warning(tmp_path):
    path = tmp_path / "disp_gt.npy"
    np.save(path, np.ones((4, 5), dtype=np.complex64))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(InputError) as info:
            formats.read_disparity(path)
    assert str(info.value) == (f"{path}: expected a 2-D real-valued disparity array, got complex64 (4, 5); "
                               "save (H, W) floats")


def test_pfm_header_claiming_a_huge_raster_is_refused_before_reading(tmp_path):
    path = tmp_path / "disp.pfm"
    path.write_bytes(b"Pf\n900000 900000\n-1.0\n" + b"\0" * 64)
    with pytest.raises(InputError) as info:
        formats.read_pfm(path)
    assert str(info.value) == (f"{path}: PFM header claims 900000x900000 pixels, more than "
                               f"{formats.MAX_IMAGE_PIXELS}; give a disparity map of the images' size")


@pytest.mark.parametrize("make", [fifo, zero_link, os.mkdir], ids=["fifo", "dev-zero", "folder"])
def test_a_left_view_that_is_no_file_is_named_not_missing(pairs_root, make):
    left = pairs_root / "a" / "left.png"
    left.unlink()
    make(left)
    pairs = {pair.name: pair for pair in datasets.discover([pairs_root])}
    assert sorted(pairs) == ["a", "b", "c"]
    with pytest.raises(InputError) as info:
        datasets.load_pair_images(pairs["a"])
    assert str(info.value).startswith(f"{left}: ")
    assert "no left image" not in str(info.value) and "not found" not in str(info.value)


@pytest.mark.parametrize("make", [fifo, zero_link], ids=["fifo", "dev-zero"])
def test_ground_truth_that_is_no_file_fails_the_pair(pairs_root, make):
    gt = pairs_root / "a" / "disp_gt.pfm"
    gt.unlink()
    make(gt)
    (pair,) = [p for p in datasets.discover([pairs_root]) if p.name == "a"]
    assert pair.gt == gt
    with pytest.raises(InputError, match=r"^.*disp_gt\.pfm: not a regular file \("):
        datasets.load_ground_truth(pair, (48, 96))


@pytest.mark.parametrize("name", ["calib.txt", "SOURCE.txt"])
def test_calib_or_source_that_is_a_device_is_named(pairs_root, name):
    path = pairs_root / "a" / name
    if path.exists():
        path.unlink()
    zero_link(path)
    with pytest.raises(InputError) as info:
        datasets.read_pair_folder(pairs_root / "a")
    assert str(info.value) == f"{path}: not a regular file (a link to /dev/zero, a character device); {DEVICE_FIX}"


def test_manifest_path_to_a_device_is_named(tmp_path, pairs_root):
    zero_link(tmp_path / "zero.png")
    manifest = tmp_path / "m.yaml"
    manifest.write_text(f"root: {pairs_root}\npairs:\n  - name: x\n    left: a/left.png\n    right: {tmp_path}/zero.png\n")
    with pytest.raises(InputError) as info:
        datasets.discover([manifest])
    assert str(info.value) == (f"{manifest} pairs[0] (x): right is not a regular file (a link to /dev/zero, a "
                               f"character device): {tmp_path}/zero.png; give the file itself")


def test_an_input_that_is_a_fifo_is_named(tmp_path, pairs_root):
    path = fifo(tmp_path / "left.png")
    with pytest.raises(InputError) as info:
        datasets.discover([path, pairs_root / "a" / "right.png"])
    assert str(info.value) == f"{path}: not a regular file (a FIFO); {DEVICE_FIX}"


def test_a_symlink_loop_in_a_dataset_is_warned_once(pairs_root, caplog):
    loop = pairs_root / "loop"
    loop.symlink_to(loop)
    with caplog.at_level("WARNING"):
        pairs = datasets.discover([pairs_root])
    assert [pair.name for pair in pairs] == ["a", "b", "c"]
    warnings_ = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert warnings_ == [f"{loop}: skipped (Too many levels of symbolic links); fix or remove the link"]


@pytest.mark.parametrize("value", ["inf", "1e400", "nan", "0", "-2"])
def test_source_txt_gt_scale_out_of_range_names_source_txt(pairs_root, value):
    source = pairs_root / "a" / "SOURCE.txt"
    source.write_text(f"gt_scale: {value}\n")
    with pytest.raises(InputError) as info:
        datasets.read_pair_folder(pairs_root / "a")
    assert str(info.value) == f"{source}: gt_scale must be a finite number > 0, got {value}; fix the value"


def test_duplicate_names_in_a_manifest_name_their_lines(tmp_path, pairs_root):
    manifest = tmp_path / "m.yaml"
    manifest.write_text(f"root: {pairs_root}\npairs:\n"
                        "  - name: x\n    left: a/left.png\n    right: a/right.png\n"
                        "  - name: y\n    left: b/left.png\n    right: b/right.png\n"
                        "  - name: x\n    left: c/left.png\n    right: c/right.png\n")
    with pytest.raises(InputError) as info:
        datasets.discover([manifest])
    assert str(info.value) == (f"{manifest}: pair name 'x' is used twice (pairs[0] at line 3 and pairs[2] at "
                               "line 9); give each pair its own name")


@pytest.mark.parametrize("width, expected", [(2, 1), (3, 1), (4, 1), (8, 2)])
def test_narrow_images_get_the_range_they_allow(pairs_root, width, expected):
    pair = datasets.Pair(name="n", left=pairs_root / "a" / "left.png", right=pairs_root / "a" / "right.png")
    assert datasets.resolve_max_disparity(pair, width) == expected


def test_one_pixel_wide_images_have_no_range(pairs_root):
    pair = datasets.Pair(name="n", left=pairs_root / "a" / "left.png", right=pairs_root / "a" / "right.png")
    with pytest.raises(InputError) as info:
        datasets.resolve_max_disparity(pair, 1)
    assert str(info.value) == "n: an image 1 pixel wide has no disparity to search; give images at least 2 pixels wide"


def test_pair_folders_beside_a_stereo_road_pair_both_run(tmp_path, make_pair_folder, caplog):
    from ..helpers import textured_pair, write_png

    root = tmp_path / "mixed"
    make_pair_folder(root, "p")
    left, right, _ = textured_pair(4)
    for side, image in (("left", left), ("right", right)):
        (root / side).mkdir()
        write_png(root / side / "0001.png", image)
    with caplog.at_level("WARNING"):
        pairs = datasets.discover([root])
    assert [pair.name for pair in pairs] == ["p", "stereo-road-0001"]
    assert [r.getMessage() for r in caplog.records] == [
        f"{root}: holds a stereo-road dataset and pair folders (p); running both"]
