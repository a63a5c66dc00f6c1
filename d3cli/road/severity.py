"""Pothole severity as road agencies grade it, and the survey summary of a batch.

Severity levels of ASTM D6433-20 ("Standard Practice for Roads and Parking Lots Pavement
Condition Index Surveys"), distress 13 *Potholes* (asphalt surfaced roads), from the
maximum depth and the average diameter:

======================  ==============  ==============  ==============
max depth \\ diameter    100-200 mm      >200-450 mm     >450-750 mm
======================  ==============  ==============  ==============
13-25 mm                low             low             medium
>25-50 mm               low             medium          high
>50 mm                  medium          medium          high
======================  ==============  ==============  ==============

A pothole wider than 750 mm is measured by area: ``area / 0.5 m^2`` equivalent potholes,
medium when at most 25 mm deep, high when deeper.  Shallower than 13 mm or narrower than
100 mm it is no pothole of the standard (severity None).  The diameter here is that of the
circle with the defect's plane area (``area_m2``, the opening deeper than
``road.min_depth_mm``).
"""

from __future__ import annotations

import math

_DIAMETERS_MM = (100.0, 200.0, 450.0, 750.0)
_TABLE = {  # depth band -> level per diameter band (100-200, >200-450, >450-750)
    0: ("low", "low", "medium"),
    1: ("low", "medium", "high"),
    2: ("medium", "medium", "high"),
}


def pothole_severity(max_depth_mm: float, area_m2: float) -> dict:
    """ASTM D6433 severity of one pothole (module docstring).

    Parameters
    ----------
    max_depth_mm : float
        Maximum depth below the surrounding surface, mm.
    area_m2 : float
        Plane area of the opening, m^2.

    Returns
    -------
    dict
        ``diameter_mm`` (equivalent circle), ``severity`` ("low", "medium", "high" or None)
        and ``equivalent_potholes`` (1, ``area / 0.5 m^2`` above 750 mm, 0 when None).
    """
    diameter = 2e3 * math.sqrt(max(area_m2, 0.0) / math.pi)
    out = {"diameter_mm": round(diameter, 1), "severity": None, "equivalent_potholes": 0.0}
    if max_depth_mm < 13.0 or diameter < _DIAMETERS_MM[0]:
        return out
    if diameter > _DIAMETERS_MM[3]:
        return {**out, "severity": "medium" if max_depth_mm <= 25.0 else "high",
                "equivalent_potholes": round(area_m2 / 0.5, 2)}
    depth_band = 0 if max_depth_mm <= 25.0 else 1 if max_depth_mm <= 50.0 else 2
    diameter_band = 0 if diameter <= _DIAMETERS_MM[1] else 1 if diameter <= _DIAMETERS_MM[2] else 2
    return {**out, "severity": _TABLE[depth_band][diameter_band], "equivalent_potholes": 1.0}


def survey_summary(per_pair: dict, *, frame_spacing_m: float = 0.0) -> dict:
    """Counts over a batch of frames: potholes per severity, per frame and per km.

    Parameters
    ----------
    per_pair : dict
        Pair name -> its defects (defects.json items).
    frame_spacing_m : float, keyword-only
        Distance driven between frames, metres (``road.frame_spacing_m``); 0: unknown, no
        per-km figures.

    Returns
    -------
    dict
        ``frames``, ``potholes``, ``bumps``, ``low_confidence`` (defects flagged),
        ``flagged_by_reason`` (reason code -> defects with it), ``by_severity``
        (low/medium/high/none: equivalent potholes), ``potholes_per_frame`` and, with a
        spacing, ``length_km`` and ``potholes_per_km``.
    """
    frames = len(per_pair)
    items = [d for ds in per_pair.values() for d in ds]
    pits = [d for d in items if d.get("kind") == "pothole"]
    by = {"low": 0.0, "medium": 0.0, "high": 0.0, "none": 0}
    for d in pits:
        level = d.get("severity")
        if level is None:
            by["none"] += 1
        else:
            by[level] = round(by[level] + float(d.get("equivalent_potholes", 1.0)), 2)
    out = {"frames": frames, "potholes": len(pits), "bumps": sum(d.get("kind") == "bump" for d in items),
           "low_confidence": sum(bool(d.get("low_confidence")) for d in items),
           "flagged_by_reason": _by_reason(items), "by_severity": by,
           "potholes_per_frame": round(len(pits) / frames, 3) if frames else 0.0}
    if frame_spacing_m > 0 and frames:
        km = frames * frame_spacing_m / 1e3
        out.update(frame_spacing_m=frame_spacing_m, length_km=round(km, 4), potholes_per_km=round(len(pits) / km, 2))
    return out


def _by_reason(items: list) -> dict:
    """Reason code -> number of flagged defects with it (a defect counts once per reason)."""
    counts: dict = {}
    for d in items:
        if d.get("low_confidence"):
            for code in d.get("flags", []):
                counts[code] = counts.get(code, 0) + 1
    return dict(sorted(counts.items(), key=lambda kv: (-kv[1], kv[0])))
