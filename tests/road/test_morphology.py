"""A region's dilation at the cost of its box (d3cli.road.morphology) equals OpenCV's on the
whole image."""

import cv2
import numpy as np
import pytest

from d3cli.road.morphology import dilate_near

KERNELS = [cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k)) for k in (3, 5, 25, 161)] + [
    cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3)), np.ones((5, 9), np.uint8)]


def _masks():
    rng = np.random.default_rng(4)
    h, w = 120, 170
    yield np.zeros((h, w), bool)  # empty
    for corner in ((0, 0), (0, w - 1), (h - 1, 0), (h - 1, w - 1)):  # a pixel in each corner
        m = np.zeros((h, w), bool)
        m[corner] = True
        yield m
    for _ in range(4):  # blobs anywhere, some cut by the border
        m = np.zeros((h, w), bool)
        for _ in range(rng.integers(1, 4)):
            cy, cx, r = rng.integers(-10, h + 10), rng.integers(-10, w + 10), rng.integers(1, 25)
            v, u = np.mgrid[0:h, 0:w]
            m |= np.hypot(v - cy, u - cx) < r
        yield m
    yield rng.random((h, w)) < 0.01  # scattered pixels: the box is the image


@pytest.mark.parametrize("k", range(len(KERNELS)))
def test_dilate_near_equals_the_whole_image_dilation(k):
    kernel = KERNELS[k]
    for mask in _masks():
        want = cv2.dilate(mask.astype(np.uint8), kernel).astype(bool)
        np.testing.assert_array_equal(dilate_near(mask, kernel), want)


def test_dilate_near_refuses_a_kernel_with_an_even_side():
    with pytest.raises(ValueError, match="odd sides"):
        dilate_near(np.ones((4, 4), bool), np.ones((4, 3), np.uint8))


def test_fill_holes_is_scipys():
    from scipy import ndimage

    from d3cli.road.morphology import fill_holes

    rng = np.random.default_rng(0)
    for i in range(200):
        mask = rng.random(tuple(rng.integers(1, 50, 2))) < rng.uniform(0.2, 0.9)
        if i % 3 == 0:
            mask = ndimage.binary_dilation(mask)
        np.testing.assert_array_equal(fill_holes(mask), ndimage.binary_fill_holes(mask))
    assert not fill_holes(np.zeros((4, 4), bool)).any()


@pytest.mark.parametrize("k", range(len(KERNELS)))
def test_opening_near_equals_the_whole_image_opening(k):
    from d3cli.road.morphology import opening_near

    kernel = KERNELS[k]
    rng = np.random.default_rng(7)
    masks = list(_masks()) + [rng.random((120, 170)) < 0.9, np.ones((120, 170), bool)]  # dense: most survive
    for mask in masks:
        want = cv2.morphologyEx(mask.astype(np.uint8), cv2.MORPH_OPEN, kernel).astype(bool)
        np.testing.assert_array_equal(opening_near(mask, kernel), want)
