"""Names, units and exact definitions of every metric column, for people reading a report.

One table (:data:`METRICS`) that report.html's column heads and definitions section,
summary.md's tables and the terminal table all read, so a column has the same name and
unit everywhere ("EPE [px]", "bad 2 (non-occ.) [%]", "PEP 3 [%]").  Which columns a
report shows is chosen in one place, :func:`d3cli.evaluation.summary.shown_columns`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .metrics import BAD_THRESHOLDS, D1_PIXELS, D1_RELATIVE, PEP_THRESHOLDS, QUANTILES, pep_key


#: From this magnitude on, values are written in exponent notation ("3.000e+38"):
#: 39 digits of a 3e38 px error help nobody.
HUGE = 1e7


@dataclass(frozen=True)
class Metric:
    """How one metric column is named, shown and defined.

    Attributes
    ----------
    name : str
        Name with its pixel set, without the unit ("bad 2 (non-occ.)").
    unit : str
        Unit ("px", "%", "dB", "s"); empty for a pure number.
    decimals : int
        Decimals shown in tables.
    definition : str
        One sentence that says exactly how the value is computed.
    """

    name: str
    unit: str
    decimals: int
    definition: str

    @property
    def label(self) -> str:
        """``name [unit]``, or the name alone when there is no unit."""
        return f"{self.name} [{self.unit}]" if self.unit else self.name

    def format(self, value: float) -> str:
        """``value`` with this metric's decimals and unit ("1.234 px"); "n/a" for a missing value."""
        if value is None or (isinstance(value, float) and math.isnan(value)):
            return "n/a"
        value = float(value)
        text = (str(value) if not math.isfinite(value) else f"{value:.3e}" if abs(value) >= HUGE
                else f"{value:.{self.decimals}f}")
        return f"{text} {self.unit}" if self.unit else text


#: The pixels every disparity figure is computed over, and how a missing estimate counts.
EVALUATED = ("Over the pixels with finite, positive ground truth; e = |d - gt|. EPE, PEP: a pixel "
             "without an estimate counts as d = 0 (an error of gt); the KITTI and Middlebury figures "
             "treat such holes as their benchmark's own code does (see each definition).")
#: What the two pixel sets of the benchmark figures are.
PIXEL_SETS = ("(all) = every pixel with ground truth; (non-occ.) = those inside the non-occlusion "
              "mask (KITTI disp_noc, whose own values are the ground truth there; Middlebury mask0nocc); no mask: "
              "the (non-occ.) figures are empty.")
#: How the per-family and overall rows are made.
MEANS = ("Means: plain means of the per-pair values over the ok pairs that have the value; "
         "failed pairs are listed, never averaged in.")

_MASK_NAMES = {"all": "all", "noc": "non-occ."}

#: How KITTI's devkit fills holes before it counts D1 (io_disp.h, interpolateBackground).
KITTI_FILL = ("holes (no estimate, or d <= 0: a 0 in KITTI's PNG) are first filled as the KITTI devkit "
              "does: in each row a gap takes the smaller of its two neighbours, the row's ends its first "
              "and last estimate, then empty rows at the top and bottom the nearest filled row (an empty "
              "row between filled ones stays d = -1)")
#: How the Middlebury SDK counts holes (evaldisp.cpp).
MIDDLEBURY_HOLES = ("a hole (no estimate) is in the total but not bad (the SDK's totbad = bad + invalid); "
                    "estimates below 0 count as 0, as in the SDK")
#: Which pixels the Middlebury error statistics average over.
MIDDLEBURY_VALID = ("over the pixels with an estimate (holes left out, as the Middlebury SDK's avgErr does; "
                    "their share is invalid)")


def _benchmark_metrics() -> dict[str, Metric]:
    """The KITTI/Middlebury figures of :func:`d3cli.evaluation.metrics.benchmark_metrics`."""
    out: dict[str, Metric] = {}
    for mask, where in _MASK_NAMES.items():
        out[f"d1_{mask}"] = Metric(f"D1 ({where})", "%", 2, (
            f"KITTI devkit outliers: {KITTI_FILL}; then 100 x share of the pixels with e > {D1_PIXELS:g} px "
            f"and e > {100 * D1_RELATIVE:g} % of gt."))
        for t in BAD_THRESHOLDS:
            out[f"bad_{t:g}_{mask}"] = Metric(f"bad {t:g} ({where})", "%", 2, (
                f"Middlebury SDK bad-{t:g}: 100 x share of the pixels with an estimate and e > {t:g} px, "
                f"among all the pixels: {MIDDLEBURY_HOLES}."))
        out[f"invalid_{mask}"] = Metric(f"invalid ({where})", "%", 2, (
            "Middlebury SDK invalid: 100 x share of the pixels without an estimate."))
        out[f"avgerr_{mask}"] = Metric(f"avg. error ({where})", "px", 3, (
            "Middlebury SDK avgErr: mean of e over the pixels with an estimate (holes left out; their share is "
            "invalid)."))
        out[f"rms_{mask}"] = Metric(f"RMS ({where})", "px", 3, f"Root of the mean of e squared, {MIDDLEBURY_VALID}.")
        for q in QUANTILES:
            k = round(q * 100)
            out[f"a{k}_{mask}"] = Metric(f"A{k} ({where})", "px", 3, (
                f"Error quantile: the smallest e with at least {k} % of the pixels at or below it, "
                f"{MIDDLEBURY_VALID}."))
    for part, what in (("bg", "background (KITTI object map 0)"), ("fg", "foreground (object map > 0)")):
        out[f"d1_{part}"] = Metric(f"D1 ({part})", "%", 2, f"D1 over the {what} pixels with ground truth.")
    return out


def _pixel_metrics() -> dict[str, Metric]:
    """EPE, PEP and density of :func:`d3cli.evaluation.metrics.disparity_errors`."""
    out = {"epe": Metric("EPE", "px", 3, (
        "End-point error: mean of e, over the non-occluded pixels where a mask exists, else all."))}
    for t in PEP_THRESHOLDS:
        out[pep_key(t)] = Metric(f"PEP {t:g}", "%", 2, (
            f"Percentage of error pixels: 100 x share of EPE's pixels with e > {t:g} px."))
    out["density"] = Metric("density", "%", 2, "100 x share of EPE's pixels that have an estimate.")
    return out


#: Every metric column: key -> :class:`Metric`.
METRICS: dict[str, Metric] = {
    **_pixel_metrics(),
    "mse": Metric("MSE", "", 2, (
        "Photometric: mean squared difference (0-255 scale) between the left image and the right "
        "image warped into the left view with the estimate, over the covered pixels.")),
    "psnr": Metric("PSNR", "dB", 2, "10 log10(255^2 / MSE)."),
    "ssim": Metric("SSIM", "", 4, (
        "Structural similarity of the left and the warped right image (Gaussian window, sigma 1.5), "
        "mean over the covered pixels.")),
    "coverage": Metric("coverage", "%", 2, (
        "100 x share of all pixels with an estimate whose match lies inside the right image.")),
    **_benchmark_metrics(),
    "time_s": Metric("time", "s", 2, (
        "Wall time of the pair in the run that made its map: reading, matching, writing and scoring.")),
}


#: Columns measured without ground truth (photometric scores, time).
WITHOUT_GT = frozenset({"mse", "psnr", "ssim", "coverage", "time_s"})


def pixels_note(keys) -> str:
    """What the definitions of ``keys`` rest on: :data:`EVALUATED` when a ground-truth
    column is among them, and :data:`PIXEL_SETS` when one is named "(all)" or "(non-occ.)";
    "" for columns that need neither."""
    keys = list(keys)
    parts = [EVALUATED] if any(key not in WITHOUT_GT for key in keys) else []
    if any("(all)" in metric(key).name or "(non-occ.)" in metric(key).name for key in keys):
        parts.append(PIXEL_SETS)
    return " ".join(parts)


def metric(key: str) -> Metric:
    """The :class:`Metric` of a column; an unknown key is its own name, with no unit or definition."""
    return METRICS.get(key) or Metric(key, "", 3, "")
