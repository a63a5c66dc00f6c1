"""10/12-bit data in 16-bit PNGs and float images: the pair is
scaled to its type's full range with one factor, detected or declared."""

import cv2
import numpy as np
import pytest

from d3cli.baselines import sgbm_disparity
from d3cli.data.layouts import load_pair_images, normalise_bit_depth, read_pair_folder
from d3cli.data.formats import to_grey
from d3cli.errors import InputError
from tests.helpers import textured_pair


def _write_pair(folder, left, right, source=""):
    folder.mkdir(parents=True, exist_ok=True)
    for name, image in (("left", left), ("right", right)):
        ext = "tif" if image.dtype.kind == "f" else "png"
        assert cv2.imwrite(str(folder / f"{name}.{ext}"), image)
    if source:
        (folder / "SOURCE.txt").write_text(source)
    return read_pair_folder(folder)


@pytest.mark.parametrize("bits", [10, 12])
def test_high_bit_pngs_match_like_their_8_bit_original(tmp_path, bits):
    left8, right8, _ = textured_pair(6, (48, 96), seed=3)
    shift = bits - 8
    pair = _write_pair(tmp_path / "p", left8.astype(np.uint16) << shift, right8.astype(np.uint16) << shift)
    left, right = load_pair_images(pair)
    # 0-1020 (10 bit) used to become 0-4 grey levels; now the grey levels are the 8-bit ones
    np.testing.assert_allclose(to_grey(left), to_grey(left8.astype(np.uint16) << 8) , atol=1e-3)
    assert to_grey(left).max() > 200
    a = sgbm_disparity(left, right, max_disparity=16).disparity
    b = sgbm_disparity(left8, right8, max_disparity=16).disparity
    np.testing.assert_array_equal(a, b)


def test_one_factor_for_both_views():
    left = np.full((4, 4), 1000, np.uint16)
    right = np.full((4, 4), 1023, np.uint16)  # 10 bits; the left alone would look 10 bits too
    l2, r2, bits = normalise_bit_depth(left, right)
    assert bits == 10 and l2[0, 0] == 1000 * 64 and r2[0, 0] == 1023 * 64


def test_declared_bit_depth_wins_and_is_checked(tmp_path):
    left = np.full((8, 8), 100, np.uint16)
    pair = _write_pair(tmp_path / "p", left, left, source="bit_depth: 12\n")
    assert pair.bit_depth == 12
    l2, _ = load_pair_images(pair)
    assert l2[0, 0] == 100 * 16
    bad = _write_pair(tmp_path / "q", np.full((8, 8), 5000, np.uint16), left, source="bit_depth: 12\n")
    with pytest.raises(InputError, match=r"q: samples up to 5000 do not fit bit_depth 12"):
        load_pair_images(bad)


def test_full_16_bit_and_8_bit_data_are_unchanged():
    a = np.array([[0, 65535]], np.uint16)
    assert normalise_bit_depth(a, a)[0] is a
    b = np.array([[0, 255]], np.uint8)
    assert normalise_bit_depth(b, b)[0] is b


@pytest.mark.parametrize("scale, top", [(1 / 255, 1.0), (1.0, 255.0), (4095 / 255, 4095.0)])
def test_float_images_come_out_on_0_255(tmp_path, scale, top):
    left8, right8, _ = textured_pair(6, (48, 96), seed=5)
    left = left8.astype(np.float32) * np.float32(scale)
    right = right8.astype(np.float32) * np.float32(scale)
    pair = _write_pair(tmp_path / "f", left, right)
    l2, r2 = load_pair_images(pair)
    assert l2.dtype == np.float32
    np.testing.assert_allclose(l2, left8, atol=0.1 if top > 255 else 1e-3)


def test_negative_float_samples_are_an_error():
    a = np.array([[-1.0, 2.0]], np.float32)
    with pytest.raises(InputError, match="negative intensities"):
        normalise_bit_depth(a, a, where="p")
