"""Step 2 with deep features: feature maps of a pre-trained backbone as the cost pyramid.

The paper's cost pyramid (section III-A) is the cosine similarity of deep feature maps:
``C(p, d) = (1 - cos(f_L(u, v), f_R(u - d, v))) / 2`` on L2-normalised feature vectors.
An ONNX model (``features.model``, run with onnxruntime: extra ``features``) maps an image
to several feature maps (``features.outputs``, finest first).  A map whose stride is
``2^i`` (image height / map height) is the cost of pyramid level ``i``; it is cropped or
zero-padded to that level's grid (the pyramid drops an odd last row/column per level).
Levels without a map (e.g. full resolution for VGG, whose first tap has stride 2) keep the
NCC cost, so the disparity is completed at full resolution with NCC.

Feature maps come from one forward pass per image (the model computes all taps at once);
each level's maps are normalised into the (H, W, C) float32 layout the kernels read.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from ..config import FeaturesConfig
from ..errors import ConfigError, InputError

#: onnxruntime sessions by (model path, modification time): one load per process.
_SESSIONS: dict = {}


@dataclass
class LevelFeatures:
    """The normalised feature maps of one pyramid level, in the kernels' layout.

    Attributes
    ----------
    left, right : ndarray, float32, (H, W, C)
        L2-normalised feature vectors (zero vectors stay zero).
    left_norm, right_norm : ndarray, float32, (H, W)
        Squared norms after normalisation: 1, or 0 for a zero vector.
    """

    left: np.ndarray
    right: np.ndarray
    left_norm: np.ndarray
    right_norm: np.ndarray


def _session(path: str):
    try:
        import onnxruntime
    except ImportError:
        raise ConfigError("cost.kind: features needs onnxruntime; install it with "
                          'pip install -e ".[features]" (or pip install onnxruntime)') from None
    try:
        key = (os.path.abspath(path), os.stat(path).st_mtime_ns)
    except OSError:
        raise ConfigError(f"{path}: features.model not found; give the path of an ONNX file") from None
    if key not in _SESSIONS:
        try:
            _SESSIONS[key] = onnxruntime.InferenceSession(path, providers=["CPUExecutionProvider"])
        except Exception as exc:  # noqa: BLE001 - onnxruntime raises its own exception types
            raise ConfigError(f"{path}: cannot load the ONNX model ({str(exc).splitlines()[0][:160]}); "
                              "give a valid ONNX file (scripts/export_backbone.py writes one)") from None
    return _SESSIONS[key]


def _model_input(image: np.ndarray, cfg: FeaturesConfig, channels: int) -> np.ndarray:
    """(1, C, H, W) float32 network input from an image on the 0-255 scale."""
    img = np.asarray(image, dtype=np.float32)
    if img.ndim == 2:
        img = img[:, :, None]
    if img.shape[2] == 4:
        img = img[:, :, :3]
    if channels == 3 and img.shape[2] == 1:
        img = np.repeat(img, 3, axis=2)
    elif channels == 1 and img.shape[2] == 3:
        img = (img @ np.array([0.299, 0.587, 0.114], np.float32))[:, :, None]
    if channels == 3 and cfg.channel_order == "bgr":
        img = img[:, :, ::-1]
    mean = np.asarray(cfg.mean, np.float32)
    std = np.asarray(cfg.std, np.float32)
    if img.shape[2] == 1:
        mean, std = mean[:1], std[:1]
    img = (img * np.float32(cfg.scale) - mean) / std
    return np.ascontiguousarray(img.transpose(2, 0, 1)[None], dtype=np.float32)


def run_model(image: np.ndarray, cfg: FeaturesConfig) -> list[np.ndarray]:
    """The feature maps ``features.outputs`` of ``image``, each (C, h, w) float32.

    Raises
    ------
    ConfigError
        No model or outputs configured, an output name the model does not have, an
        output that is not (1, C, h, w), or a map with NaN/inf values.
    """
    if not cfg.model:
        raise ConfigError("cost.kind: features needs features.model (an ONNX file); set it or use cost.kind: ncc")
    session = _session(cfg.model)  # first: a missing model is the mistake to name, not its outputs
    if not cfg.outputs:
        raise ConfigError(f"{cfg.model}: features.outputs is empty; list the model's feature outputs, finest first")
    names = [o.name for o in session.get_outputs()]
    missing = [name for name in cfg.outputs if name not in names]
    if missing:
        raise ConfigError(f"{cfg.model}: the model has no output {missing[0]!r}; its outputs are "
                          f"{', '.join(names[:12])}; fix features.outputs")
    spec = session.get_inputs()[0]
    channels = spec.shape[1] if len(spec.shape) == 4 and isinstance(spec.shape[1], int) else 3
    maps = session.run(list(cfg.outputs), {spec.name: _model_input(image, cfg, channels)})
    out = []
    for name, fmap in zip(cfg.outputs, maps):
        fmap = np.asarray(fmap)
        if fmap.ndim != 4 or fmap.shape[0] != 1:
            raise ConfigError(f"{cfg.model}: output {name!r} has shape {fmap.shape}, expected (1, C, h, w); "
                              "list feature-map outputs in features.outputs")
        if not np.isfinite(fmap).all():
            raise ConfigError(f"{cfg.model}: output {name!r} has NaN or inf values; check the model and "
                              "the features input scaling (scale, mean, std)")
        out.append(fmap[0].astype(np.float32, copy=False))
    return out


def level_of(map_shape: tuple[int, int], image_shape: tuple[int, int], *, name: str = "", model: str = "") -> int:
    """Pyramid level of a feature map: ``log2`` of its stride, which must be a power of two."""
    stride = image_shape[0] / max(map_shape[0], 1)
    level = int(round(math.log2(stride))) if stride > 0 else -1
    # the map may be one row/column larger or smaller than the exact 1/2^level grid
    if level < 0 or abs(map_shape[0] - image_shape[0] / 2**level) > 1 or \
            abs(map_shape[1] - image_shape[1] / 2**level) > 1:
        raise ConfigError(f"{model}: output {name!r} of {map_shape[0]}x{map_shape[1]} for an image of "
                          f"{image_shape[0]}x{image_shape[1]} is not at a power-of-two stride; "
                          "list only feature maps at strides 1, 2, 4, ... in features.outputs")
    return level


def _fit(fmap: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """(C, h, w) -> (H, W, C) on the level's grid: cropped, or zero-padded at the end."""
    c, h, w = fmap.shape
    out = np.zeros((shape[0], shape[1], c), np.float32)
    hh, ww = min(h, shape[0]), min(w, shape[1])
    out[:hh, :ww] = fmap[:, :hh, :ww].transpose(1, 2, 0)
    return out


def normalise(features: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """L2-normalise (H, W, C) feature vectors; return them and their squared norms (1 or 0)."""
    norm = np.sqrt(np.einsum("hwc,hwc->hw", features, features, dtype=np.float64))
    ok = norm > 1e-12
    scaled = np.where(ok[:, :, None], features / np.where(ok, norm, 1.0)[:, :, None], 0.0)
    return np.ascontiguousarray(scaled, dtype=np.float32), ok.astype(np.float32)


def feature_pyramid(left: np.ndarray, right: np.ndarray, level_shapes: list[tuple[int, int]],
                    cfg: FeaturesConfig) -> list[LevelFeatures | None]:
    """Per pyramid level (finest first) the normalised feature maps, or None (NCC level).

    Parameters
    ----------
    left, right : ndarray
        Images of the pair on the 0-255 scale, (H, W) grey or (H, W, 3) RGB.
    level_shapes : list of (H_i, W_i)
        The grid of every pyramid level, finest first.
    cfg : FeaturesConfig

    Raises
    ------
    ConfigError
        As :func:`run_model`; two outputs at the same stride.
    InputError
        The two views give feature maps of different shapes.
    """
    image_shape = np.asarray(left).shape[:2]
    maps_l, maps_r = run_model(left, cfg), run_model(right, cfg)
    levels: list[LevelFeatures | None] = [None] * len(level_shapes)
    seen = {}
    for name, fl, fr in zip(cfg.outputs, maps_l, maps_r):
        if fl.shape != fr.shape:
            raise InputError(f"pair: the model gives {name!r} of {fl.shape} for the left and {fr.shape} for the "
                             "right image; a stereo pair needs equal sizes")
        level = level_of(fl.shape[1:], image_shape, name=name, model=cfg.model)
        if level in seen:
            raise ConfigError(f"{cfg.model}: outputs {seen[level]!r} and {name!r} have the same stride "
                              f"{2 ** level}; list one feature map per stride in features.outputs")
        seen[level] = name
        if level >= len(level_shapes):
            continue  # coarser than the pyramid: not used
        left_f, left_n = normalise(_fit(fl, level_shapes[level]))
        right_f, right_n = normalise(_fit(fr, level_shapes[level]))
        levels[level] = LevelFeatures(left_f, right_f, left_n, right_n)
    return levels


def feature_bytes(shape: tuple[int, int], channels_per_level: list[int]) -> int:
    """Bytes of the normalised feature maps of both views over all levels (memory check)."""
    h, w = int(shape[0]), int(shape[1])
    return int(sum(2 * (h >> i) * (w >> i) * (c + 1) * 4 for i, c in enumerate(channels_per_level)))


#: Keys of a precomputed feature file (``features.npz``): ``left_<i>`` and ``right_<i>``
#: for pyramid level i (stride 2^i, 0 = full resolution), each (h, w, C).
NPZ_KEY = "{view}_{level}"


def npz_path(npz: str, pair_dir=None) -> str:
    """Where ``features.npz`` is for a pair: a relative path is the pair's own, in
    ``pair_dir`` (the folder of its left image); without one, as given."""
    if pair_dir is not None and not os.path.isabs(npz):
        return os.path.join(os.fspath(pair_dir), npz)
    return npz


def _npz_error(path, what: str) -> InputError:
    return InputError(f"{path}: {what}; write per-level arrays left_0, right_0, left_1, ... of shape "
                      "(H / 2^i, W / 2^i, C), finite, equal for both views (README 'Deep-feature cost pyramids')")


def load_feature_npz(path, image_shape: tuple[int, int], level_shapes: list[tuple[int, int]]
                     ) -> list[LevelFeatures | None]:
    """Per pyramid level (finest first) the normalised features of a precomputed ``.npz``.

    The file holds ``left_<i>`` and ``right_<i>`` (:data:`NPZ_KEY`) for the levels it
    covers: float arrays of shape (h, w, C) with h, w within one pixel of H / 2^i and
    W / 2^i (a backbone's map at stride 2^i), cropped or zero-padded to the level's grid
    like a model's output.  Levels without keys keep the NCC cost; keys of levels beyond
    the pyramid are ignored.

    Parameters
    ----------
    path : path-like
        The ``.npz`` file (``numpy.savez``).
    image_shape : (H, W)
        Full-resolution image size, pixels.
    level_shapes : list of (H_i, W_i)
        The grid of every pyramid level, finest first.

    Raises
    ------
    InputError
        The file is missing or unreadable, has no ``left_<i>``/``right_<i>`` pair, a key
        without its partner view, an array that is not (h, w, C), not at the level's
        stride, of different shapes for the two views, or with NaN/inf values.
    """
    try:
        archive = np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise InputError(f"{path}: features.npz not found; give the path of an .npz file of feature maps") from None
    except Exception as exc:  # noqa: BLE001 - numpy raises several types for a bad archive
        raise _npz_error(path, f"cannot be read as .npz ({str(exc).splitlines()[0][:120]})") from None
    with archive:
        names = set(archive.files)
        found = sorted({int(n.split("_", 1)[1]) for n in names
                        if n.split("_", 1)[0] in ("left", "right") and n.split("_", 1)[-1].isdigit()})
        if not found:
            raise _npz_error(path, f"no left_<i>/right_<i> arrays (keys: {', '.join(sorted(names)[:8]) or 'none'})")
        levels: list[LevelFeatures | None] = [None] * len(level_shapes)
        for level in found:
            keys = [NPZ_KEY.format(view=view, level=level) for view in ("left", "right")]
            missing = [k for k in keys if k not in names]
            if missing:
                raise _npz_error(path, f"{keys[0] if missing[0] == keys[1] else keys[1]} has no partner {missing[0]}")
            if level >= len(level_shapes):
                continue
            maps = [archive[k] for k in keys]
            for key, fmap in zip(keys, maps):
                if fmap.ndim != 3 or fmap.dtype.kind not in "fiu":
                    raise _npz_error(path, f"{key} has shape {fmap.shape} ({fmap.dtype}), expected numbers (h, w, C)")
                if not np.isfinite(fmap).all():
                    raise _npz_error(path, f"{key} has NaN or inf values")
                expect = (image_shape[0] / 2**level, image_shape[1] / 2**level)
                if abs(fmap.shape[0] - expect[0]) > 1 or abs(fmap.shape[1] - expect[1]) > 1:
                    raise _npz_error(path, f"{key} is {fmap.shape[0]}x{fmap.shape[1]} but level {level} of an "
                                           f"image of {image_shape[0]}x{image_shape[1]} is {expect[0]:g}x{expect[1]:g}")
            if maps[0].shape != maps[1].shape:
                raise _npz_error(path, f"{keys[0]} is {maps[0].shape} but {keys[1]} is {maps[1].shape}")
            fitted = [normalise(_fit(np.asarray(m, np.float32).transpose(2, 0, 1), level_shapes[level])) for m in maps]
            levels[level] = LevelFeatures(fitted[0][0], fitted[1][0], fitted[0][1], fitted[1][1])
    return levels


#: Channels assumed per level when a model's outputs do not state them (VGG16's widest
#: tap has 512): an upper bound for the memory check.
DEFAULT_CHANNELS = 512


def _npz_level_shapes(path) -> dict[int, tuple[int, ...]]:
    """``{level: (h, w, C)}`` of the ``left_<i>`` arrays, read from the headers only."""
    import zipfile

    shapes = {}
    with zipfile.ZipFile(path) as archive:
        for name in archive.namelist():
            key = name[:-4] if name.endswith(".npy") else name
            view, _, level = key.partition("_")
            if view != "left" or not level.isdigit():
                continue
            with archive.open(name) as f:
                version = np.lib.format.read_magic(f)
                read_header = {(1, 0): np.lib.format.read_array_header_1_0,
                               (2, 0): np.lib.format.read_array_header_2_0}[version]
                shape = read_header(f)[0]
            shapes[int(level)] = tuple(int(s) for s in shape)
    return shapes


def feature_channels(cfg: FeaturesConfig, levels: int) -> list[int]:
    """Feature channels per pyramid level (finest first) for the memory check.

    From the ``left_<i>`` headers of ``features.npz`` (levels it lacks: 0, they use NCC),
    else from the model's output shapes, taking output k as level k (a backbone whose
    first tap has stride 2 is over-counted: an upper bound).  A channel count the model
    leaves symbolic, an npz path that cannot be read here (a path relative to each pair's
    folder) or a model that cannot be loaded count as :data:`DEFAULT_CHANNELS` per level.
    """
    if cfg.npz:
        try:
            shapes = _npz_level_shapes(cfg.npz)
        except Exception:  # noqa: BLE001 - any unreadable file: the upper bound
            return [DEFAULT_CHANNELS] * levels
        return [shapes[i][2] if i in shapes and len(shapes[i]) == 3 else 0 for i in range(levels)]
    channels = [DEFAULT_CHANNELS] * min(levels, len(cfg.outputs))
    if cfg.model:
        try:
            outputs = {o.name: o.shape for o in _session(cfg.model).get_outputs()}
        except ConfigError:
            outputs = {}
        for k, name in enumerate(cfg.outputs[:levels]):
            shape = outputs.get(name)
            if shape is not None and len(shape) == 4 and isinstance(shape[1], int) and shape[1] > 0:
                channels[k] = shape[1]
    return channels + [0] * (levels - len(channels))
