"""Plausibility checks of a finished disparity map: warn instead of printing a confident map.

A pair that is not rectified (rows do not correspond) or swapped (the right image given
as the left one, so every true disparity is negative) still produces a full, filled,
colourful disparity map.  Its typical symptoms are visible in the result itself:

* almost no decisive seeds at the coarsest level (the PKRN and left-right tests fail
  nearly everywhere);
* a small share of pixels decided by matching (the rest is hole filling);
* many of the decided disparities piled up at the ends of the search range (a
  negative true disparity is clamped to 0; a too small range clamps at the top).

Thresholds were measured on the 29 pairs of the development data folder (defaults, CPU), each run
as given, swapped, and with the right image shifted down by 6 rows:

==========================  ===============  ==================  ==================
share                       good pairs       swapped             shifted 6 rows
==========================  ===============  ==================  ==================
decided by matching         0.57 - 0.92      0.15 - 0.53         0.13 - 0.48
at the range limits         <= 0.024         0.13 - 0.52         0.02 - 0.15
coarsest-level seeds        0.21 - 0.74      0.014 - 0.50        0.014 - 0.21
==========================  ===============  ==================  ==================

(SGBM: decided 0.64 - 0.88 on good pairs, 0.15 - 0.51 swapped.)  Each symptom gives
one warning; every swapped or shifted pair raised at least one, no good pair did.

A pair whose left image has too little texture or contrast (a dark or featureless scene:
few pixels where the grey level changes by more than sensor noise) shows the first two
symptoms too, with nothing wrong with the pair; then the warning says so instead of
pointing at the inputs (:func:`texture_share`).
"""

from __future__ import annotations

import numpy as np

#: Below this share of pixels decided by the method itself a map is suspicious.
MIN_DECIDED_SHARE = 0.5
#: Above this share of decided disparities within half a pixel of 0 or of the range end.
MAX_LIMIT_SHARE = 0.2
#: Below this share of seeds at the coarsest level: "almost no decisive seeds".
MIN_SEED_SHARE = 0.03
#: Distance to a range end (pixels) that counts as "at the limit".
LIMIT_TOLERANCE = 0.5

_CHECK_INPUTS = ("is the pair rectified (rows correspond), and is the left image really the left one? "
                 "check the inputs before trusting this map")
#: Below this share of textured pixels (:func:`texture_share`) the left image gives
#: matching too little to go on: few seeds and few decided pixels are expected.
MIN_TEXTURE_SHARE = 0.2
#: Grey-level change per pixel (0-255 scale, on the image halved) that counts as texture:
#: above the sensor noise of a dark exposure, below any visible edge.
TEXTURE_GRADIENT = 2.0


def _low_texture(share: float) -> str:
    return (f"the left image has too little texture or contrast for decisive matches ({100 * share:.1f} % of its "
            f"pixels show texture, below {100 * MIN_TEXTURE_SHARE:.0f} % matching has little to go on): a dark or "
            "featureless scene rather than a wrong pair; trust the map only where matching decided it")


def texture_share(image) -> float:
    """Share of the pixels of ``image`` (grey or colour, any dtype) that show texture.

    The image is made grey on a 0-255 scale (integers by their type's range; floats as
    0-1 when no value exceeds 1, as 0-255 when none exceeds 255, else by their maximum),
    halved by 2x2 means (which also averages out sensor
    noise), and a pixel counts where the central-difference gradient exceeds
    :data:`TEXTURE_GRADIENT`.  Cheap: a few milliseconds for a 1280x720 image.
    """
    with np.errstate(all="ignore"):  # a float64 beyond float32's range becomes inf: no texture there
        return _texture_share(np.asarray(image))


def _texture_share(image: np.ndarray) -> float:
    grey = image
    if grey.ndim == 3:
        grey = grey.mean(axis=2, dtype=np.float32)
    grey = grey.astype(np.float32, copy=False)
    kind = image.dtype
    if np.issubdtype(kind, np.integer):
        scale = 255.0 / max(1, np.iinfo(kind).max)
    else:
        finite = grey[np.isfinite(grey)]
        top = float(np.abs(finite).max()) if finite.size else 1.0
        scale = 255.0 if top <= 1.0 else 1.0 if top <= 255.0 else 255.0 / top
    height, width = grey.shape[0] // 2 * 2, grey.shape[1] // 2 * 2
    if height < 6 or width < 6:
        return 1.0  # too small to tell: never blamed on texture
    half = (grey[0:height:2, 0:width:2] + grey[1:height:2, 0:width:2]
            + grey[0:height:2, 1:width:2] + grey[1:height:2, 1:width:2]) * (scale / 4)
    half = np.nan_to_num(half, nan=0.0, posinf=0.0, neginf=0.0)
    gx = (half[1:-1, 2:] - half[1:-1, :-2]) / 2
    gy = (half[2:, 1:-1] - half[:-2, 1:-1]) / 2
    return float((np.hypot(gx, gy) > TEXTURE_GRADIENT).mean())


def _coarse_seed_share(info: dict) -> tuple[float | None, int | None]:
    """(seeds / pixels, seeds) at the coarsest level from ``info['per_level'][0]``."""
    per_level = info.get("per_level") or []
    if not per_level:
        return None, None
    coarse = per_level[0]
    seeds, shape = coarse.get("seeds"), coarse.get("shape")
    if seeds is None or not shape or len(shape) < 2 or shape[0] * shape[1] == 0:
        return None, None
    return seeds / float(shape[0] * shape[1]), int(seeds)


def suspicious_result(result, max_disparity: int, *, left=None) -> list[str]:
    """Warnings about symptoms of an unrectified or swapped pair in a finished result.

    Parameters
    ----------
    result : d3cli.method.DisparityResult
        ``disparity`` float32 (H, W) pixels; ``valid`` bool (H, W) pixels decided by
        the method itself; ``info`` with ``per_level`` (d3stereo: the first entry is the
        coarsest level with ``seeds`` and ``shape``) - baselines have none.
    max_disparity : int
        The top of the searched range, pixels.
    left : ndarray, optional, keyword-only
        The left image.  When it has too little texture (:func:`texture_share` below
        :data:`MIN_TEXTURE_SHARE`), few seeds and few decided pixels are blamed on the
        scene, not on the inputs.

    Returns
    -------
    list of str
        Empty for a plausible map; else one human-readable warning per symptom
        (few seeds, few decided pixels, disparities at the range limits).
    """
    valid = np.asarray(result.valid, dtype=bool)
    if valid.size == 0:
        return []
    warnings = []

    def check() -> str:  # what to look at: the inputs, or the scene (measured only when needed)
        share = texture_share(left) if left is not None else 1.0
        return _low_texture(share) if share < MIN_TEXTURE_SHARE else _CHECK_INPUTS

    share, seeds = _coarse_seed_share(result.info or {})
    # seeds == 0 has its own warning from the pipeline; do not say it twice.
    if share is not None and seeds and share < MIN_SEED_SHARE:
        warnings.append(
            f"almost no decisive seeds at the coarsest level ({100 * share:.1f} % of its pixels, "
            f"good pairs have > {100 * MIN_SEED_SHARE:.0f} %); {check()}"
        )
    decided = float(valid.mean())
    if decided < MIN_DECIDED_SHARE:
        warnings.append(
            f"only {100 * decided:.1f} % of the pixels were decided by matching (the rest is filled; "
            f"good pairs have > {100 * MIN_DECIDED_SHARE:.0f} %); {check()}"
        )
    disp = np.asarray(result.disparity, dtype=np.float32)[valid]
    disp = disp[np.isfinite(disp)]
    if disp.size:
        low = float((disp <= LIMIT_TOLERANCE).mean())
        high = float((disp >= max_disparity - LIMIT_TOLERANCE).mean())
        if low + high > MAX_LIMIT_SHARE:
            if low >= high:
                hint = ("true disparities may be negative: were left and right swapped? "
                        "check the inputs before trusting this map")
            else:
                hint = "the range may be too small: raise --max-disparity, or check that the pair is rectified"
            warnings.append(
                f"{100 * (low + high):.1f} % of the decided disparities sit at the range limits "
                f"({100 * low:.1f} % at 0, {100 * high:.1f} % at {max_disparity}); {hint}"
            )
    return warnings
