"""Scores of a disparity estimate: against ground truth, or by photometric consistency.

Definitions (docs/design.md, 'Metrics'), fixed so that nobody can misread a table:

* **Evaluated pixels**: finite, positive ground truth, intersected with the
  non-occlusion mask when one is given.  ``n_px`` is their number.
* **EPE** (px): mean ``|d - gt|`` over the evaluated pixels.
* **PEP(delta)** (%): 100 x share of evaluated pixels with ``|d - gt| > delta``
  (strictly greater: an error of exactly delta is not an error).
* A pixel the method left **without an estimate** (non-finite ``d``) counts as an error
  of ``|gt|``, as if ``d = 0``; **density** (%) is the share of evaluated pixels that
  have an estimate, reported beside the errors so a sparse method cannot hide.  These
  are the project's own figures.
* **Benchmark figures** (:func:`benchmark_metrics`) compute what the benchmark's own code
  computes, holes included: KITTI D1 fills the holes first as the devkit does
  (:func:`interpolate_background`) and scores the non-occluded pixels against
  ``disp_noc``'s own values; the Middlebury figures leave holes out of the errors and
  report their share as ``invalid`` (:func:`middlebury_errors`).
* **Photometric** (no ground truth): the right image warped into the left view with
  the estimate, scored over the pixels that have an estimate whose match lies inside
  the right image; **coverage** (%) is that share of all pixels.

Everything is computed in float64 and returned as plain Python numbers so the results
go straight into CSV/JSON (:mod:`d3cli.evaluation.report`).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence

import cv2
import numpy as np
from skimage.metrics import structural_similarity

from ..errors import InputError, where_what_fix

logger = logging.getLogger(__name__)

#: Thresholds (px) of the PEP columns that the paper reports.
PEP_THRESHOLDS = (0.5, 1, 2, 3)

#: Keys returned by :func:`disparity_errors` with the default thresholds.
DISPARITY_KEYS = ("epe", "pep_0.5", "pep_1", "pep_2", "pep_3", "density", "n_px")

#: Keys returned by :func:`photometric_scores`.
PHOTOMETRIC_KEYS = ("mse", "psnr", "ssim", "coverage")

#: SSIM settings of docs/design.md, 'Metrics' (Wang et al. 2004: Gaussian window, sigma 1.5).
SSIM_SIGMA = 1.5
DATA_RANGE = 255.0

#: RGB colour of pixels with ground truth but no estimate in :func:`error_map`.
MISSING_COLOUR = (255, 0, 255)


def pep_key(threshold: float) -> str:
    """Name of the PEP column for a threshold in pixels: 0.5 -> ``"pep_0.5"``, 1 -> ``"pep_1"``."""
    return f"pep_{float(threshold):g}"


def disparity_errors(
    pred: np.ndarray,
    gt: np.ndarray,
    *,
    mask: np.ndarray | None = None,
    thresholds: Sequence[float] = PEP_THRESHOLDS,
) -> dict:
    """End-point error, percentages of error pixels and density against ground truth.

    Parameters
    ----------
    pred : ndarray, float, (H, W)
        Estimated left-view disparity in pixels; any non-finite value (inf, nan) means
        "no estimate".
    gt : ndarray, float, (H, W)
        Ground-truth disparity in pixels; only finite values > 0 are evaluated.
    mask : ndarray, bool, (H, W), optional
        Pixels allowed into the evaluation (e.g. the non-occlusion mask; nonzero = use).
    thresholds : sequence of float, keyword-only
        PEP thresholds in pixels.

    Returns
    -------
    dict
        ``epe`` (px), ``pep_<t>`` for every threshold (%, see :func:`pep_key`),
        ``density`` (%), all float; ``n_px`` (int, number of evaluated pixels).
        With no evaluable pixel the floats are NaN and ``n_px`` is 0.

    Raises
    ------
    InputError
        When the shapes of ``pred``, ``gt`` and ``mask`` differ or are not 2-D.

    Notes
    -----
    A pixel without an estimate counts as an error of ``|gt|`` (as if ``d = 0``), so
    EPE and PEP never improve by leaving hard pixels out; ``density`` says how many
    pixels actually had an estimate.

    Examples
    --------
    >>> gt = np.array([[1.0, 2.0]])
    >>> pred = np.array([[1.25, np.inf]])
    >>> r = disparity_errors(pred, gt)
    >>> r["epe"], r["pep_1"], r["density"], r["n_px"]
    (1.125, 50.0, 50.0, 2)
    """
    pred = np.asarray(pred, dtype=np.float64)
    gt = np.asarray(gt, dtype=np.float64)
    _check_same_2d_shape("disparity_errors", prediction=pred, ground_truth=gt, mask=mask)

    evaluated = _evaluable_ground_truth(gt, mask)
    n_px = int(np.count_nonzero(evaluated))
    keys = ["epe", *(pep_key(t) for t in thresholds), "density"]
    if n_px == 0:
        result = {key: math.nan for key in keys}
        result["n_px"] = 0
        return result

    d = pred[evaluated]
    g = gt[evaluated]
    has_estimate = np.isfinite(d)
    # A missing estimate is scored as d = 0: its error is the whole ground truth.
    error = np.abs(np.where(has_estimate, d, 0.0) - g)

    result = {"epe": float(error.mean())}
    for t in thresholds:
        result[pep_key(t)] = 100.0 * float(np.count_nonzero(error > t)) / n_px
    result["density"] = 100.0 * float(np.count_nonzero(has_estimate)) / n_px
    result["n_px"] = n_px
    return result


def photometric_scores(left: np.ndarray, right: np.ndarray, pred: np.ndarray) -> dict:
    """Photometric consistency of a disparity map: the right image warped into the left view.

    The warped image is ``W(u, v) = R(u - d(u, v), v)`` with linear interpolation along
    the row (rectified pair: rows are identical).  A pixel is *scored* when ``d`` is
    finite and the match falls inside the right image, ``0 <= u - d <= width - 1``.

    Parameters
    ----------
    left, right : ndarray, float, (H, W)
        Grey images on the 0-255 scale (e.g. from :func:`d3cli.data.formats.to_grey`).
    pred : ndarray, float, (H, W)
        Left-view disparity in pixels; non-finite = no estimate.

    Returns
    -------
    dict
        ``mse`` (0-255 scale, mean squared difference left - warped over the scored
        pixels), ``psnr`` (dB, ``10 log10(255^2 / mse)``, ``inf`` when ``mse == 0``),
        ``ssim`` (mean of the SSIM map over the scored pixels) and ``coverage`` (%,
        scored pixels over all pixels).  With no scored pixel, ``mse``, ``psnr`` and
        ``ssim`` are NaN and ``coverage`` is 0.

    Raises
    ------
    InputError
        When the arrays are not 2-D or their shapes differ.

    Notes
    -----
    SSIM uses the settings of Wang et al. (2004) as in docs/design.md, 'Metrics':
    ``skimage.metrics.structural_similarity(left, warped, gaussian_weights=True,
    sigma=1.5, use_sample_covariance=False, data_range=255, full=True)``, and averages
    the full-size SSIM map over the scored pixels only.  Where the warp is undefined
    (no estimate, or the match falls outside the right image) the warped image takes
    the *left* image's value before SSIM runs, so that the 11 x 11 windows of scored
    pixels next to holes stay defined; those filler pixels agree perfectly with the
    left image, which biases SSIM slightly upwards right next to holes (report the
    coverage beside it).  Images smaller than the 11 x 11 SSIM window give
    ``ssim = NaN``.
    """
    left = np.asarray(left, dtype=np.float64)
    right = np.asarray(right, dtype=np.float64)
    pred = np.asarray(pred, dtype=np.float64)
    _check_same_2d_shape("photometric_scores", left=left, right=right, prediction=pred)

    warped, scored = warp_right_to_left(right, pred)
    n_scored = int(np.count_nonzero(scored))
    coverage = 100.0 * n_scored / scored.size
    if n_scored == 0:
        return {"mse": math.nan, "psnr": math.nan, "ssim": math.nan, "coverage": coverage}

    mse = float(np.mean((left[scored] - warped[scored]) ** 2))
    psnr = math.inf if mse == 0.0 else 10.0 * math.log10(DATA_RANGE**2 / mse)
    filled = np.where(scored, warped, left)
    ssim = _mean_ssim(left, filled, scored)
    return {"mse": mse, "psnr": psnr, "ssim": ssim, "coverage": coverage}


def warp_right_to_left(right: np.ndarray, pred: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sample the right image at each left pixel's match, ``R(u - d, v)``, linearly in u.

    Parameters
    ----------
    right : ndarray, float, (H, W)
        Right image.
    pred : ndarray, float, (H, W)
        Left-view disparity in pixels; non-finite = no estimate.

    Returns
    -------
    warped : ndarray, float64, (H, W)
        The warped right image; NaN where ``defined`` is False.
    defined : ndarray, bool, (H, W)
        True where ``d`` is finite and ``0 <= u - d <= W - 1``.
    """
    right = np.asarray(right, dtype=np.float64)
    pred = np.asarray(pred, dtype=np.float64)
    height, width = right.shape
    u = np.arange(width, dtype=np.float64)[None, :]
    with np.errstate(invalid="ignore"):
        x = u - pred  # inf/nan disparities give non-finite x, dropped just below
        defined = np.isfinite(x) & (x >= 0.0) & (x <= width - 1)
    x = np.where(defined, x, 0.0)
    x0 = np.floor(x).astype(np.intp)
    x1 = np.minimum(x0 + 1, width - 1)  # x == W - 1 exactly: weight of x1 is 0 anyway
    frac = x - x0
    rows = np.arange(height)[:, None]
    warped = (1.0 - frac) * right[rows, x0] + frac * right[rows, x1]
    warped[~defined] = np.nan
    return warped, defined


def error_map(
    pred: np.ndarray,
    gt: np.ndarray,
    *,
    mask: np.ndarray | None = None,
    max_error: float = 4.0,
) -> np.ndarray:
    """Colour-coded absolute disparity error, for looking at where a method fails.

    Parameters
    ----------
    pred : ndarray, float, (H, W)
        Estimated disparity in pixels; non-finite = no estimate.
    gt : ndarray, float, (H, W)
        Ground-truth disparity in pixels; finite values > 0 are valid.
    mask : ndarray, bool, (H, W), optional
        Pixels that are evaluated (e.g. non-occlusion mask); the others are drawn black
        like pixels without ground truth.
    max_error : float, keyword-only
        Error in pixels that maps to the top of the colour scale; larger errors saturate.

    Returns
    -------
    ndarray, uint8, (H, W, 3)
        RGB image: ``|d - gt|`` on OpenCV's JET scale from 0 (dark blue) to
        ``>= max_error`` (dark red); black where the pixel is not evaluated (no valid
        ground truth, or outside ``mask``); magenta (255, 0, 255) where ground truth
        exists but the method gave no estimate.

    Raises
    ------
    InputError
        When shapes differ or ``max_error`` is not a positive number.
    """
    pred = np.asarray(pred, dtype=np.float64)
    gt = np.asarray(gt, dtype=np.float64)
    _check_same_2d_shape("error_map", prediction=pred, ground_truth=gt, mask=mask)
    if not (math.isfinite(max_error) and max_error > 0):
        raise InputError(
            where_what_fix(
                "error_map", f"max_error is {max_error}", "give a positive number of pixels"
            )
        )

    evaluated = _evaluable_ground_truth(gt, mask)
    has_estimate = np.isfinite(pred)
    with np.errstate(invalid="ignore"):
        error = np.abs(pred - gt)
    scaled = np.clip(np.where(evaluated & has_estimate, error, 0.0) / max_error, 0.0, 1.0)
    ramp = np.round(scaled * 255.0).astype(np.uint8)
    rgb = cv2.cvtColor(cv2.applyColorMap(ramp, cv2.COLORMAP_JET), cv2.COLOR_BGR2RGB)
    rgb[~evaluated] = 0
    rgb[evaluated & ~has_estimate] = MISSING_COLOUR
    return rgb


def _evaluable_ground_truth(gt: np.ndarray, mask: np.ndarray | None) -> np.ndarray:
    """Boolean map of pixels with finite, positive ground truth (and inside ``mask``)."""
    with np.errstate(invalid="ignore"):
        evaluated = np.isfinite(gt) & (gt > 0)
    if mask is not None:
        evaluated &= np.asarray(mask) != 0
    return evaluated


def _mean_ssim(left: np.ndarray, filled: np.ndarray, scored: np.ndarray) -> float:
    """Mean of the SSIM map of (left, filled) over ``scored``; NaN for images below the window."""
    window = 2 * int(3.5 * SSIM_SIGMA + 0.5) + 1  # skimage's Gaussian window (truncate 3.5)
    if min(left.shape) < window:
        logger.warning(
            "SSIM needs images of at least %dx%d pixels, got %dx%d; reporting NaN",
            window,
            window,
            *left.shape,
        )
        return math.nan
    _, ssim_map = structural_similarity(
        left,
        filled,
        gaussian_weights=True,
        sigma=SSIM_SIGMA,
        use_sample_covariance=False,
        data_range=DATA_RANGE,
        full=True,
    )
    return float(np.mean(ssim_map[scored]))


def _check_same_2d_shape(where: str, **arrays: np.ndarray | None) -> None:
    """Raise InputError unless every given array is 2-D and all shapes are equal."""
    given = {name: np.shape(a) for name, a in arrays.items() if a is not None}
    for name, shape in given.items():
        if len(shape) != 2:
            raise InputError(
                where_what_fix(
                    where,
                    f"{name} has shape {shape}",
                    "give a single-channel (H, W) array (convert colour images with "
                    "d3cli.data.formats.to_grey)",
                )
            )
    shapes = set(given.values())
    if len(shapes) > 1:
        described = ", ".join(f"{name} is {s[0]}x{s[1]}" for name, s in given.items())
        raise InputError(
            where_what_fix(where, described, "all arrays must have the same height x width")
        )


#: Middlebury bad-x thresholds (px).
BAD_THRESHOLDS = (0.5, 1, 2, 4)

#: Middlebury error quantiles (fractions) reported as ``a50`` ... ``a99``.
QUANTILES = (0.50, 0.90, 0.95, 0.99)

#: KITTI D1 outlier rule: ``|err| > D1_PIXELS`` px **and** ``|err| > D1_RELATIVE * gt``.
D1_PIXELS = 3.0
D1_RELATIVE = 0.05

#: The KITTI devkit's value of a pixel without a disparity (``DisparityImage::setInvalid``);
#: a pixel that :func:`interpolate_background` cannot fill keeps it and is scored as ``d = -1``.
KITTI_INVALID = -1.0

#: Figures of :func:`benchmark_metrics` per pixel set, in column order.
BENCHMARK_FIGURES = ("d1", *(f"bad_{t:g}" for t in BAD_THRESHOLDS), "invalid", "avgerr", "rms",
                     *(f"a{round(q * 100)}" for q in QUANTILES), "n_px")


def kitti_estimates(pred: np.ndarray) -> np.ndarray:
    """Pixels that hold an estimate for the KITTI devkit: finite and > 0.

    The devkit reads a uint16 PNG in which 0 means "no estimate"; ``export --format kitti``
    (:func:`d3cli.data.formats.encode_kitti`) writes non-finite values and values <= 0 as
    that 0, so the other pixels are the holes the devkit sees in an exported map.
    """
    pred = np.asarray(pred, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return np.isfinite(pred) & (pred > 0)


def interpolate_background(pred: np.ndarray) -> np.ndarray:
    """Fill the holes of a disparity map as the KITTI devkit does before it counts D1.

    The KITTI stereo/scene-flow devkit (``devkit/cpp/io_disp.h``,
    ``DisparityImage::interpolateBackground()``, run by ``evaluate_scene_flow.cpp`` on every
    submitted map: ``D_ipol = D_orig; D_ipol.interpolateBackground()``) does, in this order:

    1. in each row, a run of holes with an estimate on both sides takes the *smaller* of
       the two neighbouring values (``std::min(getDisp(u1-1,v), getDisp(u2+1,v))``: the
       farther surface, background);
    2. in each row, the holes left of the first estimate take its value and the holes
       right of the last estimate take the last one's; a row without any estimate stays
       empty;
    3. in each column, the pixels above the first filled row take that row's value and
       the pixels below the last filled row the last row's value.  Empty rows *between*
       filled rows are not filled: they keep the devkit's invalid value -1
       (:data:`KITTI_INVALID`), and the devkit scores them as ``d = -1``; so does a map
       without any estimate.

    Parameters
    ----------
    pred : ndarray, float, (H, W)
        Disparity in pixels; holes are the pixels outside :func:`kitti_estimates`.

    Returns
    -------
    ndarray, float64, (H, W)
        The filled map: the estimates unchanged, every hole filled, -1 where the devkit
        leaves one.

    Examples
    --------
    >>> interpolate_background(np.array([[np.inf, 5.0, np.nan, 0.0, 9.0, -2.0]]))
    array([[5., 5., 5., 5., 9., 9.]])
    """
    pred = np.asarray(pred, dtype=np.float64)
    if pred.ndim != 2:
        _check_same_2d_shape("interpolate_background", prediction=pred)
    height, width = pred.shape
    valid = kitti_estimates(pred)
    filled = np.where(valid, pred, KITTI_INVALID)
    if valid.all() or not valid.any():
        return filled
    # On the flattened map (1-D accumulations are fast): the index of the nearest estimate
    # at or before / at or after each pixel, kept when it lies in the pixel's own row.
    flat, ok = filled.ravel(), valid.ravel()
    index = np.arange(flat.size)
    row_start = index - index % width
    left = np.maximum.accumulate(np.where(ok, index, -1))
    right = np.minimum.accumulate(np.where(ok, index, flat.size)[::-1])[::-1]
    has_left, has_right = left >= row_start, right < row_start + width
    left_value = flat[np.clip(left, 0, flat.size - 1)]
    right_value = flat[np.clip(right, 0, flat.size - 1)]
    hole = ~ok
    out = flat.copy()
    both = hole & has_left & has_right
    out[both] = np.minimum(left_value[both], right_value[both])  # step 1
    before = hole & ~has_left & has_right
    out[before] = right_value[before]  # step 2, left of the row's first estimate
    after = hole & has_left & ~has_right
    out[after] = left_value[after]  # step 2, right of the row's last estimate
    filled = out.reshape(height, width)
    filled_rows = np.flatnonzero(valid.any(axis=1))
    first, last = filled_rows[0], filled_rows[-1]
    filled[:first] = filled[first]  # step 3
    filled[last + 1:] = filled[last]
    return filled


def kitti_d1(filled: np.ndarray, gt: np.ndarray) -> float:
    """KITTI D1 (%) of a set of pixels: the devkit's ``disparityErrorsOutlier``.

    Parameters
    ----------
    filled : ndarray, float, (N,)
        Disparities after :func:`interpolate_background`.
    gt : ndarray, float, (N,)
        Ground truth of the same pixels (all > 0).

    Returns
    -------
    float
        100 x share of the pixels with ``|gt - d| > 3`` **and** ``|gt - d| / |gt| > 0.05``;
        NaN for no pixel.
    """
    filled = np.asarray(filled, dtype=np.float64).ravel()
    gt = np.asarray(gt, dtype=np.float64).ravel()
    if gt.size == 0:
        return math.nan
    error = np.abs(gt - filled)
    outliers = (error > D1_PIXELS) & (error > D1_RELATIVE * np.abs(gt))
    return 100.0 * float(np.count_nonzero(outliers)) / gt.size


def middlebury_errors(pred: np.ndarray, gt: np.ndarray, *, max_disparity: float | None = None) -> dict:
    """The Middlebury figures of one set of evaluated pixels, with the MiddEval3 SDK's rule for holes.

    The SDK's ``evaldisp`` (MiddEval3 SDK, ``code/evaldisp/evaldisp.cpp``, function
    ``evaldisp()``, run per dataset by ``runeval``) goes over the pixels with known ground
    truth (inside the mask): an estimate of INFINITY is *invalid* (a hole in a sparse
    map); a valid one is clipped to ``[0, maxdisp]`` and has ``err = |d - gt|``.  It counts
    ``n`` (every evaluated pixel, holes included), ``bad`` (valid estimates with
    ``err > badthresh``) and ``invalid`` (holes), and prints ``bad% = 100 bad / n`` (a hole
    is in the total but not bad), ``invalid% = 100 invalid / n``, ``totbad% = bad% +
    invalid%`` and ``avgErr = sum(err) / (n - invalid)`` (holes left out).  Non-finite
    values are this project's holes; ``export --format middeval3`` writes them as INFINITY.

    Parameters
    ----------
    pred : ndarray, float, (N,)
        Estimates of the evaluated pixels; non-finite = hole.
    gt : ndarray, float, (N,)
        Ground truth of the same pixels.
    max_disparity : float, optional, keyword-only
        evaldisp's ``maxdisp``; None clips only at 0 (evaldisp's default is 99999).

    Returns
    -------
    dict
        ``bad_<x>`` (%, the SDK's bad column, x in :data:`BAD_THRESHOLDS`), ``invalid``
        (%), ``avgerr`` (px), ``rms`` (px, ``sqrt(mean(err^2))``), ``a<q>`` (px, the
        error quantile: the smallest err such that at least q of the pixels have an error
        <= it, ``sorted(err)[ceil(q M) - 1]``) and ``n_px`` (``n``).  evaldisp prints no
        RMS or quantile: they are taken over avgErr's pixels, the ``M = n - invalid``
        valid estimates.  With ``n == 0`` every float is NaN; with ``M == 0`` avgerr, rms
        and the quantiles are.
    """
    pred = np.asarray(pred, dtype=np.float64).ravel()
    gt = np.asarray(gt, dtype=np.float64).ravel()
    if max_disparity is not None and not (isinstance(max_disparity, (int, float, np.number))
                                          and math.isfinite(max_disparity) and max_disparity > 0):
        raise InputError(where_what_fix("middlebury_errors", f"max_disparity is {max_disparity!r}",
                                        "give a positive number of pixels, or None"))
    n = int(gt.size)
    result = {key: math.nan for key in BENCHMARK_FIGURES if key not in ("d1", "n_px")}
    result["n_px"] = n
    if n == 0:
        return result
    valid = np.isfinite(pred)
    d = np.clip(pred[valid], 0.0, math.inf if max_disparity is None else float(max_disparity))
    error = np.abs(d - gt[valid])
    for t in BAD_THRESHOLDS:
        result[f"bad_{t:g}"] = 100.0 * float(np.count_nonzero(error > t)) / n
    result["invalid"] = 100.0 * float(n - error.size) / n
    if error.size:
        result["avgerr"] = float(error.mean())
        result["rms"] = float(math.sqrt(float(np.mean(error**2))))
        for q in QUANTILES:
            # inverted_cdf = Middlebury's "error threshold that q of the pixels stay under".
            result[f"a{round(q * 100)}"] = float(np.quantile(error, q, method="inverted_cdf"))
    return result


def benchmark_metrics(
    pred: np.ndarray,
    gt: np.ndarray,
    *,
    noc_mask: np.ndarray | None = None,
    noc_gt: np.ndarray | None = None,
    object_map: np.ndarray | None = None,
    max_disparity: float | None = None,
) -> dict:
    """KITTI D1 and the Middlebury figures on *all* and *noc* pixels, as each benchmark's code computes them.

    * D1 (``d1_*``, ``d1_bg``, ``d1_fg``): the KITTI devkit's rule.  The map's holes are
      filled first (:func:`interpolate_background`), then :func:`kitti_d1` counts the
      outliers; the *noc* pixels are scored against the non-occluded ground truth's own
      values (KITTI ``disp_noc``, ``noc_gt``), as the devkit does.
    * bad-x, invalid, avgerr, rms, A-quantiles: the MiddEval3 SDK's rule for holes
      (:func:`middlebury_errors`), on the unfilled map.

    The project's own figures, where every hole counts as an error of ``gt``, are
    :func:`disparity_errors` (EPE, PEP, density).

    Parameters
    ----------
    pred : ndarray, float, (H, W)
        Estimated disparity (px); non-finite = no estimate (for D1 also values <= 0,
        see :func:`kitti_estimates`).
    gt : ndarray, float, (H, W)
        Ground truth (px); finite values > 0 are evaluated ("all" = KITTI disp_occ).
    noc_mask : ndarray, bool, (H, W), optional
        Non-occluded pixels (Middlebury mask0nocc == 255, KITTI disp_noc > 0).
    noc_gt : ndarray, float, (H, W), optional
        Ground truth of the non-occluded pixels when it is a map of its own (KITTI
        ``disp_noc``): its finite values > 0 (inside ``noc_mask`` if given) are the *noc*
        pixels, scored against these values.  Without it the *noc* pixels are ``gt``'s
        inside ``noc_mask``.  With neither, every ``*_noc`` figure is NaN (never silently
        the "all" figure).
    object_map : ndarray, (H, W), optional
        KITTI 2015 obj_map: 0 = background, > 0 = foreground (cars); adds ``d1_bg`` and
        ``d1_fg`` on the "all" pixels.
    max_disparity : float, optional
        The Middlebury SDK's ``maxdisp`` (see :func:`middlebury_errors`).

    Returns
    -------
    dict
        For each figure of :data:`BENCHMARK_FIGURES` two keys ``<fig>_all`` and
        ``<fig>_noc`` (e.g. ``d1_all``, ``bad_2_noc``, ``invalid_all``, ``n_px_noc``), and
        ``d1_bg``/``d1_fg`` with an object map.
    """
    pred = np.asarray(pred, dtype=np.float64)
    gt = np.asarray(gt, dtype=np.float64)
    noc_gt = None if noc_gt is None else np.asarray(noc_gt, dtype=np.float64)
    _check_same_2d_shape("benchmark_metrics", prediction=pred, ground_truth=gt, mask=noc_mask,
                         noc_ground_truth=noc_gt, object_map=object_map)
    filled = interpolate_background(pred)
    sets = {"all": (gt, _evaluable_ground_truth(gt, None))}
    if noc_mask is not None or noc_gt is not None:
        truth = gt if noc_gt is None else noc_gt
        sets["noc"] = (truth, _evaluable_ground_truth(truth, noc_mask))
    out = {}
    for name in ("all", "noc"):
        if name in sets:
            truth, selected = sets[name]
            figures = {"d1": kitti_d1(filled[selected], truth[selected]),
                       **middlebury_errors(pred[selected], truth[selected], max_disparity=max_disparity)}
        else:
            figures = {key: (0 if key == "n_px" else math.nan) for key in BENCHMARK_FIGURES}
        out.update({f"{key}_{name}": figures[key] for key in BENCHMARK_FIGURES})
    if object_map is not None:
        fg = np.asarray(object_map) > 0
        valid = sets["all"][1]
        out["d1_bg"] = kitti_d1(filled[valid & ~fg], gt[valid & ~fg])
        out["d1_fg"] = kitti_d1(filled[valid & fg], gt[valid & fg])
    return out
