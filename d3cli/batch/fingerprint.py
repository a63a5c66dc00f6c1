"""What a pair's stored outputs depend on, as short hashes: resume decisions, versions.

A rerun skips a pair only when the :func:`pair_fingerprint` stored in its
``result.json`` equals the one of this run; anything else computes it again.  It covers

* the settings (:func:`settings_fingerprint`): the method, every config key the method
  can read, the ``--max-disparity`` override, ``run.color_range`` (disp_color.png) and
  the package versions (d3stereo and the libraries that shape results);
* the pair (:func:`input_identity`): real path, size, modification time (ns) and SHA-256
  of each of its files (left, right, ground truth, non-occlusion mask, calibration, KITTI
  ``obj_map``), so another dataset with the same names, sizes and times, or files
  replaced in place with their times kept (``rsync -a``), is computed again; and the
  dataset values read from SOURCE.txt or a manifest (``gt_scale``,
  ``gt_invalid``, ``max_disparity``, ``bit_depth``).  The resolved disparity range is a
  function of these (the override, the manifest value, or the ground truth and the
  image width), so it is covered without reading the ground truth to skip a pair.

* the feature files of ``cost.kind: features`` (:func:`feature_files`): the ONNX model,
  or the precomputed ``features.npz`` (a relative one per pair, beside its left image),
  by the same identity as the pair's files.

``cloud.ply`` has its own :func:`cloud_fingerprint` (camera section, calibration file),
so a changed ``camera.f`` or calib.txt recomputes the cloud but not the map.

Config keys left out, and why:

* ``run.backend``: CPU and CUDA kernels give the same result (tests/kernels);
* ``run.method`` and ``run.max_disparity``: hashed as resolved (``--method``,
  ``--max-disparity``);
* ``run.max_memory_gb``: only decides whether a pair is refused before it is computed;
* ``camera``: read only for clouds and road outputs (:func:`cloud_fingerprint`);
* ``road``: road outputs are written again on every run with ``--road-report``;
* ``run``, ``camera`` and ``road`` for every method (:data:`d3cli.config.NOT_READ_BY_MAP`),
  and for a method handed only its own section (``sgbm``, ``elas``, ``pandora-sgm``:
  :attr:`d3cli.config.MethodSpec.section`) everything but that section
  (:meth:`d3cli.config.MethodSpec.fingerprinted`).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import os
import stat
from pathlib import Path

from .. import __version__
from ..config import Config, MethodSpec, method_spec
from ..method.features import npz_path

#: Pair fields that are file paths (their identity is hashed, not their spelling).
_FILE_FIELDS = ("left", "right", "gt", "nocc", "calib")


def _digest(key) -> str:
    blob = json.dumps(key, sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def settings_fingerprint(cfg: Config, method: str, max_disparity: int | None) -> str:
    """Short hash of the settings a pair's outputs depend on (the same for every pair).

    Parameters
    ----------
    cfg : Config
        Resolved configuration.
    method : str
        ``--method`` as resolved.
    max_disparity : int or None
        ``--max-disparity`` override (None: each pair's own range).

    Returns
    -------
    str
        16 hex digits.  See the module docstring for the keys left out.
    """
    sections = cfg.to_dict()
    spec = method_spec(method) or MethodSpec(method, "", "")  # an unknown name: as the whole config
    covered = spec.fingerprinted(sections)
    sections = {name: sections[name] for name in covered}
    key = [method, sections, max_disparity, package_versions()]
    if cfg.run.color_range:  # a run setting that changes an output (disp_color.png)
        key.append(list(cfg.run.color_range))
    return _digest(key)


def file_identity(path) -> list | None:
    """``[real path, size in bytes, modification time in ns, SHA-256]`` of ``path``; None
    without one.

    The real path (links and ``..`` resolved) lets an absolute, a relative and a linked
    spelling of one file agree.  The SHA-256 costs about 1.5 ms for a 2 MB 1280x720 PNG
    (reading it as an image: about 40 ms), once per file and process
    (:func:`_content_digest`).  Only a regular file is read (a FIFO would block); another
    file, or one that cannot be read, has a None hash and, if it cannot be found, size and
    time: the pair then fails when it is loaded, and a fingerprint is still defined.
    """
    if path is None:
        return None
    real = os.path.realpath(path)
    try:
        st = os.stat(real)
    except OSError:
        return [real, None, None, None]
    digest = None
    if stat.S_ISREG(st.st_mode):
        digest = _content_digest(real, st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)
    return [real, st.st_size, st.st_mtime_ns, digest]


@functools.lru_cache(maxsize=512)
def _content_digest(path: str, *stat_key) -> str | None:
    """SHA-256 of the file ``path``, None when it cannot be read.  Cached by its stat
    (device, inode, size and times; ``ctime`` changes with every write, even when the
    modification time is set back), so a file every pair reads (an ONNX model) is hashed
    once."""
    try:
        with open(path, "rb") as fh:
            return hashlib.file_digest(fh, "sha256").hexdigest()
    except OSError:
        return None


def object_map_path(gt) -> Path | None:
    """KITTI 2015 ``obj_map.png`` of a ground truth (beside it, or ``../obj_map/<name>``), or None."""
    if gt is None:
        return None
    gt = Path(gt)
    for candidate in (gt.parent / "obj_map.png", gt.parent.parent / "obj_map" / gt.name):
        if candidate.is_file():
            return candidate
    return None


def input_identity(pair) -> dict:
    """Everything of a pair (a :class:`d3cli.data.layouts.Pair`) its outputs depend on.

    File fields become :func:`file_identity` (so an absolute, a relative and a linked
    spelling of the same file agree); other fields (``gt_scale``, ``gt_invalid``,
    ``max_disparity``, ``bit_depth``, ...) are taken as they are.
    """
    out = {}
    for f in dataclasses.fields(pair):
        value = getattr(pair, f.name)
        out[f.name] = file_identity(value) if f.name in _FILE_FIELDS else value
    out["obj_map"] = file_identity(object_map_path(pair.gt))
    return out


def feature_files(cfg: Config, method: str, pair) -> list:
    """The feature files d3stereo reads for ``pair`` (``cost.kind: features``), as paths.

    ``features.npz`` wins over ``features.model`` (as in the pipeline); a relative npz is
    the pair's own, in the folder of its left image.  Empty for NCC and for a method not
    handed the pair's folder (:attr:`d3cli.config.MethodSpec.pair_dir`).
    """
    spec = method_spec(method)
    if spec is None or not spec.pair_dir or cfg.cost.kind != "features":
        return []
    if cfg.features.npz:
        return [Path(npz_path(cfg.features.npz, Path(pair.left).parent))]
    return [Path(cfg.features.model)] if cfg.features.model else []


def pair_fingerprint(settings: str, pair, features: list | None = None) -> str:
    """Short hash of :func:`settings_fingerprint` ``settings``, the pair's
    :func:`input_identity` and the identity of its :func:`feature_files` ``features``."""
    key = [settings, input_identity(pair)]
    if features:  # only then: NCC fingerprints stay what they were
        key.append([file_identity(path) for path in features])
    return _digest(key)


def cloud_fingerprint(cfg: Config, pair) -> str:
    """Short hash of what ``cloud.ply`` depends on besides the map: camera section, calibration."""
    return _digest([cfg.to_dict()["camera"], file_identity(pair.calib), __version__])


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
