"""Images: read (RGB, 8/16-bit, size and bit-depth checks from the header), grey
conversion, and the atomic image writer.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import os
import re
import stat
import sys
import tempfile
import threading
from pathlib import Path

import cv2
import numpy as np

from ...errors import InputError, OutputError, where_what_fix
from .atomic import atomic_write


log = logging.getLogger(__name__)

# OpenCV prints its own "[ WARN:0@...] PNG input buffer is incomplete" and "[ERROR:0@...]
# readHeader IHDR chunk shall be first" lines to stderr for files that this module then
# reports as one Error naming the file: nothing of OpenCV's logging reaches the user.
cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)

#: Lines the image libraries write straight to file descriptor 2 (libpng's "libpng
#: error: IDAT: invalid code lengths set", libjpeg's "Corrupt JPEG data", libtiff's,
#: OpenCV's log): logged at DEBUG; any other line written meanwhile is passed on.
_DECODER_LINE = re.compile(r"^(libpng |\[ ?(ERROR|WARN|INFO|DEBUG)|TIFF|JPEG|Corrupt JPEG|Premature end of JPEG)")
#: Most bytes of decoder messages kept per image.
_DECODER_TEXT_BYTES = 64_000


#: Largest image decoded (pixels): 16384^2, ~1.6 GB as 16-bit RGB.
MAX_IMAGE_PIXELS = 16384 * 16384


IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".ppm", ".pgm", ".pnm", ".tif", ".tiff", ".bmp")


# ITU-R BT.601 luma weights, the ones OpenCV and most stereo code use.
_LUMA_RGB = np.array([0.299, 0.587, 0.114], dtype=np.float32)


#: What a non-regular file is, by the type bits of its mode.
_SPECIAL_KINDS = ((stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"),
                  (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def special_file_kind(path: str | os.PathLike) -> str | None:
    """What ``path`` is when it exists but is neither a regular file nor a folder, else None.

    A FIFO would block the reader forever and ``/dev/zero`` never ends, so inputs are
    typed by ``stat`` before they are opened; the text names the link too
    (``"a link to /dev/zero, a character device"``).
    """
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return None
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return None
    kind = next((text for test, text in _SPECIAL_KINDS if test(mode)), "a special file")
    if os.path.islink(path):
        return f"a link to {os.readlink(path)}, {kind}"
    return kind


#: Most characters of a path an error message shows (its start and end): a path longer
#: than the system allows is thousands of characters, and the line must stay readable.
SHOWN_PATH_CHARS = 120


def shown_path(path: str | os.PathLike) -> str:
    """``path`` for a message: whole up to :data:`SHOWN_PATH_CHARS` characters, else its
    first 60 and last 57 around ``...``."""
    text = os.fspath(path)
    text = text if isinstance(text, str) else os.fsdecode(text)
    if len(text) <= SHOWN_PATH_CHARS:
        return text
    return f"{text[:60]}...{text[-(SHOWN_PATH_CHARS - 63):]}"


def _system_limit(name: str, default: int) -> int:
    try:
        return int(os.pathconf("/", name))
    except (OSError, ValueError):
        return default


def unreadable(given: str | os.PathLike, exc: OSError) -> InputError:
    """The error for a path the system refuses to examine (``os.stat`` failing with
    something other than "not found"): a path longer than PATH_MAX (a working folder
    nested that deep), a name longer than NAME_MAX, no permission, an I/O error.

    ``given`` is the path as the user gave it (relative or not), named when the failure
    is its own; a file under it that fails is named instead.
    """
    given_text = os.fspath(given)
    failed = os.fspath(exc.filename) if exc.filename is not None else given_text
    own = os.path.abspath(failed) == os.path.abspath(given_text)
    where = shown_path(given_text if own else failed)
    if exc.errno == errno.ENAMETOOLONG:
        name_max = _system_limit("PC_NAME_MAX", 255)
        if any(len(os.fsencode(part)) > name_max for part in Path(failed).parts):
            return InputError(where_what_fix(where, f"a name in this path is longer than the system allows "
                                                    f"({name_max} bytes)", "give a shorter name"))
        path_max = _system_limit("PC_PATH_MAX", 4096)
        absolute = os.path.abspath(failed)
        fix = ("move the data to a shorter path" if os.path.isabs(given_text)
               else "run d3stereo from a shallower folder, or move the data to a shorter path")
        return InputError(where_what_fix(where, f"its absolute path is {len(os.fsencode(absolute))} bytes long, "
                                                f"more than the system allows ({path_max})", fix))
    fix = "check its permissions" if exc.errno in (errno.EACCES, errno.EPERM) else "check the path and the disk"
    return InputError(where_what_fix(where, f"cannot read it ({exc.strerror or exc})", fix))


def regular_file(path: str | os.PathLike, what: str = "file") -> Path:
    """``path`` as a Path when it is an existing regular file (or a link to one); special
    files (a FIFO, a device) are named as such and never opened.

    Raises
    ------
    InputError
        ``<path>: <what> not found``, ``is a folder, not a file`` or ``not a regular file
        (a FIFO)`` (a device, a socket, a link to one), or a path the system refuses to
        examine (:func:`unreadable`), each with the fix.
    """
    path = Path(path)
    try:
        exists, folder = path.exists(), path.is_dir()
    except OSError as exc:  # a name or path longer than the system allows, no permission
        raise unreadable(path, exc) from None
    if not exists:
        raise InputError(where_what_fix(str(path), f"{what} not found", "check the path"))
    if folder:
        raise InputError(where_what_fix(str(path), "is a folder, not a file", "give the file itself"))
    kind = special_file_kind(path)
    if kind is not None:
        raise InputError(where_what_fix(str(path), f"not a regular file ({kind})", "give the file itself"))
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

    if special_file_kind(path) is not None:
        return None  # never opened (a FIFO would block); the reader names it
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


#: OpenCV's own decoder limits: (environment variable, default, what an image exceeds).
_OPENCV_LIMITS = (("OPENCV_IO_MAX_IMAGE_WIDTH", 1 << 20, "is wider than"),
                  ("OPENCV_IO_MAX_IMAGE_HEIGHT", 1 << 20, "is taller than"),
                  ("OPENCV_IO_MAX_IMAGE_PIXELS", 1 << 30, "has more pixels than"))


def _opencv_limit(name: str, default: int) -> tuple[int, bool]:
    """(limit, set by the user) of one of OpenCV's variables; a value that is no integer
    counts as unset (OpenCV's default)."""
    text = os.environ.get(name)
    if text is None:
        return default, False
    try:
        return int(text), True
    except ValueError:
        return default, False


def _opencv_refusal(path: Path, width: int, height: int) -> InputError | None:
    """The error for an image OpenCV's decoders would refuse by its size, or None.

    OpenCV refuses a side longer than 2**20 pixels, or more than 2**30 pixels, unless
    ``OPENCV_IO_MAX_IMAGE_WIDTH`` / ``HEIGHT`` / ``PIXELS`` say otherwise; a limit set in
    the environment is named with its value, so that a pair failing on it is not blamed
    on the image.
    """
    for (name, default, verb), size in zip(_OPENCV_LIMITS, (width, height, width * height)):
        limit, from_env = _opencv_limit(name, default)
        if size <= limit:
            continue
        if from_env:
            return InputError(where_what_fix(
                str(path), f"image of {width}x{height} pixels {verb} {name}={limit} (set in the environment) "
                           "lets OpenCV decode", f"raise or unset {name}"))
        if name != "OPENCV_IO_MAX_IMAGE_PIXELS":  # the default pixel limit is above MAX_IMAGE_PIXELS
            return InputError(where_what_fix(
                str(path), f"image of {width}x{height} pixels has a side longer than {limit} pixels, "
                           "the most OpenCV decodes",
                "crop or downscale it (a stereo pair this wide is likely a mistake)"))
    return None


def _opencv_variables_set() -> list[str]:
    """``NAME=value`` of OpenCV's size variables set in the environment."""
    return [f"{name}={os.environ[name]}" for name, _, _ in _OPENCV_LIMITS if name in os.environ]


#: One decode at a time swaps file descriptor 2 (:func:`_decoder_messages_logged`): two
#: overlapping swaps (a pipelined batch's reader and writer threads) restored it crosswise
#: and left the process's stderr in a deleted temporary file.
_STDERR_SWAP = threading.Lock()


@contextlib.contextmanager
def _decoder_messages_logged(path: Path):
    """Catch what C libraries write to file descriptor 2 while decoding ``path``.

    libpng reports a corrupt file with its own stderr line before OpenCV returns None,
    and this module then raises one Error naming the file: the library's line is logged
    at DEBUG (``-v`` shows it) instead of reaching the terminal.  Lines that are not a
    decoder's (another thread's output) are written to stderr afterwards.  Threads take
    turns (:data:`_STDERR_SWAP`).
    """
    with _STDERR_SWAP, _stderr_to_sink(path):
        yield


@contextlib.contextmanager
def _stderr_to_sink(path: Path):
    """:func:`_decoder_messages_logged` without the lock."""
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError, AttributeError):  # no descriptor 2: nothing to guard
        yield
        return
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            text = sink.read(_DECODER_TEXT_BYTES).decode("utf-8", errors="replace")
            for line in text.splitlines():
                if _DECODER_LINE.match(line):
                    log.debug("%s: decoder: %s", path, line.strip())
                elif line.strip():
                    os.write(2, (line + "\n").encode("utf-8", errors="replace"))


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
    # OpenCV would refuse it with its own assertion text (or libpng lines on stderr) and
    # no file name.
    refusal = _opencv_refusal(path, *size) if size is not None else None
    if refusal is not None:
        raise refusal
    data = np.frombuffer(_read_bytes(path), dtype=np.uint8)
    try:
        with _decoder_messages_logged(path):
            image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    except cv2.error as exc:  # e.g. a header beyond OpenCV's own size limit
        # "OpenCV(4.9.0) /path/loadsave.cpp:77: error: (-215:Assertion failed) ... in function
        # '...'": the part after "error:" says what is wrong.
        reason = " ".join(str(exc).split()).rpartition(" error: ")[2][:160]
        fix = "give an 8/16-bit PNG, JPEG, PPM/PGM or TIFF of a sensible size"
        variables = _opencv_variables_set()
        if "CV_IO_MAX_IMAGE" in reason and variables:  # a size limit the user set
            fix = f"raise or unset {', '.join(variables)} (set in the environment)"
        raise InputError(where_what_fix(str(path), f"cannot decode image (OpenCV: {reason})", fix)) from None
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
        The file is missing, unreadable, corrupt, not 8/16-bit, or a float image with
        non-finite or negative samples.
    """
    path = regular_file(path, "image file")
    image = _decode_unchanged(path)
    if image.dtype.kind == "f":
        image = image.astype(np.float32, copy=False)
        if not np.isfinite(image).all():
            raise InputError(where_what_fix(str(path), "float image with NaN or inf samples",
                                            "give finite intensities (or an 8/16-bit image)"))
        low = float(image.min(initial=0.0))
        if low < 0:  # named here, by the file: the pair's check cannot tell which view it is
            raise InputError(where_what_fix(str(path), f"negative intensities (down to {low:g}) in a float image",
                                            "give intensities >= 0 (0-1, 0-255 or integer counts)"))
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
