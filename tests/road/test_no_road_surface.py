"""A frame that is not a road: the road report says so, lists no defects and adds no
second warning to the fallback's own."""

from __future__ import annotations

import json

import numpy as np
from click.testing import CliRunner

from d3cli.cli import main, samples_dir
from d3cli.config import RoadConfig
from d3cli.road.outputs import road_report

from .scene import pothole_scene

ROAD = RoadConfig(report=True, sigma_disparity=0.05)


def test_report_of_a_fallback_pair_says_no_road_surface_without_a_warning(tmp_path):
    disp, cam, _ = pothole_scene()
    left = np.random.default_rng(0).integers(0, 255, disp.shape, dtype=np.uint8)
    reason = "7.4% of the pixels lie more than 8 px of disparity off the fitted plane (> 3.0%)"
    items, warnings = road_report(tmp_path, left, disp, np.isfinite(disp), cam,
                                  {"pt": {"fallback": True, "reason": reason}}, ROAD)
    assert items == [] and warnings == []
    data = json.loads((tmp_path / "defects.json").read_text())
    assert data["road_like"] is False and data["defects"] == []
    assert data["warnings"] == [f"no road surface: {reason}; no defects measured"]
    assert (tmp_path / "height.pfm").is_file() and (tmp_path / "defects.png").is_file()


def test_motorcycle_with_the_road_config_falls_back_with_one_warning_and_no_bump(tmp_path):
    """The bundled Motorcycle sample (indoor) with ``-c road``: the coarse fit takes a plane
    (89 % inliers), 7.4 % of the pixels match at the ends of the narrow band, so it falls
    back, with default.yaml's settings: the defaults' EPE (0.910 px; 2.465 with PT,
    1.734 over the full range with road.yaml's settings) and no "+648 mm bump"."""
    pair = samples_dir() / "motorcycle"
    road_out, plain_out = tmp_path / "road", tmp_path / "plain"
    runner = CliRunner()
    road = runner.invoke(main, ["run", str(pair), "-o", str(road_out), "-c", "road", "--eval", "--road-report",
                                "--backend", "cpu"])
    assert road.exit_code == 0, road.output
    plain = runner.invoke(main, ["run", str(pair), "-o", str(plain_out), "--eval", "--backend", "cpu", "-q"])
    assert plain.exit_code == 0, plain.output
    result = json.loads((road_out / "motorcycle" / "result.json").read_text())
    (warning,) = result["warnings"]
    assert warning.startswith("perspective transformation skipped: ") and "default.yaml" in warning
    assert result["info"]["pt"]["fallback"] is True
    epe = result["metrics"]["epe"]
    epe_default = json.loads((plain_out / "motorcycle" / "result.json").read_text())["metrics"]["epe"]
    assert epe <= 1.05 * epe_default
    defects = json.loads((road_out / "motorcycle" / "defects.json").read_text())
    assert defects["defects"] == [] and defects["warnings"][0].startswith("no road surface: ")
