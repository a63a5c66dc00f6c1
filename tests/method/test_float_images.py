"""Float images given to the API are read as float image files are: values in [0, 1]
are scaled to 0-255 (scikit-image's convention), values up to 255 taken as they are,
larger ones as integer counts of the smallest bit depth that holds them; negative values
are an error."""

import numpy as np
import pytest

from d3cli import D3Stereo, InputError, load_config

from ..helpers import textured_pair


@pytest.fixture(scope="module")
def pair_u8():
    left, right, _ = textured_pair(5, (48, 96), seed=3)
    return left, right


@pytest.fixture(scope="module")
def reference(pair_u8):
    return D3Stereo(load_config()).compute(*pair_u8, max_disparity=16)


@pytest.mark.parametrize("scale", [1 / 255, 1.0, 4095 / 255])
def test_float_images_give_the_maps_of_their_8_bit_pair(pair_u8, reference, scale):
    if scale < 1:  # k / 255 * 255 gives k back exactly in float32
        left, right = (view.astype(np.float32) / np.float32(255) for view in pair_u8)
    else:
        left, right = (view.astype(np.float32) * np.float32(scale) for view in pair_u8)
    if scale > 1:
        left, right = np.round(left), np.round(right)  # 12-bit counts
    result = D3Stereo(load_config()).compute(left, right, max_disparity=16)
    if scale > 1:  # 12-bit counts come back to 0-255 up to rounding: nearly the same map
        same = np.isclose(result.disparity, reference.disparity, atol=0.5) | (
            ~np.isfinite(result.disparity) & ~np.isfinite(reference.disparity))
        assert same.mean() > 0.95
    else:
        np.testing.assert_array_equal(result.disparity, reference.disparity)


def test_negative_float_images_are_refused(pair_u8):
    left, right = (view.astype(np.float32) / 255 for view in pair_u8)
    left[0, 0] = -0.5
    with pytest.raises(InputError) as info:
        D3Stereo(load_config()).compute(left, right, max_disparity=16)
    assert str(info.value) == ("pair: negative intensities (down to -0.5) in a float image; give intensities >= 0 "
                               "(0-1, 0-255 or integer counts)")
