"""The measuring grid (d3cli.road.grid): cells, their camera, the maps down to the grid, the
defects back to the image's pixels, and a report on the grid measuring as one on the pixels."""

import numpy as np
import pytest

from d3cli.config import RoadConfig
from d3cli.road import grid as grid_module
from d3cli.road.confidence import ConfidenceRules
from d3cli.road.defects import Defect, DefectTuning, outline
from d3cli.road.grid import Grid, grid_step
from d3cli.road.outputs import road_report
from d3cli.road.plane import RoadPlane, height_map
from d3cli.road.pointcloud import Camera

from .scene import pothole_scene


def _cell_means_reference(values, decided, step):
    """NumPy: each cell's mean of its finite values where at least half of its pixels have
    one, decided where at least half of those are decided."""
    h, w = values.shape
    rows, cols = -(-h // step), -(-w // step)
    out = np.full((rows, cols), np.inf, np.float32)
    out_decided = np.zeros((rows, cols), bool)
    for i in range(rows):
        for j in range(cols):
            block = values[i * step:(i + 1) * step, j * step:(j + 1) * step]
            finite = np.isfinite(block)
            if finite.sum() and 2 * finite.sum() >= block.size:
                out[i, j] = block[finite].astype(np.float64).mean()
                good = decided[i * step:(i + 1) * step, j * step:(j + 1) * step][finite]
                out_decided[i, j] = 2 * good.sum() >= finite.sum()
    return out, out_decided


def test_the_step_keeps_at_least_grid_columns_cells():
    assert grid_step((720, 1280)) == 2
    assert grid_step((375, 1242)) == 1  # KITTI: measured on its pixels
    assert grid_step((1080, 1920)) == 3
    assert grid_step((96, 160)) == 1
    assert Grid.for_shape((721, 1283)).cells == (361, 642)


@pytest.mark.parametrize("shape, step", [((37, 52), 2), ((36, 51), 3), ((20, 40), 2)])
def test_cell_disparities_are_the_means_of_their_finite_pixels(shape, step):
    rng = np.random.default_rng(3)
    disparity = (rng.random(shape) * 40).astype(np.float32)
    finite = rng.random(shape) > 0.3
    finite[:step, :step] = [[True] + [False] * (step - 1)] + [[False] * step] * (step - 1)  # 1 of s^2: no value
    decided = rng.random(shape) > 0.4
    grid = Grid.for_shape(shape, step)
    cells, cells_decided = grid.disparities(disparity, finite, decided)
    ref, ref_decided = _cell_means_reference(np.where(finite, disparity, np.inf).astype(np.float32), decided, step)
    assert np.isinf(cells[0, 0])
    np.testing.assert_allclose(cells, ref / step, rtol=1e-6)
    assert np.array_equal(np.isfinite(cells), np.isfinite(ref))
    assert np.array_equal(cells_decided, ref_decided)


def test_patched_cells_are_those_of_the_whole_changed_map():
    rng = np.random.default_rng(4)
    shape = (61, 83)
    disparity = (rng.random(shape) * 30).astype(np.float32)
    finite = rng.random(shape) > 0.1
    grid = Grid.for_shape(shape, 2)
    cells = grid.disparities(disparity, finite, finite)[0]
    changed = np.zeros(shape, bool)
    changed[50:61, 70:83] = True  # reaches the partial last row and column of cells
    changed[5:8, 3:5] = True
    again = np.where(changed, disparity + 2.5, disparity).astype(np.float32)
    assert np.array_equal(grid.patched(cells, again, finite, changed), grid.disparities(again, finite, finite)[0])
    assert grid.patched(cells, again, finite, np.zeros(shape, bool)) is cells


def test_any_of_marks_the_cells_holding_a_pixel():
    mask = np.zeros((9, 11), bool)
    mask[8, 10] = mask[0, 3] = True
    cells = Grid.for_shape(mask.shape, 2).any_of(mask)
    assert cells.shape == (5, 6)
    assert set(zip(*np.nonzero(cells))) == {(4, 5), (0, 1)}


def test_the_grid_camera_sees_a_cell_as_its_pixels_centre():
    """On a road plane the disparity is linear in (u, v): a cell's mean is the disparity of
    its centre, and the grid camera puts that point on the plane (height 0)."""
    camera = Camera(f=800.0, baseline=0.3, cx=641.3, cy=355.7, doffs=2.0)
    plane = RoadPlane(normal=(0.0, -0.8, -0.6), offset=1.5, inlier_share=1.0)
    v, u = np.mgrid[0:720, 0:1280].astype(np.float64)
    n = np.asarray(plane.normal)
    # the ray (u - cx, v - cy, f) / f meets n . P + c = 0 at Z = -c / (n . r); d = f B / Z - doffs
    z = -plane.offset / ((u - camera.cx) / camera.f * n[0] + (v - camera.cy) / camera.f * n[1] + n[2])
    disparity = np.where(z > 0, camera.f * camera.baseline / np.where(z > 0, z, 1) - camera.doffs, np.inf)
    disparity = disparity.astype(np.float32)
    finite = np.isfinite(disparity) & (disparity > 0)
    grid = Grid.for_shape(disparity.shape)
    cells, _ = grid.disparities(disparity, finite, finite)
    heights = height_map(cells, np.isfinite(cells), grid.camera(camera), plane)
    assert np.isfinite(heights).mean() > 0.5
    assert np.nanmax(np.abs(np.where(np.isfinite(heights), heights, np.nan))) < 1e-4  # metres


def test_settings_in_cells():
    grid = Grid(2, (720, 1280))
    tuning = grid.tuning(DefectTuning())
    assert (tuning.median_px, tuning.peak_px, tuning.noise_cell_px, tuning.split_smooth_px,
            tuning.local_noise_px, tuning.gap_px, tuning.wall_step_px) == (3, 3, 225.0, 6.0, 40, 1, 1)
    assert grid.road(RoadConfig(ring_px=12)).ring_px == 6
    assert grid.rules(ConfidenceRules()).spike_px == 7
    one = Grid(1, (96, 160))
    assert one.tuning(DefectTuning()) == DefectTuning() and one.road(RoadConfig()) == RoadConfig()


def test_a_defect_back_in_the_images_pixels():
    grid = Grid(2, (9, 11))
    cells = np.zeros(grid.cells, bool)
    cells[1:3, 4:6] = True
    cells[4, 5] = True  # the partial last row and column of cells: pixel (8, 10) only
    defect = Defect(id=1, kind="pothole", centroid_px=(4.5, 2.0), bbox_px=(4, 1, 5, 4), centroid_m=(0, 0, 0),
                    area_m2=0.1, max_depth_mm=30.0, mean_depth_mm=10.0, volume_l=1.0, decided_share=1.0,
                    low_confidence=False, outline_px=((0, 0),))
    moved, mask = grid.defect(defect, cells)
    expected = np.zeros((9, 11), bool)
    expected[2:6, 8:11] = True
    expected[8, 10] = True
    assert np.array_equal(mask, expected)
    assert moved.bbox_px == (8, 2, 10, 8)
    assert moved.centroid_px == (9.5, 4.5)
    assert moved.outline_px == outline(expected)


@pytest.fixture(scope="module")
def wide_scene():
    """A 1280x720 road with a paraboloid pothole 60 mm deep, 0.25 m in radius."""
    disparity, camera, _ = pothole_scene(width=1280, height=720, f=900.0, baseline=0.3, pitch_deg=30.0,
                                         roll_deg=2.0, depth=0.06, radius=0.25, centre=(0.1, 4.0))
    return disparity, camera


def test_a_report_on_the_grid_measures_as_one_on_the_pixels(wide_scene, tmp_path, monkeypatch):
    disparity, camera = wide_scene
    finite = np.isfinite(disparity)
    left = np.full(disparity.shape, 128, np.uint8)
    road = RoadConfig()
    (tmp_path / "grid").mkdir()
    (tmp_path / "pixels").mkdir()
    on_grid = road_report(tmp_path / "grid", left, disparity, finite, camera, {}, road, groups=frozenset())[0]
    monkeypatch.setattr(grid_module, "GRID_COLUMNS", 10 ** 6)  # every map measured on its pixels
    on_pixels = road_report(tmp_path / "pixels", left, disparity, finite, camera, {}, road, groups=frozenset())[0]
    assert [d["kind"] for d in on_grid] == [d["kind"] for d in on_pixels] == ["pothole"]
    a, b = on_grid[0], on_pixels[0]
    assert a["max_depth_mm"] == pytest.approx(b["max_depth_mm"], rel=0.02)
    assert a["max_depth_mm"] == pytest.approx(60.0, rel=0.05)
    assert a["area_m2"] == pytest.approx(b["area_m2"], rel=0.03)
    assert a["volume_l"] == pytest.approx(b["volume_l"], rel=0.03)
    assert np.allclose(a["centroid_m"], b["centroid_m"], atol=0.01)
    assert np.allclose(a["bbox_px"], b["bbox_px"], atol=4)
