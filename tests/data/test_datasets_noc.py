"""KITTI-style disp_noc.png in a pair folder is read as the non-occlusion mask."""

import numpy as np

from d3cli.data import formats as io, layouts as datasets


def test_disp_noc_png_is_the_mask(tmp_path):
    pair_dir = tmp_path / "p" / "kitti-like"
    pair_dir.mkdir(parents=True)
    img = np.full((4, 6), 100, np.uint8)
    io.write_image(pair_dir / "left.png", img)
    io.write_image(pair_dir / "right.png", img)
    gt = np.full((4, 6), 5.0, np.float32)
    io.write_kitti_png(pair_dir / "disp_gt.png", gt)
    noc = gt.copy()
    noc[:, :2] = np.inf  # occluded: 0 in the uint16 PNG
    io.write_kitti_png(pair_dir / "disp_noc.png", noc)
    (pair_dir / "SOURCE.txt").write_text("gt_scale: 256\n")  # KITTI's encoding (read with 1: 1280 px, refused)
    (pair,) = datasets.discover([tmp_path / "p"])
    assert pair.nocc is not None and pair.nocc.name == "disp_noc.png"
    _, mask = datasets.load_ground_truth(pair, img.shape)
    assert mask.sum() == 16 and not mask[:, :2].any()
