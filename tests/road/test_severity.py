"""ASTM D6433 pothole severity and the survey summary (d3cli.road.severity)."""

import csv
import json
import math

import numpy as np
import pytest

from d3cli.config import RoadConfig
from d3cli.road.outputs import road_report, write_defects_csv
from d3cli.road.severity import pothole_severity, survey_summary

from .scene import pothole_scene


def area(diameter_mm):
    return math.pi * (diameter_mm / 2e3) ** 2


@pytest.mark.parametrize("depth, diameter, level", [
    (20, 150, "low"), (20, 300, "low"), (20, 600, "medium"),
    (40, 150, "low"), (40, 300, "medium"), (40, 600, "high"),
    (60, 150, "medium"), (60, 300, "medium"), (60, 600, "high"),
    (12.9, 300, None), (40, 99, None),
])
def test_the_standards_table(depth, diameter, level):
    s = pothole_severity(depth, area(diameter))
    assert s["severity"] == level and s["diameter_mm"] == pytest.approx(diameter, abs=0.1)
    assert s["equivalent_potholes"] == (1.0 if level else 0.0)


def test_wider_than_750_mm_counts_by_area():
    assert pothole_severity(20, 1.0) == {"diameter_mm": 1128.4, "severity": "medium", "equivalent_potholes": 2.0}
    assert pothole_severity(30, 1.0)["severity"] == "high"


def test_survey_counts_per_frame_and_per_km():
    per_pair = {"a": [{"kind": "pothole", "severity": "low", "equivalent_potholes": 1.0},
                      {"kind": "bump", "low_confidence": True, "flags": ["specular", "noisy"]}],
                "b": [{"kind": "pothole", "severity": "high", "equivalent_potholes": 2.0},
                      {"kind": "pothole", "severity": None}],
                "c": []}
    assert survey_summary(per_pair, frame_spacing_m=5.0) == {
        "frames": 3, "potholes": 3, "bumps": 1, "low_confidence": 1,
        "flagged_by_reason": {"noisy": 1, "specular": 1},
        "by_severity": {"low": 1.0, "medium": 0.0, "high": 2.0, "none": 1}, "potholes_per_frame": 1.0,
        "frame_spacing_m": 5.0, "length_km": 0.015, "potholes_per_km": 200.0}
    assert "potholes_per_km" not in survey_summary(per_pair)


def test_defects_json_csv_and_survey_carry_the_severity(tmp_path):
    # 80 mm deep paraboloid of radius 0.3 m: the area deeper than 10 mm is a circle of
    # 0.3 sqrt(1 - 10/80) m radius, 561 mm across: high.
    disp, cam, _ = pothole_scene()
    (tmp_path / "a").mkdir()
    (d,), _ = road_report(tmp_path / "a", np.zeros(disp.shape, np.uint8), disp, np.isfinite(disp), cam, {},
                          RoadConfig(report=True, sigma_disparity=0.05))
    assert d["severity"] == "high" and d["diameter_mm"] == pytest.approx(561, rel=0.03)
    write_defects_csv(tmp_path, [tmp_path / "a"], frame_spacing_m=10.0)
    (row,) = list(csv.DictReader((tmp_path / "defects.csv").open()))
    assert row["severity"] == "high"
    survey = json.loads((tmp_path / "road_survey.json").read_text())
    assert (survey["potholes"], survey["by_severity"]["high"], survey["potholes_per_km"]) == (1, 1.0, 100.0)
