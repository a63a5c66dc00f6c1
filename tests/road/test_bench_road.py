"""scripts/bench_road.py: the what-if decided-share filter (duplicate fragments of one pothole)."""

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
    r = bench_road.score_pair(gt, out, min_gt_depth_mm=20)
    assert (r["found"], r["duplicates"], r["false"]) == (1, 1, 0)
    r = bench_road.score_pair(gt, out, min_gt_depth_mm=20, min_decided_share=0.5)
    assert (r["found"], r["duplicates"], r["false"], r["predicted"]) == (1, 0, 0, 1)
    assert r["errors"][0]["depth"] == abs(38.0 - 40.0) / 40.0
    # Per family: the entry without a shape is a classic pothole.
    (classic, overall) = bench_road.family_table([r])
    assert classic == {"family": "classic", "gt": 1, "found": 1, "recall": 1.0, "depth": 0.05,
                       "signed_depth": -0.05, "area": pytest.approx(0.1), "volume": pytest.approx(0.1)}
    assert {**overall, "family": "classic"} == classic
