"""The per-pair output files (d3cli.batch.outputs)."""

import numpy as np

from d3cli.batch.outputs import write_disparity_outputs
from d3cli.data import formats as io


def test_write_disparity_outputs(tmp_path):
    disp = np.array([[1.25, np.inf, 30.0], [0.5, 7.0, np.inf]], np.float32)
    valid = np.isfinite(disp)
    paths = write_disparity_outputs(tmp_path / "out" / "pair", disp, valid, color_range=(0, 32))
    assert paths.pop("color_range") == {"min": 0.0, "max": 32.0, "how": "fixed range"}
    assert paths.pop("png_clipped") == 0
    assert sorted(paths) == ["disp.pfm", "disp.png", "disp_color.png", "valid.png"]
    folder = tmp_path / "out" / "pair"
    assert sorted(p.name for p in folder.iterdir()) == sorted(paths)
    np.testing.assert_array_equal(io.read_pfm(folder / "disp.pfm").view(np.uint32), disp.view(np.uint32))
    np.testing.assert_array_equal(io.read_kitti_png(folder / "disp.png"), disp)
    np.testing.assert_array_equal(io.read_image(folder / "valid.png"), valid.astype(np.uint8) * 255)
    colour = io.read_image(folder / "disp_color.png")
    assert colour.shape[1:] == (3, 3) and colour.shape[0] > 2  # the colour bar below the map
    assert tuple(colour[0, 1]) == (0, 0, 0)


def test_robust_range_panel_and_overlay(tmp_path):
    from d3cli.batch.outputs import write_panel

    disp = np.full((30, 40), 10.0, np.float32)
    disp[:, 20:] = 20.0
    disp[0, 0] = 1000.0  # one outlier must not set the colour range
    valid = np.ones_like(disp, bool)
    left = np.zeros((30, 40, 3), np.uint8)
    written = write_disparity_outputs(tmp_path, disp, valid, left=left)
    assert written["color_range"]["max"] == 20.0 and written["color_range"]["min"] == 10.0
    assert (tmp_path / "valid_overlay.png").is_file()
    panel = io.read_image(write_panel(tmp_path, "pair-x", left, {"epe": 1.5}))
    assert panel.shape[1] > 3 * 40


def test_negative_disparities_are_never_written(tmp_path):
    import pytest

    disp = np.array([[1.0, -0.5]], np.float32)
    with pytest.raises(ValueError, match="negative disparities"):
        write_disparity_outputs(tmp_path / "p", disp, np.ones_like(disp, bool))
    assert not (tmp_path / "p" / "disp.pfm").exists()


def test_recomputing_a_pair_removes_its_road_outputs_but_not_the_users_files(tmp_path):
    from d3cli.batch.outputs import ROAD_FILES, remove_pair_files

    for name in (*ROAD_FILES, "disp.pfm", "notes.txt"):
        (tmp_path / name).write_text("x")
    remove_pair_files(tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]


def test_png_clipped_counts_what_disp_png_cannot_hold(tmp_path):
    from d3cli.batch.outputs import kitti_clipped

    disp = np.array([[255.99, 255.996, 255.9995, 256.0, 300.0, np.inf]], np.float32)
    # round(d * 256) > 65535 from 65535.5 / 256 = 255.99805 px on
    assert kitti_clipped(disp) == 3
    written = write_disparity_outputs(tmp_path / "p", disp, np.isfinite(disp))
    assert written["png_clipped"] == 3


def test_the_panel_title_gives_every_figure_its_unit():
    from d3cli.batch.outputs import panel_title

    title = panel_title("p", {"epe": 1.234, "d1_all": 4.5, "bad_2_noc": 7.8, "a90_noc": 2.1, "psnr": 30.0, "mse": 3.0})
    assert title == "p   EPE 1.23 px   D1 4.50%   bad2noc 7.80%   A90noc 2.10 px   PSNR 30.00 dB"
