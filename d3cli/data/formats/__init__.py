"""File formats: images, disparity maps (PFM, KITTI PNG, scaled images, ``.npy``), masks,
calibration files, colour pictures, and the atomic writer every output goes through.

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
  ``.npy``        float                                   non-finite (as PFM)
  ==============  ======================================  =================

Every writer is atomic (a temporary file in the same folder, then ``os.replace``), so an
interrupted run never leaves a half-written output behind.  User mistakes raise
:class:`~d3cli.errors.InputError` / :class:`~d3cli.errors.OutputError` with the message
form ``<where>: <what>; <fix>``.

Modules: ``images``, ``pfm``, ``kitti_png``, ``disparity``, ``calib``, ``colour``,
``atomic``; this package re-exports their public functions.

May import: :mod:`d3cli.errors` only (no config, no layouts, no synth).
"""

from __future__ import annotations

from .atomic import DISK_FULL_ERRNOS, atomic_write, is_disk_full
from .images import (IMAGE_EXTENSIONS, MAX_IMAGE_PIXELS, image_size, read_image, regular_file, shown_path,
                     special_file_kind, to_grey, unreadable, write_encoded, write_image)
from .pfm import read_pfm, read_pfm_raw, write_pfm
from .kitti_png import encode_kitti, read_kitti_png, write_kitti_png
from .disparity import DISPARITY_EXTENSIONS, INVALID_CONVENTIONS, read_disparity, read_mask
from .calib import CALIB_KEYS, read_calib
from .colour import colorize_disparity

__all__ = [
    "CALIB_KEYS",
    "DISK_FULL_ERRNOS",
    "DISPARITY_EXTENSIONS",
    "IMAGE_EXTENSIONS",
    "INVALID_CONVENTIONS",
    "MAX_IMAGE_PIXELS",
    "atomic_write",
    "colorize_disparity",
    "encode_kitti",
    "image_size",
    "is_disk_full",
    "read_calib",
    "read_disparity",
    "read_image",
    "read_kitti_png",
    "read_mask",
    "read_pfm",
    "read_pfm_raw",
    "regular_file",
    "shown_path",
    "special_file_kind",
    "to_grey",
    "unreadable",
    "write_encoded",
    "write_image",
    "write_kitti_png",
    "write_pfm",
]
