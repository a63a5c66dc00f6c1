"""Whether a defect's measurement can be acted on: ``ok``, or flagged with the reasons why not.

A crew acts on single potholes, so a depth that stereo cannot measure must be reported as
such, with its outline, instead of as a confident wrong number.  Every reason is computed
from the images and the maps of the pair (never from ground truth), and every number it is
computed from is written beside it (defects.json ``evidence``), so a user can see why.

Reasons (defects.json ``flags``, in this order):

``weak_match``
    The images barely support the disparity the defect was measured on: the 25 px NCC at
    that disparity exceeds the better NCC one pixel to either side by less than
    :attr:`ConfidenceRules.min_match_margin`, in the median over the defect
    (:func:`d3cli.road.rematch.match_margin`, evidence ``match_margin``).  Dark, smooth
    and wet floors give flat NCC curves: many depths fit them about equally well, and the
    one reported may be any of them.  Needs the right image (``d3stereo run
    --road-report`` always has it).
``specular``
    Raised only where no match margin is known (a report without the right image): the
    defect's deepest pixels stand more than :attr:`ConfidenceRules.max_spikiness` above
    the deepest pixels of the same depth median-filtered over
    :attr:`ConfidenceRules.spike_px` pixels (a wet floor mirrors the sky, and a reflection
    matched by stereo lies as far below the surface as its source lies above it: isolated,
    deep spikes on the floor).  With the margin known the spikiness stays in the evidence
    but decides nothing: on the tuning pairs it flagged well measured wet potholes far
    more often than badly measured ones.
``noisy``
    Dark or noisy: the depth is less than :attr:`ConfidenceRules.min_snr` times the height
    noise its significance was tested against (:func:`d3cli.road.defects.find_defects`);
    without the match margin, less than :attr:`ConfidenceRules.min_snr_alone` times.  The
    deepest pixels of a noisy map read deep by a few noise levels.
``few_decided``
    Fewer than ``road.min_decided_share`` of the defect's pixels were decided by the method
    itself; the rest is hole filling, an extrapolation.
``at_border``
    The defect's deep part (deeper than half its depth) reaches the image border: its
    deepest point may lie beyond.  A defect whose rim only touches the border keeps its
    depth (``at_border`` in defects.json says that area and volume are lower bounds).
``merged``
    The region holds two or more depressions, each standing ``road.split_prominence_mm``
    above the saddle between them, that the splitting did not cut because the map's noise
    is larger (:func:`d3cli.road.splitting.split_parts`): possibly two potholes as one.
``rematch``
    The small-window re-match (:mod:`d3cli.road.rematch`) and the stored map disagree in
    a way the stored map's bias cannot explain.  The stored map averages a pothole's floor
    with its shallower walls (the 25 px matching window and the smoothing of
    configs/road.yaml), so it reads a pothole shallower, never deeper, by up to about half
    its depth for one a window across: a re-match that makes the depth shallower by more
    than :attr:`ConfidenceRules.min_rematch_change`, or deeper by more than
    :attr:`ConfidenceRules.max_rematch_change` (more than twice as deep), measured
    something else than the floor the stored map saw (a shelf of a deeper pothole, a
    reflection).  The window it used is evidence too (``rematch_window``, 0:
    none was clean and the depth is the stored, smoothed map's).
``narrow``
    No re-match window measured the defect cleanly (``rematch_window`` 0), so its depth is
    the stored map's, and the defect is too narrow for that map to reach its floor: the
    largest disc inside it (evidence ``inscribed_px``, its radius in the image's pixels)
    is smaller than how far the method that made the map averages around a pixel
    (evidence ``averaging_px``: for d3stereo half its matching window plus its smoothing
    radius, 12 + 15 = 27 px with configs/road.yaml; for SGBM half its block;
    :attr:`d3cli.config.MethodSpec.averaging_px`).  Every floor pixel of such a map
    averages the shallower walls in: the depth reads low (dusk cones and narrow potholes
    23-35 % shallow on the check seeds).  Without ``averaging_px`` (a method that does not
    say) no defect is flagged ``narrow``.

The thresholds were chosen on synthetic pairs with exact ground truth (docs/road.md, "The
confidence check"): on the 252 pairs of the twelve seeds they were last chosen on, 5 of
the 214 potholes reported ``ok`` are off by more than 20 % (four measured on the stored map,
23-35 % shallow: dusk cones and narrow potholes whose re-match scores below
:data:`~d3cli.road.rematch.MIN_SCORE`; one wet pothole 42 % too deep), and the check on
seeds never used for them is in docs/road.md.

May import numpy, OpenCV and :mod:`d3cli.road.compiled`.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .compiled import h_maxima, window_medians

#: Reason code -> the words a report prints for it.
REASONS = {
    "weak_match": "weak match on little texture",
    "specular": "wet or specular surface",
    "noisy": "dark or noisy",
    "few_decided": "few decided pixels",
    "at_border": "at the image border",
    "merged": "possibly merged with a neighbour",
    "rematch": "re-match unreliable",
    "narrow": "narrower than the matching window, not re-matched",
}

#: Short labels for pictures (defects.png).
SHORT = {"weak_match": "weak", "specular": "wet", "noisy": "dark", "few_decided": "filled", "at_border": "edge",
         "merged": "merged", "rematch": "rematch", "narrow": "narrow"}


@dataclass(frozen=True)
class ConfidenceRules:
    """Thresholds of the reasons (module docstring); fixed by measurement, changed in tests
    and experiments only.

    Attributes
    ----------
    min_match_margin : float
        ``weak_match`` below this match margin (NCC units).
    max_spikiness : float
        ``specular`` above this ratio of the peak depth to the peak of the depth
        median-filtered over ``spike_px`` pixels.
    spike_px : int
        Odd side of that median filter, pixels.
    min_snr : float
        ``noisy`` below this ratio of the depth to the height noise around the defect.
    min_snr_alone : float
        The same where no match margin is known.
    min_rematch_change, max_rematch_change : float
        ``rematch`` below the first or above the second relative change of the depth by
        the re-match (the re-matched depth over the stored one, minus 1).
    """

    min_match_margin: float = 0.020
    max_spikiness: float = 1.10
    spike_px: int = 15
    min_snr: float = 4.0
    min_snr_alone: float = 10.0
    min_rematch_change: float = -0.15
    max_rematch_change: float = 1.0


def flags_of(evidence: dict, *, min_decided_share: float, rules: ConfidenceRules | None = None) -> tuple:
    """The reason codes of one defect from its evidence (keys as written by
    :func:`d3cli.road.defects.find_defects` and :func:`d3cli.road.outputs.road_report`; a
    missing key raises no flag).

    Parameters
    ----------
    evidence : dict
        ``match_margin`` (absent without the right image; None where it could not be
        measured: ``weak_match``), ``spikiness``, ``snr``, ``decided_share``,
        ``deep_at_border``, ``depressions``, ``rematch_change``, ``rematch_window``,
        ``inscribed_px`` and ``averaging_px`` (absent without a re-match; the last where
        the method does not say) and ``map_decided_share`` (present when the whole map's
        decided share is below
        ``min_decided_share``: every defect is ``few_decided``).
    min_decided_share : float, keyword-only
        ``road.min_decided_share``.
    rules : ConfidenceRules, optional

    Returns
    -------
    tuple of str
        Codes of :data:`REASONS`, in its order; empty: ``ok``.
    """
    rules = ConfidenceRules() if rules is None else rules
    margin_known = "match_margin" in evidence
    margin = evidence.get("match_margin")
    raised = {
        "weak_match": margin_known and (margin is None or margin < rules.min_match_margin),
        "specular": not margin_known and evidence.get("spikiness", 1.0) > rules.max_spikiness,
        "noisy": evidence.get("snr", np.inf) < (rules.min_snr if margin_known else rules.min_snr_alone),
        "few_decided": min(evidence.get("decided_share", 1.0), evidence.get("map_decided_share", 1.0))
        < min_decided_share,
        "at_border": bool(evidence.get("deep_at_border", False)),
        "merged": evidence.get("depressions", 1) >= 2,
        "rematch": not rules.min_rematch_change <= evidence.get("rematch_change", 0.0) <= rules.max_rematch_change,
        "narrow": evidence.get("rematch_window") == 0
        and evidence.get("inscribed_px", np.inf) < evidence.get("averaging_px", 0.0),
    }
    return tuple(code for code in REASONS if raised[code])


def describe(flags) -> str:
    """``"ok"`` or the reasons in words, for reports: ``"wet or specular surface; dark or noisy"``."""
    return "; ".join(REASONS.get(f, f) for f in flags) or "ok"


def spikiness(depth: np.ndarray, inside: np.ndarray, *, peak_px: int, spike_px: int) -> float:
    """Ratio of the peak depth of ``depth`` over ``inside`` to the peak of ``depth``
    median-filtered over ``spike_px`` pixels (1 where the filtered peak is not positive).

    The peak is the mean of the ``peak_px`` largest values: the extremes a spike makes
    (the reported depth averages a share of the region, :class:`d3cli.road.defects.DefectTuning`).  The filter is evaluated only at the pixels
    around the deepest ones (the ``16 peak_px`` deepest of ``inside``): a median of a window
    is at most the window's largest value, so the filtered peak lies where the depth is deep.

    Parameters
    ----------
    depth : ndarray, float, (H, W)
        Depth below the surrounding surface, metres (finite where ``inside``).
    inside : ndarray, bool, (H, W)
        The pixels the peak is taken over.
    peak_px, spike_px : int, keyword-only
    """
    values = depth[inside]
    if values.size < peak_px:
        return 1.0
    k = min(peak_px, values.size)
    peak = float(np.mean(np.partition(values, values.size - k)[values.size - k:]))
    v, u = np.nonzero(inside)
    n = min(values.size, 16 * peak_px)
    top = np.argpartition(values, values.size - n)[values.size - n:]
    # np.nanmedian of each window, the values that are not finite left out (compiled)
    filtered = window_medians(np.ascontiguousarray(depth), v[top], u[top], spike_px // 2)
    filtered = filtered[np.isfinite(filtered)]
    if filtered.size == 0:
        return 1.0
    k = min(peak_px, filtered.size)
    smooth_peak = float(np.mean(np.partition(filtered, filtered.size - k)[filtered.size - k:]))
    return peak / smooth_peak if smooth_peak > 0 and peak > 0 else 1.0


def deep_at_border(depth: np.ndarray, region: np.ndarray, peak: float, origin: tuple, full_shape: tuple) -> bool:
    """Whether the part of ``region`` deeper than half ``peak`` reaches the image border.

    ``depth`` and ``region`` are a window of the image starting at ``origin`` (row, column)
    in an image of ``full_shape``.
    """
    with np.errstate(invalid="ignore"):
        deep = region & (depth > 0.5 * peak)
    if not deep.any():
        return False
    v, u = np.nonzero(deep)
    v0, u0 = origin
    return bool(v.min() + v0 == 0 or u.min() + u0 == 0 or v.max() + v0 == full_shape[0] - 1
                or u.max() + u0 == full_shape[1] - 1)


def depressions(depth: np.ndarray, region: np.ndarray, *, prominence: float, smooth_px: float) -> int:
    """Number of depressions of ``region``: regional maxima of ``depth`` (Gaussian-smoothed
    with ``smooth_px``, as the splitting sees it) that stand at least ``prominence`` above
    the saddle to any deeper one (the h-maxima, metres), the deepest counting always.

    The smoothed depth varies over ``smooth_px``, so it is counted on a grid of
    ``smooth_px / 3`` pixels: the same maxima at a fraction of the cost.
    """
    if not region.any():
        return 0
    v, u = np.nonzero(region)
    box = (slice(v.min(), v.max() + 1), slice(u.min(), u.max() + 1))
    inside = region[box].astype(np.float32)
    d = np.where(region[box] & np.isfinite(depth[box]), depth[box], 0.0).astype(np.float32)
    if smooth_px > 0:
        d = cv2.GaussianBlur(d, (0, 0), smooth_px)
    step = max(int(smooth_px // 3), 1)
    if step > 1 and min(d.shape) > 2 * step:
        size = (max(d.shape[1] // step, 1), max(d.shape[0] // step, 1))
        d = cv2.resize(d, size, interpolation=cv2.INTER_AREA)
        inside = cv2.resize(inside, size, interpolation=cv2.INTER_AREA)
    keep = inside > 0.5
    if not keep.any():
        return 1
    d = np.where(keep, d, float(d[keep].min()) - prominence).astype(np.float64)
    peaks = h_maxima(d, prominence) & keep
    return max(int(cv2.connectedComponents(peaks.astype(np.uint8), connectivity=8)[0]) - 1, 1)
