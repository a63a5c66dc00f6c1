"""Morphology of one region's mask at the cost of the region, not of the image.

Used by :mod:`d3cli.road.defects` and :mod:`d3cli.road.outputs`, which dilate every candidate
region of a map by the reference ring and the local-noise disc.  May import numpy, OpenCV,
:mod:`d3cli.road.compiled` and the standard library only.
"""

from __future__ import annotations

import cv2
import numpy as np

from .compiled import dilate, dilate_rows, erode_rows, symmetric_half_widths


def dilate_near(mask: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """``cv2.dilate(mask, kernel)`` of a bool mask, as bool, computed on the mask's bounding
    box grown by the kernel's reach only.

    The same pixels as the dilation of the whole image (outside that box it is empty, and
    inside it the pixels beyond the box are zero either way: OpenCV's border of a dilation
    adds nothing), at the cost of the box: the local-noise disc of
    :func:`d3cli.road.defects.find_defects` (161 px) takes 13 ms per full 640x480 dilation,
    and a noisy map has hundreds of candidate regions (seconds per map on the whole image).

    The dilation itself is compiled (:func:`d3cli.road.compiled.dilate`: rows of the box
    times rows of the kernel instead of pixels times kernel pixels).

    Parameters
    ----------
    mask : ndarray, bool, (H, W)
    kernel : ndarray, uint8, (kh, kw)
        A structuring element with odd sides, anchored at its centre (OpenCV's default).

    Returns
    -------
    ndarray, bool, (H, W)
    """
    if kernel.shape[0] % 2 == 0 or kernel.shape[1] % 2 == 0:
        raise ValueError(f"dilate_near needs a kernel with odd sides, got {kernel.shape}")
    out = np.zeros(mask.shape, bool)
    box = grown_box(mask, kernel.shape[0] // 2, kernel.shape[1] // 2)
    if box is not None:
        # compiled (:func:`d3cli.road.compiled.dilate`, the same pixels): OpenCV's dilation by
        # the 161 px disc costs the box's pixels times the disc's, 36 ms a region at 720p
        out[box] = dilate(mask[box], kernel)
    return out


def grown_box(mask: np.ndarray, ry: int, rx: int) -> tuple[slice, slice] | None:
    """Slices of ``mask``'s bounding box grown by ``ry`` rows and ``rx`` columns (cut at the
    array), or None for an empty mask: where the road report's per-region work reads."""
    rows = np.flatnonzero(mask.any(axis=1))
    if rows.size == 0:
        return None
    cols = np.flatnonzero(mask.any(axis=0))
    return (slice(max(int(rows[0]) - ry, 0), min(int(rows[-1]) + ry + 1, mask.shape[0])),
            slice(max(int(cols[0]) - rx, 0), min(int(cols[-1]) + rx + 1, mask.shape[1])))


def opening_near(mask: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """``cv2.morphologyEx(mask, cv2.MORPH_OPEN, kernel)`` of a bool mask, as bool, computed on
    the mask's bounding box grown by the kernel's reach and a pixel, and only as far as
    needed: when the erosion leaves nothing, the opening is empty and is not dilated.

    The same pixels as the opening of the whole array: a pixel that survives the erosion
    is a pixel of the mask, and everything its kernel reads lies in the grown box (the
    pixels beyond it are background either way); the dilation of those pixels reaches no
    farther.  The terrace cue of :func:`d3cli.road.splitting.split_parts` opens a band
    of a pothole once per depth level, and most bands hold no shelf at all.

    Parameters
    ----------
    mask : ndarray, bool, (H, W)
    kernel : ndarray, uint8, (kh, kw)
        A structuring element with odd sides made of centred row runs (an ellipse, a
        rectangle, a cross: :func:`d3cli.road.compiled.symmetric_half_widths`).

    Returns
    -------
    ndarray, bool, (H, W)
    """
    half = symmetric_half_widths(kernel)
    if half is None or kernel.shape[0] % 2 == 0 or kernel.shape[1] % 2 == 0:
        raise ValueError(f"opening_near needs a kernel of centred row runs with odd sides, got {kernel.shape}")
    out = np.zeros(mask.shape, bool)
    box = grown_box(mask, kernel.shape[0] // 2 + 1, kernel.shape[1] // 2 + 1)
    if box is not None:
        eroded = erode_rows(np.ascontiguousarray(mask[box], np.bool_), half)
        if eroded.any():
            out[box] = dilate_rows(eroded, half)
    return out


def fill_holes(mask: np.ndarray) -> np.ndarray:
    """``scipy.ndimage.binary_fill_holes(mask)``, bool: the mask and every 4-connected piece
    of background it encloses, labelled on the mask's bounding box (grown by a pixel of
    background, which joins whatever reaches the box's edge) instead of the whole array."""
    out = np.array(mask, bool, copy=True)
    rows = np.flatnonzero(out.any(axis=1))
    if rows.size == 0:
        return out
    cols = np.flatnonzero(out.any(axis=0))
    box = (slice(int(rows[0]), int(rows[-1]) + 1), slice(int(cols[0]), int(cols[-1]) + 1))
    background = np.pad(~out[box], 1, constant_values=True).astype(np.uint8)
    _, labels = cv2.connectedComponents(background, connectivity=4)
    out[box] |= (labels != labels[0, 0])[1:-1, 1:-1] & ~out[box]
    return out
