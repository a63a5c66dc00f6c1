"""scripts/bench_road.py: the match rule and the what-if decided-share filter."""

import importlib.util
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

_spec = importlib.util.spec_from_file_location("bench_road", Path(__file__).parents[2] / "scripts" / "bench_road.py")
bench_road = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bench_road)


def _square(u0, v0, u1, v1):
    return [[[u0, v0], [u1, v0], [u1, v1], [u0, v1]]]


def test_fragment_with_low_decided_share_is_a_duplicate_unless_filtered(tmp_path):
    gt, out = tmp_path / "gt", tmp_path / "out"
    gt.mkdir()
    out.mkdir()
    ids = np.zeros((100, 100), np.uint8)
    ids[20:80, 20:80] = 1  # one 60 x 60 px pothole, 40 mm deep
    cv2.imwrite(str(gt / "potholes_gt.png"), ids)
    (gt / "defects_gt.json").write_text(json.dumps({"potholes": [
        {"id": 1, "depth_mm": 40.0, "area_m2": 0.1, "volume_l": 2.0, "visible_px": 3600}]}))
    common = {"kind": "pothole", "area_m2": 0.09, "volume_l": 1.8}
    (out / "defects.json").write_text(json.dumps({"defects": [
        {**common, "id": 1, "bbox_px": [20, 20, 79, 79], "outline_px": _square(20, 20, 79, 79),
         "max_depth_mm": 38.0, "decided_share": 0.9},
        # a fragment on the wet floor, mostly filled pixels, far too deep
        {**common, "id": 2, "bbox_px": [30, 30, 45, 45], "outline_px": _square(30, 30, 45, 45),
         "max_depth_mm": 120.0, "decided_share": 0.3}]}))
    flat = np.where(ids > 0, 40.0, 0.0)
    r = bench_road.score_pair(gt, out, min_gt_depth_mm=20, depth_mm=flat)
    assert (r["found"], r["duplicates"], r["false"]) == (1, 1, 0)
    r = bench_road.score_pair(gt, out, min_gt_depth_mm=20, min_decided_share=0.5, depth_mm=flat)
    assert (r["found"], r["duplicates"], r["false"], r["predicted"]) == (1, 0, 0, 1)
    assert r["errors"][0]["depth"] == abs(38.0 - 40.0) / 40.0
    # Per family: the entry without a shape is a classic pothole.
    (classic, overall) = bench_road.family_table([r])
    assert classic == {"family": "classic", "gt": 1, "found": 1, "recall": 1.0, "depth": 0.05,
                       "signed_depth": -0.05, "area": pytest.approx(0.1), "volume": pytest.approx(0.1)}
    assert {**overall, "family": "classic"} == classic


def _cone(shape, centre, radius_px, depth_mm):
    """Ids (1 where deeper than 1 mm) and depth (mm) of a cone pothole."""
    v, u = np.mgrid[0:shape[0], 0:shape[1]]
    depth = depth_mm * np.clip(1.0 - np.hypot(u - centre[0], v - centre[1]) / radius_px, 0.0, None)
    return depth


def _disc(centre, radius):
    """outline_px polygon of a disc (64 vertices)."""
    a = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    return [[[float(centre[0] + radius * np.cos(t)), float(centre[1] + radius * np.sin(t))] for t in a]]


def _pit(outline, **extra):
    return {"kind": "pothole", "outline_px": outline, "bbox_px": [0, 0, 1, 1], **extra}


def test_a_shallow_cone_outlined_at_the_report_threshold_is_found():
    # A 20 mm cone: its part deeper than 10 mm is the inner half of the radius, a quarter of
    # its > 1 mm footprint. A detection outlining exactly that part is a correct report;
    # the footprint rule (30 % of the footprint) called it a miss.
    depth = _cone((200, 200), (100, 100), 80, 20.0)
    ids = (depth > 1.0).astype(np.uint8)
    pits = [_pit(_disc((100, 100), 40))]
    hits, dup, false = bench_road.match_deep(ids, depth, pits, threshold_mm=10.0)
    assert (list(hits), dup, false) == ([1], 0, 0)
    hits, dup, false = bench_road.match_potholes(ids, pits, min_inside=0.5, min_cover=0.3)
    assert (list(hits), dup, false) == ([], 1, 0)


def test_deep_part_or_deepest_point_and_one_to_one():
    depth = _cone((200, 200), (100, 100), 80, 40.0)  # deep part: radius 60 px
    ids = (depth > 1.0).astype(np.uint8)
    # 20 % of the deep part, off the deepest point: a fragment, not a match.
    off_centre = [_pit(_disc((100, 145), 13))]
    assert bench_road.match_deep(ids, depth, off_centre, threshold_mm=10.0)[1:] == (1, 0)
    assert bench_road.match_deep(ids, depth, off_centre, threshold_mm=10.0)[0] == {}
    # A small detection on the deepest point matches; of two matching detections the one
    # covering more of the deep part is the match, the other a duplicate.
    small, large = _pit(_disc((100, 100), 10), id=1), _pit(_disc((100, 100), 50), id=2)
    hits, dup, false = bench_road.match_deep(ids, depth, [small, large], threshold_mm=10.0)
    assert (hits[1]["id"], dup, false) == (2, 1, 0)
    # Mostly road (less than half on pothole pixels): a false defect even over the deepest point.
    huge = _pit(_disc((100, 100), 150))
    assert bench_road.match_deep(ids, depth, [huge], threshold_mm=10.0) == ({}, 0, 1)


def test_a_detection_joined_over_two_potholes_counts_for_the_one_holding_most_of_it():
    a = _cone((200, 300), (90, 100), 60, 40.0)
    b = _cone((200, 300), (200, 100), 50, 30.0)
    ids = np.where(a > 1.0, 1, np.where(b > 1.0, 2, 0)).astype(np.uint8)
    depth = np.maximum(a, b)
    joined = [_pit([[[40, 60], [240, 60], [240, 140], [40, 140]]])]
    hits, dup, false = bench_road.match_deep(ids, depth, joined, threshold_mm=10.0)
    assert (list(hits), dup, false) == ([1], 0, 0)
