"""Loading a discovered pair: images (bit depth normalised), ground truth and
non-occlusion mask, and the disparity range.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path
from typing import Sequence

import numpy as np

from ...config.checks import value_origin
from ...errors import InputError, where_what_fix
from .. import formats
from .pair import Pair

log = logging.getLogger(__name__)


def _hw(shape) -> str:
    return f"{shape[0]}x{shape[1]}"


def _as_grey_like(image: np.ndarray) -> np.ndarray:
    """Colour -> grey of the same dtype (used only when one view is grey, the other colour)."""
    grey = formats.to_grey(image)
    if image.dtype == np.uint16:
        grey = grey * 257.0
    if image.dtype.kind == "f":
        return grey
    return np.round(grey).astype(image.dtype)


def normalise_bit_depth(left: np.ndarray, right: np.ndarray, *, bits: int | None = None,
                        where: str = "pair") -> tuple[np.ndarray, np.ndarray, int]:
    """Bring the samples of a pair to the full range of their type, with one factor.

    10- and 12-bit camera data stored in 16-bit PNGs would otherwise be read as 0-4 or
    0-16 grey levels (16-bit values are mapped to 0-255 by /257).  Both views get the same
    factor, so that matching and photometric scores see the same scale.

    Parameters
    ----------
    left, right : ndarray
        uint8, uint16 or float32 images of one pair (same dtype).
    bits : int, optional, keyword-only
        Bits per sample declared by the dataset; None: the smallest bit count (>= 8) that
        holds the pair's largest value.  Float images: values <= 1 are taken as 0-1,
        values <= 255 as 0-255, larger ones as ``bits``-bit integers.
    where : str
        Names the pair in errors.

    Returns
    -------
    left, right : ndarray
        uint16 scaled by ``2^(16 - bits)`` (exact), uint8 unchanged, float32 on 0-255.
    bits : int
        The bit depth used.

    Raises
    ------
    InputError
        Values beyond the declared bit depth, or negative float samples.
    """
    top = float(max(left.max(initial=0), right.max(initial=0)))
    if left.dtype == np.uint8:
        return left, right, 8
    if left.dtype == np.uint16:
        used = bits if bits is not None else max(8, int(top).bit_length())
        if top >= 2 ** used:
            raise InputError(where_what_fix(where, f"samples up to {int(top)} do not fit bit_depth {used}",
                                            f"fix bit_depth (at least {int(top).bit_length()}) or remove it"))
        if used >= 16:
            return left, right, 16
        shift = 16 - used
        return (left.astype(np.uint16) << shift), (right.astype(np.uint16) << shift), used
    low = float(min(left.min(initial=0), right.min(initial=0)))
    if low < 0:
        raise InputError(where_what_fix(where, f"negative intensities (down to {low:g}) in a float image",
                                        "give intensities >= 0 (0-1, 0-255 or integer counts)"))
    if bits is None and top <= 1.0:
        scale, used = 255.0, 0
    elif bits is None and top <= 255.0:
        scale, used = 1.0, 8
    else:
        used = bits if bits is not None else max(8, math.ceil(math.log2(top + 1)))
        scale = 255.0 / (2 ** used - 1)
    return (left * np.float32(scale)).astype(np.float32), (right * np.float32(scale)).astype(np.float32), used


def pair_image_size(pair: Pair, *, both: bool = False):
    """The pair's image size from the file headers, without decoding.

    Returns
    -------
    (height, width), or with ``both`` ((w_left, h_left), (w_right, h_right)); None when a
    header cannot be read without decoding.  Lets a batch check memory before it decodes.
    """
    if pair.error is not None:
        raise InputError(pair.error)
    left, right = formats.image_size(pair.left), formats.image_size(pair.right)
    if left is None or right is None:
        return None
    return (left, right) if both else (left[1], left[0])


def load_pair_images(pair: Pair) -> tuple[np.ndarray, np.ndarray]:
    """Read the two views of a pair.

    Parameters
    ----------
    pair : Pair
        A pair from :func:`discover` or :func:`load_manifest`.

    Returns
    -------
    left, right : ndarray
        uint8, uint16 or float32 (0-255), ``(H, W)`` or ``(H, W, 3)`` RGB, same shape and
        dtype.  When one view is grey and the other colour, the colour one is converted
        to grey.  16-bit and float data are scaled to their type's full range with the
        pair's bit depth (:func:`normalise_bit_depth`).

    Raises
    ------
    InputError
        Unreadable image, different sizes, or different bit depths.
    """
    if pair.error is not None:
        raise InputError(pair.error)
    sizes = pair_image_size(pair, both=True)
    if sizes is not None and sizes[0] != sizes[1]:  # refused before decoding either view
        (wl, hl), (wr, hr) = sizes
        raise InputError(where_what_fix(pair.name, f"left is {hl}x{wl} but right is {hr}x{wr}",
                                        "a stereo pair needs equal sizes"))
    left = formats.read_image(pair.left)
    right = formats.read_image(pair.right)
    if left.shape[:2] != right.shape[:2]:
        raise InputError(
            where_what_fix(
                pair.name,
                f"left is {_hw(left.shape)} but right is {_hw(right.shape)}",
                "a stereo pair needs equal sizes",
            )
        )
    if left.dtype != right.dtype:
        raise InputError(
            where_what_fix(
                pair.name,
                f"left is {left.dtype.itemsize * 8}-bit but right is {right.dtype.itemsize * 8}-bit",
                "give both views with the same bit depth",
            )
        )
    left, right, bits = normalise_bit_depth(left, right, bits=pair.bit_depth, where=pair.name)
    if bits not in (8, 16):
        log.debug("%s: %d-bit samples scaled to the full range", pair.name, bits)
    if left.ndim != right.ndim:
        log.warning("%s: one view is grey, the other colour; using grey for both", pair.name)
        left = _as_grey_like(left) if left.ndim == 3 else left
        right = _as_grey_like(right) if right.ndim == 3 else right
    return left, right


def _nocc_min_value(path: Path) -> int:
    # Middlebury 2014 mask0nocc.png: 255 = non-occluded, 128 = occluded, 0 = no GT.
    return 255 if path.name.lower().startswith("mask0nocc") else 1


def load_ground_truth(pair: Pair, shape: Sequence[int]) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Read a pair's ground truth and non-occlusion mask.

    Parameters
    ----------
    pair : Pair
    shape : sequence of int
        ``(H, W, ...)`` of the left image; the ground truth must match ``(H, W)``.

    Returns
    -------
    gt : ndarray float32 (H, W) with inf where invalid, or None without ground truth
    mask : ndarray bool (H, W) (True = evaluate), or None without a mask

    Raises
    ------
    InputError
        Unreadable file, ground truth / mask of another size than the images, or ground
        truth with disparities of the image width or more (a wrong ``gt_scale``).
    """
    if pair.gt is None:
        return None, None
    height, width = int(shape[0]), int(shape[1])
    gt = formats.read_disparity(pair.gt, scale=pair.gt_scale, invalid=pair.gt_invalid)
    if gt.shape != (height, width):
        raise InputError(
            where_what_fix(
                pair.name,
                f"ground truth {Path(pair.gt).name} is {_hw(gt.shape)} but the images are {height}x{width}",
                "give ground truth of the left image's size",
            )
        )
    _check_gt_values(pair, gt, width)
    mask = None
    if pair.nocc is not None:
        mask = formats.read_mask(pair.nocc, min_value=_nocc_min_value(Path(pair.nocc)))
        if mask.shape != (height, width):
            raise InputError(
                where_what_fix(
                    pair.name,
                    f"mask {Path(pair.nocc).name} is {_hw(mask.shape)} but the images are {height}x{width}",
                    "give a mask of the left image's size",
                )
            )
    return gt, mask


def _check_gt_values(pair: Pair, gt: np.ndarray, width: int) -> None:
    """Refuse ground truth with disparities no pixel of an image ``width`` wide can have.

    A left pixel ``u`` matches the right pixel ``u - d``, so ``d < width``: larger values
    mean the file was read with the wrong ``gt_scale`` (a KITTI x256 PNG read with
    ``gt_scale: 1`` gives disparities of thousands of pixels and an EPE to match).
    """
    with np.errstate(invalid="ignore"):
        finite = gt[np.isfinite(gt)]
    top = float(finite.max()) if finite.size else 0.0
    if top >= width:
        raise InputError(where_what_fix(
            pair.name,
            f"ground truth {Path(pair.gt).name} holds disparities up to {top:g} px, more than the image width "
            f"({width} px) allows",
            f"it is read with gt_scale {pair.gt_scale:g}: set gt_scale to the scale the file was written with "
            "(256 for KITTI PNGs) in SOURCE.txt or the manifest"))


def _max_disparity_from_gt(pair: Pair, width: int) -> int | None:
    gt = formats.read_disparity(pair.gt, scale=pair.gt_scale, invalid=pair.gt_invalid)
    _check_gt_values(pair, gt, width)
    finite = gt[np.isfinite(gt) & (gt > 0)]
    if finite.size == 0:
        return None
    # A small margin above the largest true disparity, rounded up to a multiple of 16
    # (what SGBM needs and a comfortable search range for ours).
    return int(16 * math.ceil((math.ceil(float(finite.max())) + 4) / 16))


def resolve_max_disparity(pair: Pair, width: int, override: int | None = None) -> int:
    """Pick the disparity search range of a pair.

    Order: ``override`` (``--max-disparity``), ``pair.max_disparity`` (dataset), a margin
    above the largest ground-truth disparity rounded up to a multiple of 16 (capped at
    ``width - 1``), else ``width // 4``.

    Parameters
    ----------
    pair : Pair
    width : int
        Image width in pixels.
    override : int or None
        User value; wins when given.

    Returns
    -------
    int
        In ``[1, width - 1]``.

    Raises
    ------
    InputError
        A user or dataset value outside ``[1, width - 1]``, or ground truth with
        disparities of the image width or more (a wrong ``gt_scale``).
    """
    if override is not None:
        if isinstance(override, bool) or not isinstance(override, (int, np.integer)) or not 0 < override < width:
            origin = value_origin(override, "")
            if origin:  # from a config file or --set, not from --max-disparity
                raise InputError(where_what_fix(
                    origin, f"{int(override)} must be in [1, {width - 1}] for pair {pair.name} (image width {width})",
                    "set a smaller value there, or pass --max-disparity"))
            raise InputError(
                where_what_fix(
                    pair.name,
                    f"--max-disparity {override} must be in [1, {width - 1}] (image width {width})",
                    "give a smaller positive value",
                )
            )
        return int(override)
    if pair.max_disparity is not None:
        if not 0 < pair.max_disparity < width:
            raise InputError(
                where_what_fix(
                    pair.name,
                    f"max disparity {pair.max_disparity} from the dataset must be in [1, {width - 1}] (image width {width})",
                    "fix max_disparity in the manifest/calib or pass --max-disparity",
                )
            )
        return int(pair.max_disparity)
    if width < 2:
        raise InputError(where_what_fix(pair.name, f"an image {width} pixel wide has no disparity to search",
                                        "give images at least 2 pixels wide"))
    derived = _max_disparity_from_gt(pair, width) if pair.gt is not None else None
    if derived is None:
        derived = width // 4
    # At least 1 (what --max-disparity 1 gives): width // 4 is 0 below 4 pixels.
    return max(1, min(derived, width - 1))
