"""`eval` scores KITTI's non-occluded pixels against disp_noc's own values, as the devkit does,
and fills a sparse prediction's holes as the devkit does before it counts D1."""

import numpy as np
import pytest

from d3cli.batch import evaluate_folders
from d3cli.batch.scoring import evaluate_pair
from d3cli.data import formats as io, layouts as datasets
from d3cli.errors import InputError

# 4 x 30 (disparities below the width): columns 0-14 at 20 px, 15-29 at 10 px.
GT_OCC = np.repeat(np.array([[20.0] * 15 + [10.0] * 15], np.float32), 4, axis=0)
GT_NOC = GT_OCC.copy()
GT_NOC[0, 15:] = np.inf  # occluded: 0 in the PNG; 105 non-occluded pixels are left
GT_NOC[2, 0] = 24.0  # disp_noc's own value where disp_occ has 20


def kitti_like_pair(root, gt_name="disp_gt.png"):
    pair_dir = root / "data" / "kitti-like"
    pair_dir.mkdir(parents=True)
    img = np.full((4, 30), 100, np.uint8)
    io.write_image(pair_dir / "left.png", img)
    io.write_image(pair_dir / "right.png", img)
    if gt_name.endswith(".png"):
        io.write_kitti_png(pair_dir / gt_name, GT_OCC)
        (pair_dir / "SOURCE.txt").write_text("gt_scale: 256\n")
    else:
        io.write_pfm(pair_dir / gt_name, GT_OCC)
    io.write_kitti_png(pair_dir / "disp_noc.png", GT_NOC)
    (pair,) = datasets.discover([root / "data"])
    return pair, img


def test_sparse_and_dense_predictions_score_the_devkits_d1(tmp_path):
    pair, _ = kitti_like_pair(tmp_path)
    preds = tmp_path / "preds"
    preds.mkdir()
    dense = GT_OCC.copy()  # exact everywhere: D1 (all) 0, but 4 px off disp_noc's 24 at (2, 0)
    io.write_kitti_png(preds / f"{pair.name}.png", dense)
    rows = evaluate_folders([preds], [pair], out_dir=tmp_path / "dense", progress=False)["results"]["preds"]
    assert rows[0]["d1_all"] == 0.0
    assert rows[0]["d1_noc"] == pytest.approx(100.0 / 105)  # |24 - 20| = 4 > 3 and 4/24 > 5 %

    sparse = np.full((4, 30), np.inf, np.float32)  # PNG 0 = no estimate
    sparse[1, 5], sparse[1, 20] = 20.0, 10.0
    # The devkit fills row 1: columns 0-4 with 20 (left of the first estimate), 6-19 with the
    # smaller neighbour 10, 21-29 with 10 (right of the last); then copies row 1 to rows 0, 2
    # and 3.  Outliers: columns 6-14 of every row (|20 - 10| = 10), 9 a row.
    io.write_kitti_png(preds / f"{pair.name}.png", sparse)
    rows = evaluate_folders([preds], [pair], out_dir=tmp_path / "sparse", progress=False)["results"]["preds"]
    assert rows[0]["d1_all"] == pytest.approx(100.0 * 36 / 120)
    assert rows[0]["d1_noc"] == pytest.approx(100.0 * 37 / 105)  # and (2, 0): 20 against disp_noc's 24
    # Middlebury figures: holes left out (avgErr over the 2 estimates, both exact) and counted as invalid.
    assert rows[0]["avgerr_all"] == 0.0 and rows[0]["invalid_all"] == pytest.approx(100.0 * 118 / 120)


def test_disp_noc_written_at_another_scale_than_the_ground_truth_is_refused(tmp_path):
    pair, img = kitti_like_pair(tmp_path, gt_name="disp_gt.pfm")  # PFM in px, disp_noc.png in px x 256
    with pytest.raises(InputError) as info:
        evaluate_pair(pair, img, img, GT_OCC, tmp_path / "out")
    assert str(info.value) == (
        "kitti-like: non-occluded ground truth disp_noc.png holds 256 times the disparities of disp_gt.pfm; "
        "write both with the same scale: gt_scale applies to both")
