"""Merging sightings of one defect: hand-made sightings in a local metric plane."""

from __future__ import annotations

import pytest

pytest.importorskip("shapely")

from shapely.geometry import Point  # noqa: E402

from d3cli.survey.merge import merge_sightings, score  # noqa: E402


def sighting(frame, order, x, y, *, kind="pothole", r=0.15, range_m=5.0, decided=0.9, confidence="ok", i=1):
    side = 40.0 * 5.0 / range_m  # its pixel outline shrinks with the range
    return {"frame": frame, "order": order, "id": i, "kind": kind, "xy": (x, y), "shape": Point(x, y).buffer(r),
            "range_m": range_m, "decided_share": decided, "confidence": confidence,
            "outline_px": [[[0, 0], [side, 0], [side, side], [0, side]]]}


def test_the_same_pothole_in_three_frames_is_one_defect_with_three_sightings():
    s = [sighting("f0", 0, 0.00, 0.00, range_m=9.0), sighting("f1", 1, 0.08, -0.05, range_m=4.0),
         sighting("f2", 2, -0.06, 0.04, range_m=6.5)]
    [group] = merge_sightings(s, distance_m=0.3)
    assert len(group) == 3
    assert group[0]["frame"] == "f1"  # the nearest: most decided pixels, least depth error


def test_two_nearby_distinct_potholes_stay_two():
    s = []
    for k, frame in enumerate(["f0", "f1", "f2"]):
        jitter = 0.03 * (k - 1)
        s += [sighting(frame, k, 0.0 + jitter, 0.0, r=0.12, i=1), sighting(frame, k, 0.55 - jitter, 0.0, r=0.12, i=2)]
    groups = merge_sightings(s, distance_m=0.3)
    assert sorted(len(g) for g in groups) == [3, 3]
    assert all(len({x["frame"] for x in g}) == 3 for g in groups)


def test_kinds_and_frames_are_never_merged_directly():
    s = [sighting("f0", 0, 0.0, 0.0), sighting("f1", 1, 0.1, 0.0, kind="bump"),
         sighting("f0", 0, 0.1, 0.0, i=2)]
    assert sorted(len(g) for g in merge_sightings(s, distance_m=0.3)) == [1, 1, 1]


def test_chains_are_one_defect():
    # A ~ B and B ~ C by distance, A and C 0.5 m apart: one defect (union-find).
    s = [sighting("f0", 0, 0.0, 0.0, r=0.05), sighting("f1", 1, 0.25, 0.0, r=0.05),
         sighting("f2", 2, 0.5, 0.0, r=0.05)]
    [group] = merge_sightings(s, distance_m=0.3)
    assert len(group) == 3


def test_overlapping_outlines_merge_beyond_the_distance():
    # A long crack-like pothole: centroids 0.6 m apart, outlines overlapping by most of the smaller.
    from shapely.geometry import box

    a, b = sighting("f0", 0, 0.0, 0.0), sighting("f1", 1, 0.6, 0.0)
    a["shape"], b["shape"] = box(-0.8, -0.1, 0.8, 0.1), box(0.0, -0.1, 1.2, 0.1)
    assert len(merge_sightings([a, b], distance_m=0.3)) == 1
    b["shape"] = box(0.7, -0.1, 1.2, 0.1)  # touching at a sliver: 0.1 of 0.5 m overlap, 20 % of the smaller
    assert len(merge_sightings([a, b], distance_m=0.3)) == 2


def test_the_best_sighting_is_ok_before_low_then_the_highest_score():
    near_low = sighting("f0", 0, 0.0, 0.0, range_m=3.0, confidence="low")
    far_ok = sighting("f1", 1, 0.05, 0.0, range_m=8.0)
    mid_ok = sighting("f2", 2, 0.0, 0.05, range_m=6.0, decided=0.1)
    [group] = merge_sightings([near_low, far_ok, mid_ok], distance_m=0.3)
    assert [g["frame"] for g in group] == ["f1", "f2", "f0"]
    assert score(far_ok) == pytest.approx(0.9 * 25.0 ** 2 / 64.0)
    assert score(mid_ok) == pytest.approx(0.1 * (200 / 6) ** 2 / 36.0) and score(mid_ok) < score(far_ok)
