"""One defect for every sighting of it: detections of the same pothole in overlapping frames.

**Rule.**  Two sightings are of the same defect when they are of the same kind (pothole,
bump), come from different frames, and either their centroids lie within
``road.merge_distance_m`` of each other or their outlines overlap by at least
:data:`MIN_OVERLAP` of the smaller outline's area.  Distances and areas are measured in a
local metric plane (an azimuthal equidistant projection centred on the track,
:func:`d3cli.survey.gis.local_projection`).  Sameness is transitive (union-find): when A is
B and B is C, A, B and C are one defect even if A and C are farther apart.  Two defects of
one frame are never joined directly (the frame's own measurement separated them); only a
sighting that is the same as both joins them.

**Best sighting.**  A merged defect takes its depth, area, volume, severity and confidence
from its best-measured sighting: confidence ``ok`` beats ``low``; among equals, the higher
score ``decided pixels / (range / 1 m)^2`` wins, where decided pixels = the sighting's
``decided_share`` x the pixel area of its outline and range = its depth along the camera's
optical axis (at least 0.5 m).  More decided pixels mean a depth measured rather than
filled; the range squared is the growth of stereo depth error with distance.  Ties go
to the earlier frame.  Its outline and centroid are the best sighting's too; ``spread_m``
says how far the other sightings' centroids lie from it.
"""

from __future__ import annotations

import math

import numpy as np

#: Outlines of one defect overlap by at least this share of the smaller outline's area.
MIN_OVERLAP = 0.25
#: Ranges below this (metres) count as this in the score.
MIN_RANGE_M = 0.5


def pixel_area(outline_px) -> float:
    """Area (pixels) of a defects.json ``outline_px`` (a list of polygons, shoelace)."""
    total = 0.0
    for poly in outline_px or []:
        p = np.asarray(poly, np.float64).reshape(-1, 2)
        if len(p) >= 3:
            total += 0.5 * abs(float(np.dot(p[:, 0], np.roll(p[:, 1], -1)) - np.dot(p[:, 1], np.roll(p[:, 0], -1))))
    return total


def score(sighting: dict) -> float:
    """The best-sighting score (module docstring) of a sighting."""
    decided_px = float(sighting.get("decided_share") or 0.0) * max(pixel_area(sighting.get("outline_px")), 1.0)
    return decided_px / max(float(sighting.get("range_m") or 0.0), MIN_RANGE_M) ** 2


def _rank(s: dict) -> tuple:
    """Sort key of the best sighting (smallest first)."""
    return (s.get("confidence", "ok") != "ok", -s["score"], s["order"])


class _Sets:
    def __init__(self, n: int):
        self.parent = list(range(n))

    def find(self, i: int) -> int:
        while self.parent[i] != i:
            self.parent[i] = self.parent[self.parent[i]]
            i = self.parent[i]
        return i

    def union(self, i: int, j: int) -> None:
        a, b = self.find(i), self.find(j)
        if a != b:
            self.parent[max(a, b)] = min(a, b)


def same_defect(a: dict, b: dict, *, distance_m: float) -> bool:
    """Whether sightings ``a`` and ``b`` (with ``xy``, shapely ``shape`` in the local plane)
    are of the same defect by the module's rule (without the transitive closure)."""
    if a["kind"] != b["kind"] or a["frame"] == b["frame"]:
        return False
    if math.dist(a["xy"], b["xy"]) <= distance_m:
        return True
    sa, sb = a.get("shape"), b.get("shape")
    if sa is None or sb is None or sa.is_empty or sb.is_empty or not sa.intersects(sb):
        return False
    smaller = min(sa.area, sb.area)
    return smaller > 0 and sa.intersection(sb).area >= MIN_OVERLAP * smaller


def merge_sightings(sightings: list[dict], *, distance_m: float) -> list[list[dict]]:
    """Group sightings into defects (module docstring).

    Parameters
    ----------
    sightings : list of dict
        Each with ``frame``, ``kind``, ``xy`` (centroid, metres in the local plane),
        ``shape`` (the outline as a shapely polygon in that plane, or None), ``order``
        (the frame's place in the drive) and the defects.json fields the score reads
        (``decided_share``, ``outline_px``, ``range_m``, ``confidence``).
    distance_m : float, keyword-only
        ``road.merge_distance_m``.

    Returns
    -------
    list of list of dict
        One list per defect, best sighting first (its ``score`` set on every sighting);
        defects in the order of their first sighting in the drive.
    """
    from shapely import STRtree
    from shapely.geometry import Point

    for s in sightings:
        s["score"] = score(s)
    n = len(sightings)
    sets = _Sets(n)
    if n > 1:
        footprints = [s["shape"] if s.get("shape") is not None and not s["shape"].is_empty else Point(s["xy"])
                      for s in sightings]
        tree = STRtree(footprints)
        for i, s in enumerate(sightings):
            for j in tree.query(footprints[i].buffer(distance_m)):
                j = int(j)
                if j > i and same_defect(s, sightings[j], distance_m=distance_m):
                    sets.union(i, j)
    groups: dict[int, list[dict]] = {}
    for i, s in enumerate(sightings):
        groups.setdefault(sets.find(i), []).append(s)
    out = [sorted(g, key=_rank) for g in groups.values()]
    out.sort(key=lambda g: min((s["order"], s.get("id", 0)) for s in g))
    return out
