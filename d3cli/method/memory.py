"""The memory model of a d3stereo pair: its estimated peak, before anything big is allocated.

The estimate models the pipeline's peak (cost, aggregation, seeds and diffusion;
docs/design.md, 'Cost volumes'), which is reached at the finest level (level 1):

* cost volumes: float32 ``(H, W, D + 1)``, the worst case of the band search (a band
  can be the full range); RBF filters the NCC volume in place (1 volume), the plain
  bilateral filter also needs its output volume (2);
* the RBF weights: float32 ``(H, W, 9)``;
* with ``cost.kind: features``: the feature maps of both views at every level, float32
  ``(H / 2^i, W / 2^i, C_i + 1)`` (vectors and norms), twice (the model's raw outputs and
  the normalised copies); C_i from ``features.npz``'s headers or the model's output
  shapes (:func:`d3cli.method.features.feature_channels`);
* per-pixel maps: grey images and their pyramids, the integer disparity maps and the
  diffusion's frontier arrays (int32 lists), the band indexes (two int32 ``(H, W, 3)``),
  min-cost, sub-pixel and output maps.

:func:`d3cli.batch.resources.check_memory` reads it through the method's declaration
(:attr:`d3cli.config.MethodSpec.peak_bytes`).
"""

from __future__ import annotations

from ..config import Config
from .features import feature_bytes, feature_channels

#: Bytes per pixel of the per-pixel maps of the d3stereo pipeline: 2 raw images
#: (worst case 3 x uint16 = 6 B each), 2 grey float32 images with pyramids (x 4/3),
#: disparity int32 double buffer, seeds int32, min cost float32, diffusion's changed,
#: stamp and active int32 lists, new values int32, the stored and visible band indexes
#: (2 x 3 int32) and the uniform-band mask, sub-pixel float32, valid/occluded bool,
#: output float32 and its filled copy.
D3_BYTES_PER_PIXEL = 12 + 2 * 4 * 4 / 3 + 8 + 4 + 4 + 3 * 4 + 4 + 2 * 12 + 1 + 4 + 2 + 8


def volume_bytes(cfg: Config, pixels: int, n_disp: int) -> int:
    """Bytes of the float32 cost volumes alive at once at the finest level.

    RBF filters the raw NCC volume in place, row strip by row strip (one volume and a
    few rows); the plain bilateral filter holds the NCC volume and its output.  The
    full range is assumed (the band search can fall back to it).
    """
    volume = pixels * n_disp * 4
    agg = cfg.aggregation
    if agg.rbf:
        return volume
    return 2 * volume if agg.kappa_a > 0 else volume


def d3stereo_peak_bytes(shape, max_disparity: int, cfg: Config) -> int:
    """Estimated peak memory of one d3stereo pair.

    Parameters
    ----------
    shape : sequence of int
        ``(H, W)`` (or ``(H, W, C)``) of the full-resolution images, pixels.
    max_disparity : int
        Largest disparity searched at full resolution, pixels (the volume has
        ``max_disparity + 1`` slices).
    cfg : Config
        Resolved configuration (aggregation settings change the number of volumes, the
        cost kind adds the feature maps).

    Returns
    -------
    int
        Bytes; an upper estimate of the largest simultaneous allocation, not counting
        the Python interpreter and the libraries themselves.
    """
    height, width = int(shape[0]), int(shape[1])
    pixels = max(height, 0) * max(width, 0)
    n_disp = max(int(max_disparity), 0) + 1
    volumes = volume_bytes(cfg, pixels, n_disp)
    weights = pixels * 9 * 4
    features = 0
    if cfg.cost.kind == "features":
        # the model's raw maps of both views, then the normalised (H_i, W_i, C) maps and
        # norms of every level, alive while the levels are matched: twice the latter
        channels = feature_channels(cfg.features, cfg.pyramid.levels)
        features = 2 * feature_bytes((height, width), channels)
    return int(volumes + weights + features + D3_BYTES_PER_PIXEL * pixels)
