"""PFM disparity files (float32, rows stored bottom-up, ``inf`` = invalid): read and
atomic write.
"""

from __future__ import annotations

import math
import os
import re
from pathlib import Path

import numpy as np

from ...errors import InputError, where_what_fix
from .atomic import atomic_write
from .images import MAX_IMAGE_PIXELS, _read_bytes, regular_file


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


#: Bytes of a PFM file that hold its header (identifier, size and scale lines).
_HEADER_BYTES = 256


def _check_claimed_size(path: Path) -> None:
    """Refuse a header that claims more than :data:`MAX_IMAGE_PIXELS` pixels, from the
    header alone: the file is not read (nor its raster allocated) before this."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(_HEADER_BYTES)
    except OSError as exc:
        raise InputError(where_what_fix(str(path), f"cannot read file ({exc.strerror})", "check its permissions")) from None
    _, width, height, _, _ = _parse_pfm_header(path, head)
    if width * height > MAX_IMAGE_PIXELS:
        raise InputError(where_what_fix(str(path), f"PFM header claims {width}x{height} pixels, more than "
                                                   f"{MAX_IMAGE_PIXELS}", "give a disparity map of the images' size"))


def read_pfm_raw(path: str | os.PathLike) -> np.ndarray:
    """Read every channel of a PFM file, top row first.

    Returns
    -------
    ndarray, float32
        ``(H, W)`` for ``Pf`` files, ``(H, W, 3)`` for ``PF`` files; values bit-exact.
    """
    path = regular_file(path, "PFM file")
    _check_claimed_size(path)
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
