"""Ground-truth disparity in any supported encoding (PFM, KITTI PNG, scaled 8/16-bit
images, ``.npy``) and non-occlusion masks.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from ...errors import InputError, where_what_fix
from .images import MAX_IMAGE_PIXELS, _decode_unchanged, _single_channel, regular_file
from .pfm import read_pfm


DISPARITY_EXTENSIONS = (".pfm", ".png", ".pgm", ".ppm", ".tif", ".tiff", ".npy")
INVALID_CONVENTIONS = ("auto", "zero", "inf", "none")


def _normalise_invalid(path: Path, invalid: str) -> str:
    text = str(invalid).strip().lower()
    aliases = {"0": "zero", "zeros": "zero", "infinity": "inf", "nonfinite": "inf", "-": "auto", "": "auto"}
    text = aliases.get(text, text)
    if text not in INVALID_CONVENTIONS:
        raise InputError(
            where_what_fix(
                str(path),
                f"unknown invalid-value convention {invalid!r}",
                f"use one of {', '.join(INVALID_CONVENTIONS)}",
            )
        )
    return text


def _npy_header(path: Path) -> tuple[tuple, np.dtype]:
    """(shape, dtype) from a .npy header, checked against the file's size and
    :data:`MAX_IMAGE_PIXELS` before anything is allocated (a 100-byte file can claim
    900000x900000 floats: 3 TiB)."""
    npy_format = np.lib.format
    try:
        with open(path, "rb") as fh:
            version = npy_format.read_magic(fh)
            reader = npy_format.read_array_header_1_0 if version == (1, 0) else npy_format.read_array_header_2_0
            shape, _, dtype = reader(fh)
            offset = fh.tell()
    except (ValueError, OSError, EOFError) as exc:  # EOFError: an empty or truncated file
        raise InputError(
            where_what_fix(str(path), f"cannot read .npy file ({exc})", "give a NumPy array saved with np.save")
        ) from None
    count = math.prod(shape)
    shape_text = "x".join(map(str, shape))
    if count > MAX_IMAGE_PIXELS:
        raise InputError(where_what_fix(str(path), f".npy header claims a {shape_text} array, more than "
                                                   f"{MAX_IMAGE_PIXELS} values", "give a disparity map of the images' size"))
    found = os.stat(path).st_size - offset
    if not dtype.hasobject and found < count * dtype.itemsize:
        raise InputError(where_what_fix(str(path), f"truncated .npy file: a {shape_text} {dtype} array needs "
                                                   f"{count * dtype.itemsize} bytes, found {found}",
                                        "re-download or re-write the file"))
    return shape, dtype


def _load_npy(path: Path) -> np.ndarray:
    _npy_header(path)
    try:
        array = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:  # EOFError: an empty or truncated file
        raise InputError(
            where_what_fix(str(path), f"cannot read .npy file ({exc})", "give a NumPy array saved with np.save")
        ) from None
    if array.ndim == 3 and array.shape[2] == 1:
        array = array[:, :, 0]
    # Complex values have no disparity meaning (their cast to float drops the imaginary
    # part with a ComplexWarning on stderr).
    real = np.issubdtype(array.dtype, np.integer) or np.issubdtype(array.dtype, np.floating)
    if array.ndim != 2 or not real:
        raise InputError(
            where_what_fix(
                str(path), f"expected a 2-D real-valued disparity array, got {array.dtype} {array.shape}",
                "save (H, W) floats"
            )
        )
    return array


def read_disparity(path: str | os.PathLike, *, scale: float = 1.0, invalid: str = "auto") -> np.ndarray:
    """Read a disparity map in any supported format.

    Parameters
    ----------
    path : str or path-like
        ``.pfm``, ``.png``/``.pgm``/``.ppm``/``.tif`` (integer values) or ``.npy``.
    scale : float, keyword-only
        Stored value per pixel of disparity: disparity = value / scale (KITTI 256,
        Middlebury 2001 8 or 16, 2003 quarter 4, 2005/2006 third 3).
    invalid : {"auto", "zero", "inf", "none"}, keyword-only
        Which stored values mean "no value". ``"auto"`` by format: float formats (PFM,
        npy) non-finite, one rule for both, so a map scores the same in either; integer
        images (PNG/PGM/TIFF, KITTI's encoding) 0, their formats' own rule. ``"zero"``: 0
        (and NaN); ``"inf"``: non-finite; ``"none"``: nothing is converted. ``"0"`` is
        accepted for ``"zero"``.  Ground truth <= 0 is never scored either way
        (:mod:`d3cli.evaluation.metrics` evaluates finite, positive ground truth only).

    Returns
    -------
    ndarray, float32, (H, W)
        Disparity in pixels with inf where invalid.
    """
    path = regular_file(path, "disparity file")
    mode = _normalise_invalid(path, invalid)
    if not (isinstance(scale, (int, float)) and math.isfinite(scale) and scale > 0):
        raise InputError(where_what_fix(str(path), f"disparity scale must be > 0, got {scale!r}", "fix gt_scale"))
    ext = path.suffix.lower()
    if ext == ".pfm":
        raw = read_pfm(path)
        auto = "inf"
    elif ext == ".npy":
        raw = _load_npy(path)
        auto = "inf"
    elif ext in DISPARITY_EXTENSIONS:
        raw = _single_channel(path, _decode_unchanged(path), "disparity image")
        auto = "zero"
    else:
        raise InputError(
            where_what_fix(
                str(path), f"unsupported disparity format '{ext}'", "use .pfm, .png, .pgm or .npy"
            )
        )
    if mode == "auto":
        mode = auto
    raw64 = raw.astype(np.float64)
    disp = (raw64 / float(scale)).astype(np.float32)
    if mode == "none":
        return disp
    bad = ~np.isfinite(raw64)
    if mode == "zero":
        bad |= raw64 == 0
    disp[bad] = np.inf
    return disp


def read_mask(path: str | os.PathLike, *, min_value: int = 1) -> np.ndarray:
    """Read an evaluation mask.

    Parameters
    ----------
    path : str or path-like
        Any image (palette PNGs are expanded by OpenCV; any channel counts).
    min_value : int, keyword-only
        Pixels whose value reaches this are True. The default 1 means nonzero = True;
        Middlebury 2014 ``mask0nocc.png`` needs 255 (128 marks occluded pixels).

    Returns
    -------
    ndarray, bool, (H, W)
    """
    path = regular_file(path, "mask file")
    image = _decode_unchanged(path)
    hit = image >= min_value
    return hit.any(axis=2) if hit.ndim == 3 else hit
