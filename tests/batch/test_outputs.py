"""The per-pair output files (d3cli.batch.outputs)."""

import numpy as np

from d3cli.batch.outputs import write_disparity_outputs
from d3cli.data import io


def test_write_disparity_outputs(tmp_path):
    disp = np.array([[1.25, np.inf, 30.0], [0.5, 7.0, np.inf]], np.float32)
    valid = np.isfinite(disp)
    paths = write_disparity_outputs(tmp_path / "out" / "pair", disp, valid, vmax=32)
    assert sorted(paths) == ["disp.pfm", "disp.png", "disp_color.png", "valid.png"]
    folder = tmp_path / "out" / "pair"
    assert sorted(p.name for p in folder.iterdir()) == sorted(paths)
    np.testing.assert_array_equal(io.read_pfm(folder / "disp.pfm").view(np.uint32), disp.view(np.uint32))
    np.testing.assert_array_equal(io.read_kitti_png(folder / "disp.png"), disp)
    np.testing.assert_array_equal(io.read_image(folder / "valid.png"), valid.astype(np.uint8) * 255)
    colour = io.read_image(folder / "disp_color.png")
    assert colour.shape == (2, 3, 3) and tuple(colour[0, 1]) == (0, 0, 0)


def test_negative_disparities_are_never_written(tmp_path):
    import pytest

    disp = np.array([[1.0, -0.5]], np.float32)
    with pytest.raises(ValueError, match="negative disparities"):
        write_disparity_outputs(tmp_path / "p", disp, np.ones_like(disp, bool), vmax=4)
    assert not (tmp_path / "p" / "disp.pfm").exists()
