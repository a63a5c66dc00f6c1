"""The bundled road sample shows the road report: calibrated, one pothole measured."""

import json

import pytest
from click.testing import CliRunner

from d3cli.cli import main


def test_road_report_on_the_bundled_samples_measures_the_pothole(tmp_path):
    # The sample (scripts/make_samples.py, synth seed 2035): a bowl 51.7 mm deep,
    # 0.128 m^2 deeper than 10 mm, 4.47 l.  SGBM keeps the test fast.
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["run", "-o", str(out), "--method", "sgbm", "--road-report", "-q"])
    assert result.exit_code == 0, result.output
    data = json.loads((out / "road" / "defects.json").read_text())
    assert data["warnings"] == []
    (pothole,) = [d for d in data["defects"] if d["kind"] == "pothole"]
    assert pothole["max_depth_mm"] == pytest.approx(51.7, rel=0.2)
    assert pothole["area_m2"] == pytest.approx(0.128, rel=0.2)
    assert pothole["volume_l"] == pytest.approx(4.47, rel=0.2)
    assert pothole["severity"] == "medium"
    # SGBM's map is noisy around the pothole (spikes on the floor, a depth 7.5x the height
    # noise around it: without the right image the specular and noisy flags would be
    # raised) and reads the depth 13 % deep,
    # within the 20 % an ok defect must meet; the sample's texture supports the match
    # clearly (match margin 0.17), so it is ok, with the numbers behind it.
    assert pothole["evidence"]["snr"] < 10 and pothole["evidence"]["spikiness"] > 1.1
    assert pothole["evidence"]["match_margin"] > 0.1
    # No re-match window is clean on SGBM's noisy map: the depth is the stored map's.
    assert (pothole["evidence"]["rematch_window"], pothole["evidence"]["rematch_change"]) == (0, 0.0)
    # SGBM's 5 px block averages 2 px around a pixel: the pothole is far wider, not narrow
    assert pothole["evidence"]["averaging_px"] == 2 and pothole["evidence"]["inscribed_px"] > 10
    assert (pothole["flags"], pothole["confidence"], pothole["low_confidence"]) == ([], "ok", False)
    assert pothole["reasons"] == ""
