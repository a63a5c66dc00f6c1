"""Road inspection outputs: files of one pair, warnings, defects.csv, ``run --road-report``."""

import csv
import json

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from d3cli.cli import main
from d3cli.config import RoadConfig
from d3cli.data import formats as io
from d3cli.road.plane import seen_by_both
from d3cli.road.outputs import height_colour, road_report, write_defects_csv

from .scene import pothole_scene


def left_image(shape):
    rng = np.random.default_rng(0)
    return rng.integers(0, 255, shape, dtype=np.uint8)


ROAD = RoadConfig(report=True, sigma_disparity=0.05)


def test_pair_outputs_of_a_pothole(tmp_path):
    disp, cam, _ = pothole_scene()
    decided = np.isfinite(disp)
    items, warnings = road_report(tmp_path, left_image(disp.shape), disp, decided, cam, {}, ROAD)
    assert warnings == []
    height = io.read_pfm(tmp_path / "height.pfm")
    assert height.shape == disp.shape and height.min() == pytest.approx(-0.08, abs=2e-3)
    data = json.loads((tmp_path / "defects.json").read_text())
    assert data["road_like"] and data["plane"]["offset_m"] == pytest.approx(1.5, abs=1e-3)
    (d,) = data["defects"]
    assert d["kind"] == "pothole" and d == items[0]
    assert {"id", "centroid_px", "bbox_px", "centroid_m", "area_m2", "max_depth_mm", "mean_depth_mm",
            "volume_l", "decided_share", "low_confidence"} <= set(d)
    overlay = cv2.imread(str(tmp_path / "defects.png"))
    # The picture, then the legend strip below it.
    assert overlay.shape[1:] == (disp.shape[1], 3) and overlay.shape[0] > disp.shape[0]
    # The outline is drawn in red around the pothole, on its bounding box (+ line width).
    red = (overlay[: disp.shape[0], :, 2] >= 250) & (overlay[: disp.shape[0], :, :2] <= 5).all(axis=2)
    u0, v0, u1, v1 = d["bbox_px"]
    assert red[v0 - 2: v1 + 3, u0 - 2: u1 + 3].sum() > 50
    assert red[v0 - 2: v1 + 3, u0 - 2: u0 + 3].any() and red[v0 - 2: v1 + 3, u1 - 2: u1 + 3].any()
    colour = cv2.imread(str(tmp_path / "height_color.png"))
    assert colour.shape[0] == disp.shape[0] and colour.shape[1] > disp.shape[1]  # + the colour bar


def test_height_colour_is_diverging():
    h = np.array([[-0.05, 0.0, 0.05, np.inf]], np.float32).repeat(40, 0)
    img = height_colour(h, range_mm=50.0)[:, :4]
    assert tuple(img[0, 0]) == (0, 0, 255)  # RGB: deepest blue
    assert tuple(img[0, 1]) == (255, 255, 255)
    assert tuple(img[0, 2]) == (255, 0, 0)
    assert tuple(img[0, 3]) == (96, 96, 96)  # no estimate


def test_no_camera_gives_a_warning_and_no_files(tmp_path):
    disp, _, _ = pothole_scene(width=80, height=60, f=75.0)
    items, warnings = road_report(tmp_path, left_image(disp.shape), disp, np.isfinite(disp), None, {}, ROAD)
    assert items == [] and warnings[0].startswith("no road report: focal length or baseline unknown")
    assert list(tmp_path.iterdir()) == []


def test_pt_fallback_gives_heights_but_no_defects(tmp_path):
    disp, cam, _ = pothole_scene()
    items, warnings = road_report(tmp_path, left_image(disp.shape), disp, np.isfinite(disp), cam,
                                  {"pt": {"fallback": True}}, ROAD)
    # The pipeline's fallback warning says why; the report adds none and measures no defect.
    assert items == [] and warnings == []
    assert (tmp_path / "height.pfm").is_file()
    report = json.loads((tmp_path / "defects.json").read_text())
    assert report["defects"] == [] and report["warnings"][0].startswith("no road surface")


def test_few_decided_pixels_flag_every_defect(tmp_path):
    disp, cam, _ = pothole_scene()
    decided = np.zeros(disp.shape, bool)
    decided[::4] = True
    items, warnings = road_report(tmp_path, left_image(disp.shape), disp, decided, cam, {}, ROAD)
    assert items and all(d["low_confidence"] for d in items)
    assert any("few decided pixels" in w for w in warnings)


def test_defects_csv_lists_every_defect_of_every_pair(tmp_path):
    disp, cam, _ = pothole_scene()
    for name in ("a", "b"):
        (tmp_path / name).mkdir()
        road_report(tmp_path / name, left_image(disp.shape), disp, np.isfinite(disp), cam, {}, ROAD)
    (tmp_path / "c").mkdir()  # a pair without road outputs
    path = write_defects_csv(tmp_path, [tmp_path / n for n in ("a", "b", "c")])
    rows = list(csv.DictReader(path.open()))
    assert [r["pair"] for r in rows] == ["a", "b"]
    assert float(rows[0]["max_depth_mm"]) == pytest.approx(80, rel=0.03)
    assert write_defects_csv(tmp_path / "c", [tmp_path / "c"]) is None


def test_run_road_report_writes_the_outputs(tmp_path):
    runner = CliRunner()
    data = tmp_path / "synth"
    assert runner.invoke(main, ["synth", str(data), "--n", "1", "--seed", "2", "--width", "320",
                                "--height", "192", "-q"]).exit_code == 0
    out = tmp_path / "out"
    result = runner.invoke(main, ["run", str(data), "-o", str(out), "--method", "sgbm", "--road-report", "-q"])
    assert result.exit_code == 0, result.output
    (pair_dir,) = [p for p in out.iterdir() if p.is_dir()]
    for name in ("height.pfm", "height_color.png", "defects.json", "defects.png"):
        assert (pair_dir / name).is_file(), name
    assert (out / "defects.csv").read_text().startswith("pair,id,kind")
    # The road plane is about the synthetic camera height below the camera.
    calib = io.read_calib(data / pair_dir.name / "calib.txt")
    plane = json.loads((pair_dir / "defects.json").read_text())["plane"]
    assert plane["offset_m"] == pytest.approx(float(calib["height_m"]), rel=0.05)


def test_run_without_camera_warns(tmp_path, make_pair_folder):
    root = tmp_path / "pairs"
    make_pair_folder(root, "p", shift=6)
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["run", str(root), "-o", str(out), "--method", "sgbm", "--road-report", "-q"])
    assert result.exit_code == 0, result.output
    assert not (out / "p" / "height.pfm").exists()
    warnings = json.loads((out / "p" / "result.json").read_text())["warnings"]
    assert any(w.startswith("no road report") for w in warnings)


def test_left_border_strip_is_no_estimate_and_holds_no_defects(tmp_path):
    # Left of u = d the right camera does not see the point: the hole filling extrapolates
    # there.  Make that strip 3 px too large (a 'high' streak): before the fix it was
    # reported as a bump; now the strip is no estimate and only the pothole is left.
    disp, cam, _ = pothole_scene()
    u = np.arange(disp.shape[1])[None, :]
    strip = u < disp
    assert 0.05 < strip.mean() < 0.2
    streaked = np.where(strip, disp + 3.0, disp).astype(np.float32)
    items, _ = road_report(tmp_path, left_image(disp.shape), streaked, ~strip, cam, {}, ROAD)
    height = io.read_pfm(tmp_path / "height.pfm")
    assert np.isinf(height[strip]).all() and np.isfinite(height[~strip]).all()
    (d,) = items  # only the real pothole, right of the strip
    assert d["bbox_px"][0] > strip.sum(axis=1).max()
    assert d["max_depth_mm"] == pytest.approx(80, rel=0.03)
    assert seen_by_both(np.array([[5.0, 0.5, np.inf, 2.0]], np.float32)).tolist() == [[False, True, False, True]]
    # the road model's right-image rule: half a pixel of slack (the first right pixel's area), finite only
    assert seen_by_both(np.array([[0.5, 1.75, -np.inf, np.nan]], np.float32)).tolist() == [[True, False, False, False]]
