"""What a pair's result depends on: the settings fingerprint and the package versions.

A pair whose stored ``result.json`` carries another fingerprint is computed again.
"""

from __future__ import annotations

import hashlib
import json

from .. import __version__
from ..config import Config

#: Config sections that shape each baseline's result; d3stereo uses all but run and sgbm.
_BASELINE_SECTIONS = {"sgbm": ("sgbm",), "pt-sgm": ("sgbm", "pt"), "elas": ("peers",), "pandora-sgm": ("peers",)}


def settings_fingerprint(cfg: Config, method: str, max_disparity: int | None) -> str:
    """Short hash of what determines a pair's result: method, its config sections, range.

    The backend is left out on purpose: CPU and CUDA give the same result.
    """
    sections = cfg.to_dict()
    del sections["run"]  # method and max_disparity are hashed as resolved; backend does not matter
    if method in _BASELINE_SECTIONS:
        sections = {name: sections[name] for name in _BASELINE_SECTIONS[method]}
    else:
        del sections["sgbm"], sections["peers"]  # d3stereo reads neither
    key = [method, sections, max_disparity]
    if cfg.run.color_range:  # a run setting that changes an output (disp_color.png)
        key.append(list(cfg.run.color_range))
    blob = json.dumps(key, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def package_versions() -> dict:
    """Versions of d3stereo and the libraries that shape its results."""
    import cv2
    import numba
    import numpy
    import skimage

    return {
        "d3stereo": __version__,
        "numpy": numpy.__version__,
        "numba": numba.__version__,
        "cv2": cv2.__version__,
        "skimage": skimage.__version__,
    }
