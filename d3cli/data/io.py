"""Reading and writing images, disparity maps, masks and calibration files.

Conventions used everywhere in d3stereo:

* Images are NumPy arrays of dtype uint8 or uint16, ``(H, W)`` grey or ``(H, W, 3)``
  **RGB** (OpenCV's BGR order is converted on the way in and out; alpha is dropped).
* Disparity maps are float32 ``(H, W)`` in pixels of the stored images, with ``inf``
  where there is no value ("invalid").  A left pixel ``(u, v)`` matches the right
  pixel ``(u - d, v)``.
* Ground-truth files keep their native encodings:

  ==============  ======================================  =================
  format          value                                   invalid
  ==============  ======================================  =================
  ``.pfm``        float32, rows stored bottom-up           ``inf``
  KITTI ``.png``  uint16 / 256                            0
  ``.png/.pgm``   8/16-bit / scale (Middlebury 2001-2006:  0
                  /8 or /16, /4, /3)
  ``.npy``        float                                   non-finite, <= 0
  ==============  ======================================  =================

Every writer is atomic (a temporary file in the same folder, then ``os.replace``), so an
interrupted run never leaves a half-written output behind.  User mistakes raise
:class:`~d3cli.errors.InputError` / :class:`~d3cli.errors.OutputError` with the message
form ``<where>: <what>; <fix>``.
"""

from __future__ import annotations

import errno
import logging
import math
import os
import re
from pathlib import Path
from typing import Callable

import cv2
import numpy as np

from ..errors import InputError, OutputError, where_what_fix

log = logging.getLogger(__name__)

# OpenCV prints its own "[ WARN:0@...] PNG input buffer is incomplete" lines to stderr for
# files that this module then reports as one Error naming the file: keep only errors.
cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)

#: Largest image decoded (pixels): 16384^2, ~1.6 GB as 16-bit RGB.
MAX_IMAGE_PIXELS = 16384 * 16384
IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".ppm", ".pgm", ".pnm", ".tif", ".tiff", ".bmp")
DISPARITY_EXTENSIONS = (".pfm", ".png", ".pgm", ".ppm", ".tif", ".tiff", ".npy")
INVALID_CONVENTIONS = ("auto", "zero", "inf", "none")

# ITU-R BT.601 luma weights, the ones OpenCV and most stereo code use.
_LUMA_RGB = np.array([0.299, 0.587, 0.114], dtype=np.float32)

# Keys read_calib may return, with the numeric type of each.
CALIB_KEYS = {
    "f": float,
    "baseline": float,
    "cx": float,
    "cy": float,
    "doffs": float,
    "ndisp": int,
    "width": int,
    "height": int,
    "height_m": float,
    "pitch_deg": float,
    "roll_deg": float,
    "vmin": float,
    "vmax": float,
}
_CALIB_ALIASES = {"focal": "f", "fx": "f", "focal_px": "f", "baseline_m": "baseline"}


# --------------------------------------------------------------------------- helpers


def _existing_file(path: str | os.PathLike, what: str = "file") -> Path:
    """Return ``path`` as a Path, raising InputError when it is missing or a folder."""
    path = Path(path)
    if not path.exists():
        raise InputError(where_what_fix(str(path), f"{what} not found", "check the path"))
    if path.is_dir():
        raise InputError(where_what_fix(str(path), "is a folder, not a file", "give the file itself"))
    return path


def _read_bytes(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except OSError as exc:
        raise InputError(
            where_what_fix(str(path), f"cannot read file ({exc.strerror})", "check its permissions")
        ) from None


def image_size(path: str | os.PathLike) -> tuple[int, int] | None:
    """(width, height) from the image file's header, without decoding the pixels.

    A 1 MB PNG can claim 32000x32000 pixels (3 GB once decoded): sizes are checked from
    the header first.  Returns None when the header cannot be read this way (the decoder
    then says what is wrong).  Uses Pillow (a dependency of scikit-image) for the header.
    """
    from PIL import Image  # header parsing only; OpenCV has no header-only reader

    try:
        with Image.open(path) as image:  # lazy: reads the header, decodes nothing
            return int(image.size[0]), int(image.size[1])
    except Image.DecompressionBombError:  # Pillow refuses > 179 Mpx even to open
        limit, Image.MAX_IMAGE_PIXELS = Image.MAX_IMAGE_PIXELS, None
        try:
            with Image.open(path) as image:
                return int(image.size[0]), int(image.size[1])
        finally:
            Image.MAX_IMAGE_PIXELS = limit
    except Exception:  # noqa: BLE001 - any header Pillow cannot parse: let OpenCV decide
        return None


def _opencv_max_side() -> int:
    """Longest image side OpenCV's decoders accept: 2**20 unless the user raised it with
    ``OPENCV_IO_MAX_IMAGE_WIDTH`` / ``OPENCV_IO_MAX_IMAGE_HEIGHT`` (OpenCV's own variables)."""
    limits = []
    for name in ("OPENCV_IO_MAX_IMAGE_WIDTH", "OPENCV_IO_MAX_IMAGE_HEIGHT"):
        try:
            limits.append(int(os.environ.get(name, 1 << 20)))
        except ValueError:
            limits.append(1 << 20)
    return min(limits)


def _decode_unchanged(path: Path) -> np.ndarray:
    """Decode an image file with OpenCV keeping bit depth and channels (BGR order)."""
    # imdecode on the raw bytes instead of imread(path): imread cannot open non-ASCII
    # paths on some platforms and says nothing about why it failed.
    size = image_size(path)
    if size is not None and size[0] * size[1] > MAX_IMAGE_PIXELS:
        raise InputError(where_what_fix(
            str(path), f"image of {size[0]}x{size[1]} pixels is larger than {MAX_IMAGE_PIXELS} pixels "
                       f"(about {size[0] * size[1] * 6 / 1e9:.1f} GB to decode)",
            "give an image of at most 16384x16384 pixels, or crop or downscale it"))
    side = _opencv_max_side()
    if size is not None and max(size) > side:
        # OpenCV would refuse it with its own assertion text (or libpng lines on stderr)
        # and no file name (issue 12 item 13).
        raise InputError(where_what_fix(
            str(path), f"image of {size[0]}x{size[1]} pixels has a side longer than {side} pixels, "
                       "the most OpenCV decodes",
            "crop or downscale it (a stereo pair this wide is likely a mistake)"))
    data = np.frombuffer(_read_bytes(path), dtype=np.uint8)
    try:
        image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    except cv2.error as exc:  # e.g. a header beyond OpenCV's own size limit
        # "OpenCV(4.9.0) /path/loadsave.cpp:77: error: (-215:Assertion failed) ... in function
        # '...'": the part after "error:" says what is wrong.
        reason = " ".join(str(exc).split()).rpartition(" error: ")[2][:160]
        raise InputError(where_what_fix(str(path), f"cannot decode image (OpenCV: {reason})",
                                        "give an 8/16-bit PNG, JPEG, PPM/PGM or TIFF of a sensible size")) from None
    if image is None:
        raise InputError(
            where_what_fix(
                str(path),
                "cannot read image (corrupt or not an image)",
                "give an 8/16-bit PNG, JPEG, PPM/PGM or TIFF file",
            )
        )
    return image


def _bgr_to_rgb(image: np.ndarray) -> np.ndarray:
    """(H, W) stays; (H, W, 1) -> (H, W); BGR(A) -> RGB (alpha dropped)."""
    if image.ndim == 2:
        return image
    channels = image.shape[2]
    if channels == 1:
        return image[:, :, 0]
    if channels == 2:  # grey + alpha
        return image[:, :, 0]
    return image[:, :, 2::-1]


def _shape_text(shape) -> str:
    """``(H, W, ...)`` -> ``'HxW'`` as in the error messages."""
    return f"{shape[0]}x{shape[1]}"


# --------------------------------------------------------------------------- images


def read_image(path: str | os.PathLike) -> np.ndarray:
    """Read an 8- or 16-bit image.

    Parameters
    ----------
    path : str or path-like
        PNG, JPEG, PPM/PGM, TIFF or BMP file; grey, grey+alpha, RGB or RGBA.

    Returns
    -------
    ndarray
        uint8, uint16 or float32 (float TIFF; values as stored), ``(H, W)`` for grey
        images, ``(H, W, 3)`` RGB otherwise (alpha dropped).

    Raises
    ------
    InputError
        The file is missing, unreadable, corrupt, or not 8/16-bit.
    """
    path = _existing_file(path, "image file")
    image = _decode_unchanged(path)
    if image.dtype.kind == "f":
        image = image.astype(np.float32, copy=False)
        if not np.isfinite(image).all():
            raise InputError(where_what_fix(str(path), "float image with NaN or inf samples",
                                            "give finite intensities (or an 8/16-bit image)"))
    elif image.dtype not in (np.uint8, np.uint16):
        raise InputError(
            where_what_fix(
                str(path),
                f"unsupported pixel type {image.dtype} (expected 8/16-bit integers or float)",
                "convert the image to 8- or 16-bit PNG",
            )
        )
    return np.ascontiguousarray(_bgr_to_rgb(image))


def to_grey(img: np.ndarray) -> np.ndarray:
    """Convert an image to float32 grey levels on the 0-255 scale.

    Parameters
    ----------
    img : ndarray
        ``(H, W)`` or ``(H, W, 3)`` RGB (``(H, W, 4)`` RGBA: alpha ignored); uint8,
        uint16 (divided by 257 so 65535 -> 255) or float (taken as 0-255 already).

    Returns
    -------
    ndarray, float32, (H, W)
        ``0.299 R + 0.587 G + 0.114 B`` for colour images.
    """
    img = np.asarray(img)
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    if img.ndim == 3 and img.shape[2] in (3, 4):
        grey = img[:, :, :3].astype(np.float32) @ _LUMA_RGB
    elif img.ndim == 2:
        grey = img.astype(np.float32)
    else:
        raise ValueError(f"to_grey expects (H, W) or (H, W, 3) images, got shape {img.shape}")
    if img.dtype == np.uint16:
        grey /= np.float32(257.0)
    return np.ascontiguousarray(grey, dtype=np.float32)


def _encode_image(path: Path, image: np.ndarray) -> bytes:
    ext = path.suffix.lower() or ".png"
    ok, buffer = cv2.imencode(ext, image)
    if not ok:
        raise OutputError(
            where_what_fix(str(path), f"OpenCV cannot encode {image.dtype} {image.shape} as {ext}", "use .png")
        )
    return buffer.tobytes()


def write_encoded(path: Path, image: np.ndarray) -> None:
    """Encode ``image`` by the extension of ``path`` and write it there (not atomic: the
    public writers call this on a temporary file)."""
    Path(path).write_bytes(_encode_image(Path(path), image))


def write_image(path: str | os.PathLike, img: np.ndarray) -> Path:
    """Write an image atomically (format from the extension, RGB converted to BGR).

    Parameters
    ----------
    path : str or path-like
        Output file (``.png`` keeps 16-bit data; ``.jpg`` is 8-bit only).
    img : ndarray
        uint8 or uint16, ``(H, W)`` grey or ``(H, W, 3)`` RGB.

    Returns
    -------
    Path
        The written file.
    """
    img = np.asarray(img)
    if img.ndim == 3 and img.shape[2] == 3:
        img = np.ascontiguousarray(img[:, :, ::-1])
    elif img.ndim == 3 and img.shape[2] == 4:
        img = np.ascontiguousarray(img[:, :, [2, 1, 0, 3]])
    return atomic_write(path, lambda tmp: write_encoded(tmp, img))


# --------------------------------------------------------------------------- PFM

_PFM_TOKEN = re.compile(rb"\s*(\S+)")


def _parse_pfm_header(path: Path, data: bytes) -> tuple[int, int, int, str, int]:
    """Return (channels, width, height, byte order '<' or '>', data offset)."""
    tokens = []
    pos = 0
    for _ in range(4):  # identifier, width, height, scale
        match = _PFM_TOKEN.match(data, pos, min(len(data), pos + 64))
        if match is None:
            break
        tokens.append(match.group(1))
        pos = match.end()
    bad = InputError(
        where_what_fix(
            str(path),
            f"not a PFM file (header {data[:20]!r})",
            "give a PFM written as 'PF'/'Pf', 'W H', scale, then float32 rows",
        )
    )
    if len(tokens) < 4 or tokens[0] not in (b"PF", b"Pf"):
        raise bad
    try:
        width, height, scale = int(tokens[1]), int(tokens[2]), float(tokens[3])
    except ValueError:
        raise bad from None
    if width <= 0 or height <= 0 or not math.isfinite(scale):
        raise bad
    if scale == 0:
        # the sign of the scale is the byte order: 0 (or -0) says neither
        raise InputError(where_what_fix(str(path), "PFM scale is 0, so the byte order is unknown",
                                        "write the file with scale -1 (little-endian) or 1 (big-endian)"))
    channels = 3 if tokens[0] == b"PF" else 1
    # The sign of the scale is the byte order; its magnitude is not applied to the data
    # (Middlebury writes -1/255 and stores disparities in pixels).
    byte_order = "<" if math.copysign(1.0, scale) < 0 else ">"
    # One whitespace character separates the header from the raster; files written on
    # Windows end the header with CRLF.  The raster size decides, since a raster may
    # itself start with the byte 0x0A.
    offset = pos + 1
    raster_bytes = 4 * width * height * channels
    if data[pos:pos + 2] == b"\r\n" and len(data) - (pos + 2) == raster_bytes:
        offset = pos + 2
    return channels, width, height, byte_order, offset


def read_pfm_raw(path: str | os.PathLike) -> np.ndarray:
    """Read every channel of a PFM file, top row first.

    Returns
    -------
    ndarray, float32
        ``(H, W)`` for ``Pf`` files, ``(H, W, 3)`` for ``PF`` files; values bit-exact.
    """
    path = _existing_file(path, "PFM file")
    data = _read_bytes(path)
    channels, width, height, byte_order, offset = _parse_pfm_header(path, data)
    count = width * height * channels
    available = len(data) - offset
    if available < 4 * count:
        raise InputError(
            where_what_fix(
                str(path),
                f"truncated PFM: {width}x{height}x{channels} needs {4 * count} bytes of data, found {available}",
                "re-download or re-write the file",
            )
        )
    raster = np.frombuffer(data, dtype=f"{byte_order}f4", count=count, offset=offset)
    raster = raster.reshape(height, width, channels)[::-1]  # rows are stored bottom-up
    raster = raster.astype(np.float32)  # native byte order; values unchanged bit for bit
    return raster[:, :, 0] if channels == 1 else raster


def read_pfm(path: str | os.PathLike) -> np.ndarray:
    """Read a PFM disparity map.

    Parameters
    ----------
    path : str or path-like
        Little- or big-endian (sign of the header scale) ``Pf`` or ``PF`` file.

    Returns
    -------
    ndarray, float32, (H, W)
        Values exactly as stored (inf stays inf); for a 3-channel ``PF`` file the first
        channel.
    """
    raster = read_pfm_raw(path)
    return np.ascontiguousarray(raster[:, :, 0] if raster.ndim == 3 else raster)


def _pfm_bytes(array: np.ndarray) -> bytes:
    if array.ndim == 3 and array.shape[2] == 3:
        identifier = b"PF"
    elif array.ndim == 2:
        identifier = b"Pf"
    else:
        raise ValueError(f"write_pfm expects (H, W) or (H, W, 3), got shape {array.shape}")
    height, width = array.shape[:2]
    header = identifier + f"\n{width} {height}\n-1.0\n".encode("ascii")
    raster = np.ascontiguousarray(array[::-1], dtype="<f4")
    return header + raster.tobytes()


def write_pfm(path: str | os.PathLike, disp: np.ndarray) -> Path:
    """Write a little-endian PFM (header scale -1.0) atomically.

    Parameters
    ----------
    path : str or path-like
        Output file.
    disp : ndarray
        ``(H, W)`` (written as ``Pf``) or ``(H, W, 3)`` (``PF``); converted to float32.
        inf, nan and negative values are stored unchanged, so :func:`read_pfm` returns
        the same bits.

    Returns
    -------
    Path
        The written file.
    """
    payload = _pfm_bytes(np.asarray(disp, dtype=np.float32))
    return atomic_write(path, lambda tmp: Path(tmp).write_bytes(payload))


# --------------------------------------------------------------------------- KITTI PNG


def _single_channel(path: Path, image: np.ndarray, what: str) -> np.ndarray:
    """Accept (H, W) or a colour image whose channels are all equal (a grey saved as RGB)."""
    if image.ndim == 2:
        return image
    first = image[:, :, 0]
    if all(np.array_equal(first, image[:, :, c]) for c in range(1, min(image.shape[2], 3))):
        return first
    raise InputError(
        where_what_fix(str(path), f"{what} has {image.shape[2]} different channels", "give a single-channel image")
    )


def read_kitti_png(path: str | os.PathLike) -> np.ndarray:
    """Read a KITTI disparity PNG.

    Parameters
    ----------
    path : str or path-like
        16-bit single-channel PNG, disparity = value / 256, 0 = no ground truth.

    Returns
    -------
    ndarray, float32, (H, W)
        Disparity in pixels, inf where the stored value is 0.
    """
    path = _existing_file(path, "disparity file")
    raw = _single_channel(path, _decode_unchanged(path), "KITTI disparity PNG")
    if raw.dtype != np.uint16:
        raise InputError(
            where_what_fix(
                str(path),
                f"KITTI disparity PNGs are 16-bit but this one is {raw.dtype}",
                "give the uint16 PNG (or read it with read_disparity and its scale)",
            )
        )
    disp = raw.astype(np.float32) / np.float32(256.0)
    disp[raw == 0] = np.inf
    return disp


def encode_kitti(disp: np.ndarray) -> np.ndarray:
    """Disparity (float, inf invalid) -> KITTI uint16: round(d * 256) in [1, 65535], 0 invalid."""
    disp = np.asarray(disp, dtype=np.float64)
    if disp.ndim != 2:
        raise ValueError(f"KITTI disparity maps are (H, W), got shape {disp.shape}")
    valid = np.isfinite(disp) & (disp > 0)
    out = np.zeros(disp.shape, dtype=np.uint16)
    out[valid] = np.clip(np.round(disp[valid] * 256.0), 1, 65535).astype(np.uint16)
    return out


def write_kitti_png(path: str | os.PathLike, disp: np.ndarray) -> Path:
    """Write a disparity map as a KITTI uint16 PNG atomically.

    Parameters
    ----------
    path : str or path-like
        Output ``.png`` file.
    disp : ndarray, float, (H, W)
        Disparity in pixels; inf, nan and values <= 0 are written as 0 (invalid), finite
        values as ``round(d * 256)`` clipped to [1, 65535].

    Returns
    -------
    Path
        The written file.
    """
    encoded = encode_kitti(disp)
    return atomic_write(path, lambda tmp: write_encoded(tmp, encoded))


# --------------------------------------------------------------------------- disparity


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


def _load_npy(path: Path) -> np.ndarray:
    try:
        array = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:  # EOFError: an empty or truncated file
        raise InputError(
            where_what_fix(str(path), f"cannot read .npy file ({exc})", "give a NumPy array saved with np.save")
        ) from None
    if array.ndim == 3 and array.shape[2] == 1:
        array = array[:, :, 0]
    if array.ndim != 2 or not np.issubdtype(array.dtype, np.number):
        raise InputError(
            where_what_fix(
                str(path), f"expected a 2-D numeric disparity array, got {array.dtype} {array.shape}", "save (H, W) floats"
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
        Which stored values mean "no ground truth". ``"auto"`` by format: PFM non-finite;
        PNG/PGM 0; npy non-finite or <= 0. ``"zero"``: 0 (and NaN); ``"inf"``: non-finite;
        ``"none"``: nothing is converted. ``"0"`` is accepted for ``"zero"``.

    Returns
    -------
    ndarray, float32, (H, W)
        Disparity in pixels with inf where invalid.
    """
    path = _existing_file(path, "disparity file")
    mode = _normalise_invalid(path, invalid)
    if not (isinstance(scale, (int, float)) and math.isfinite(scale) and scale > 0):
        raise InputError(where_what_fix(str(path), f"disparity scale must be > 0, got {scale!r}", "fix gt_scale"))
    ext = path.suffix.lower()
    if ext == ".pfm":
        raw = read_pfm(path)
        auto = "inf"
    elif ext == ".npy":
        raw = _load_npy(path)
        auto = "npy"
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
    elif mode == "npy":
        bad |= raw64 <= 0
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
    path = _existing_file(path, "mask file")
    image = _decode_unchanged(path)
    hit = image >= min_value
    return hit.any(axis=2) if hit.ndim == 3 else hit


# --------------------------------------------------------------------------- calibration

_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_MIDDLEBURY_CAM = re.compile(r"^cam0\s*=\s*\[(.*)\]\s*$")
_KEY_VALUE = re.compile(r"^\s*([A-Za-z_][\w.]*)\s*[:=]\s*(.*?)\s*$")
# Left/right projection-matrix pairs, first match wins: KITTI 2012 grey (P0, P1),
# KITTI 2015 calib_cam_to_cam (P_rect_02, P_rect_03), KITTI colour (P2, P3),
# Karlsruhe sequences (P1 = left, P2 = right).
_PROJECTION_PAIRS = (("P0", "P1"), ("P_rect_02", "P_rect_03"), ("P2", "P3"), ("P1", "P2"))
#: Karlsruhe-style files give the projections of the cropped images (``roi:``) too.
_ROI_PAIR = ("P1_roi", "P2_roi")


def _numbers(text: str) -> list[float]:
    return [float(x) for x in re.findall(_NUMBER, text)]


def _calib_from_projections(matrices: dict[str, np.ndarray], pairs=_PROJECTION_PAIRS) -> dict:
    for left_key, right_key in pairs:
        if left_key in matrices and right_key in matrices:
            left, right = matrices[left_key], matrices[right_key]
            f = float(left[0, 0])
            if f <= 0:
                continue
            return {
                "f": f,
                "cx": float(left[0, 2]),
                "cy": float(left[1, 2]),
                # P[0, 3] = -f * (camera x offset), so the baseline is the difference.
                "baseline": float(left[0, 3] - right[0, 3]) / f,
            }
    return {}


def _roi_size(numbers: list[float]) -> tuple[int, int] | None:
    """(width, height) of a Karlsruhe ``roi: x0 x1 y0 y1`` line (inclusive pixel bounds)."""
    if len(numbers) != 4:
        return None
    x0, x1, y0, y1 = numbers
    return int(round(x1 - x0)) + 1, int(round(y1 - y0)) + 1


def read_calib(path: str | os.PathLike, *, image_size: tuple[int, int] | None = None) -> dict:
    """Read a stereo calibration file.

    Understands Middlebury 2014 ``calib.txt`` (``cam0=[f 0 cx; 0 f cy; 0 0 1]``,
    ``baseline=`` in mm, ``doffs=``, ``ndisp=``, ``width=``, ``height=``), KITTI /
    Karlsruhe projection matrices (``P0:`` ... ``P3:``, ``P_rect_02:``; 3x4 row-major)
    and plain ``key: value`` / ``key=value`` lines (as written by :mod:`d3cli.data.synth`;
    there the baseline is in metres).  Unknown lines are ignored.

    Karlsruhe files also give ``roi: x0 x1 y0 y1`` and the projections ``P1_roi``/``P2_roi``
    of the images cropped to it, which is how those images are distributed: their
    principal point is used unless ``image_size`` shows uncropped images.

    Parameters
    ----------
    path : str or path-like
    image_size : (width, height), optional, keyword-only
        Size of the images the calibration is for: picks the projections (full or
        ``roi``) that match it.

    Returns
    -------
    dict
        Whatever of ``f`` (px), ``baseline`` (m), ``cx``, ``cy`` (px), ``doffs`` (px),
        ``ndisp``, ``width``, ``height`` (px), ``height_m`` (m), ``pitch_deg``,
        ``roll_deg``, ``vmin``, ``vmax`` the file defines.
    """
    path = _existing_file(path, "calibration file")
    text = _read_bytes(path).decode("utf-8", errors="replace")
    calib: dict = {}
    matrices: dict[str, np.ndarray] = {}
    middlebury = False
    roi = None
    for line in text.splitlines():
        line = line.strip()
        cam = _MIDDLEBURY_CAM.match(line)
        if cam:
            values = _numbers(cam.group(1))
            if len(values) == 9:
                middlebury = True
                calib.update(f=values[0], cx=values[2], cy=values[5])
            continue
        match = _KEY_VALUE.match(line)
        if not match:
            continue
        key, value = match.group(1), match.group(2)
        numbers = _numbers(value)
        if re.fullmatch(r"P\d|P_rect_\d\d|P\d_roi", key) and len(numbers) == 12:
            matrices[key] = np.array(numbers, dtype=np.float64).reshape(3, 4)
            continue
        if key == "roi":
            roi = _roi_size(numbers)
            continue
        key = _CALIB_ALIASES.get(key.lower(), key.lower())
        if key in CALIB_KEYS and len(numbers) == 1:
            kind = CALIB_KEYS[key]
            calib[key] = int(round(numbers[0])) if kind is int else float(numbers[0])
    if middlebury and "baseline" in calib:
        calib["baseline"] = calib["baseline"] / 1000.0  # Middlebury gives millimetres
    pairs = _PROJECTION_PAIRS
    if all(key in matrices for key in _ROI_PAIR) and (image_size is None or tuple(image_size) == roi):
        pairs = (_ROI_PAIR,)
    for key, value in _calib_from_projections(matrices, pairs).items():
        calib.setdefault(key, value)
    return calib


# --------------------------------------------------------------------------- output


def colorize_disparity(disp: np.ndarray, vmin: float, vmax: float) -> np.ndarray:
    """Colour-code a disparity map over a fixed range (turbo colour map).

    Parameters
    ----------
    disp : ndarray, float, (H, W)
        Disparity in pixels; non-finite = invalid.
    vmin, vmax : float
        Disparities mapped to the two ends of the colour map (values outside clip).

    Returns
    -------
    ndarray, uint8, (H, W, 3)
        RGB image; invalid pixels black.
    """
    if not vmax > vmin:
        raise ValueError(f"colorize_disparity needs vmax > vmin, got vmin={vmin}, vmax={vmax}")
    disp = np.asarray(disp, dtype=np.float32)
    valid = np.isfinite(disp)
    scaled = np.zeros(disp.shape, dtype=np.float32)
    scaled[valid] = (disp[valid] - vmin) / (vmax - vmin)
    levels = np.round(np.clip(scaled, 0.0, 1.0) * 255.0).astype(np.uint8)
    bgr = cv2.applyColorMap(levels, cv2.COLORMAP_TURBO)
    bgr[~valid] = 0
    return np.ascontiguousarray(bgr[:, :, ::-1])


def atomic_write(path: str | os.PathLike, write_fn: Callable[[Path], object]) -> Path:
    """Write a file atomically.

    ``write_fn(tmp)`` writes a temporary file in the same folder whose name keeps the
    extension (``.disp.png.tmp-<pid>.png``, so format-by-extension writers work); it is
    then renamed over ``path`` with :func:`os.replace`.  The temporary file is removed
    when anything fails.

    Parameters
    ----------
    path : str or path-like
        Final file name; its folder must exist.
    write_fn : callable
        Called with the temporary path; must create that file.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    OutputError
        The folder is missing or not writable, or the write failed with an OS error.
    """
    path = Path(path)
    folder = path.parent
    if not folder.is_dir():
        what = "output folder is a file" if folder.exists() else "output folder does not exist"
        raise OutputError(where_what_fix(str(folder), what, "create it or choose another output folder"))
    if not os.access(folder, os.W_OK):
        raise OutputError(
            where_what_fix(str(folder), "output folder is not writable", "fix its permissions or choose another one")
        )
    tmp = folder / f".{path.name}.tmp-{os.getpid()}{path.suffix}"
    try:
        write_fn(tmp)
        if not tmp.is_file():
            raise OutputError(where_what_fix(str(path), "the writer produced no file", "report this as a bug"))
        os.replace(tmp, path)
    except OSError as exc:
        _remove_quietly(tmp)
        raise _write_error(path, exc) from None
    except BaseException:  # KeyboardInterrupt included: no temporary file stays behind
        _remove_quietly(tmp)
        raise
    return path


#: errno values that mean "the disk (or the quota) is full".
DISK_FULL_ERRNOS = frozenset({errno.ENOSPC, getattr(errno, "EDQUOT", errno.ENOSPC)})


def _write_error(path: Path, exc: OSError) -> OutputError:
    """OutputError for a failed write; carries ``errno`` so a batch can stop on a full disk."""
    if exc.errno in DISK_FULL_ERRNOS:
        fix = "free disk space, then rerun the same command (finished pairs are kept and skipped)"
    else:
        fix = "check free space and permissions"
    error = OutputError(where_what_fix(str(path), f"cannot write ({exc.strerror or exc})", fix))
    error.errno = exc.errno
    return error


def is_disk_full(exc: BaseException) -> bool:
    """True when ``exc`` (an OSError or an OutputError from a write) means the disk is full."""
    return getattr(exc, "errno", None) in DISK_FULL_ERRNOS


def _remove_quietly(path: Path) -> None:
    try:
        path.unlink()
    except FileNotFoundError:
        pass
    except OSError as exc:  # the original error matters more than this one
        log.warning("could not remove temporary file %s: %s", path, exc)
