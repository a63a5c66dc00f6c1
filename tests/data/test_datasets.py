"""Tests of d3cli.data.layouts: every layout on tiny generated fixtures, manifests, bad inputs."""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from d3cli.data import formats as io
from d3cli.data.layouts import (
    LAYOUTS,
    Pair,
    detect_layout,
    discover,
    family_from_name,
    load_ground_truth,
    load_pair_images,
    load_manifest,
    resolve_max_disparity,
)
from d3cli.errors import InputError

MANIFEST_DIR = Path(__file__).resolve().parents[2] / "data_manifests"
# The development data folder (29 pairs), where the environment names it (the benchmark
# scripts read the same variable); the test is skipped without it.
DEV_DATA = Path(os.environ.get("D3STEREO_DATA", "/nonexistent"))


def _img(path: Path, h=6, w=10, colour=False, seed=0, dtype=np.uint8) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    shape = (h, w, 3) if colour else (h, w)
    cv2.imwrite(str(path), rng.integers(0, 200, shape).astype(dtype))
    return path


def _kitti_gt(path: Path, h=6, w=10, value=4.5) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    raw = np.zeros((h, w), np.uint16)
    raw[2:, 3:] = int(value * 256)
    cv2.imwrite(str(path), raw)
    return path


def _pair_folder(folder: Path, *, h=6, w=10, source: str | None = None, gt: str | None = None, extra=()) -> Path:
    _img(folder / "left.png", h, w, seed=1)
    _img(folder / "right.png", h, w, seed=2)
    if source is not None:
        (folder / "SOURCE.txt").write_text(source)
    if gt == "png8":
        raw = np.full((h, w), 24, np.uint8)
        raw[0, 0] = 0
        cv2.imwrite(str(folder / "disp_gt.png"), raw)
    elif gt == "pfm":
        disp = np.full((h, w), 4.5, np.float32)
        disp[0, 0] = np.inf
        io.write_pfm(folder / "disp_gt.pfm", disp)
    for name in extra:
        _img(folder / name, h, w, seed=3)
    return folder


# --------------------------------------------------------------------------- pair folders


def test_pair_folders_layout(tmp_path):
    root = tmp_path / "data"
    _pair_folder(root / "middlebury2005-art-third", source="name: x\ngt_scale: 3\ngt_invalid: 0 (unknown disparity)\n", gt="png8")
    mb = _pair_folder(root / "middlebury2014-teddy-Q", source="gt_scale: 1\ngt_invalid: inf (unknown)\n", gt="pfm",
                      extra=["mask0nocc.png"])
    (mb / "calib.txt").write_text("cam0=[10 0 5; 0 10 3; 0 0 1]\nbaseline=100\nwidth=10\nheight=6\nndisp=7\n")
    _pair_folder(root / "karlsruhe2010-drive-000000", source="gt_format: none\n")
    _pair_folder(root / "sid-campus")
    (root / "notes").mkdir()  # folders without views are skipped
    assert detect_layout(root) == "pair-folders"
    pairs = discover([root])
    assert [p.name for p in pairs] == ["karlsruhe2010-drive-000000", "middlebury2005-art-third", "middlebury2014-teddy-Q", "sid-campus"]
    road, art, teddy, sid = pairs
    assert (road.family, sid.family, art.family, teddy.family) == ("road", "road", "middlebury2005", "middlebury2014")
    assert art.gt == root / "middlebury2005-art-third" / "disp_gt.png"
    assert (art.gt_scale, art.gt_invalid, art.max_disparity, art.nocc) == (3.0, "zero", None, None)
    assert (teddy.gt_scale, teddy.gt_invalid, teddy.max_disparity) == (1.0, "inf", 7)
    assert teddy.nocc.name == "mask0nocc.png" and teddy.calib.name == "calib.txt"
    assert road.gt is None and road.gt_invalid == "auto"
    gt, mask = load_ground_truth(art, (6, 10, 3))
    assert gt[0, 0] == np.inf and gt[1, 1] == 8.0
    assert mask is None


def test_pair_folder_ndisp_rescaled_for_downsized_images(tmp_path):
    folder = _pair_folder(tmp_path / "mb-x", source="image_size: 10x6 (W x H), mode L\n")
    (folder / "calib.txt").write_text("width=40\nheight=24\nndisp=70\n")
    assert discover(folder)[0].max_disparity == 18  # ceil(70 * 10 / 40)


def test_pair_folder_source_max_disparity_and_family(tmp_path):
    folder = _pair_folder(tmp_path / "thing", source="max_disparity: 9\nfamily: synth\n")
    pair = discover(str(folder))[0]
    assert (pair.max_disparity, pair.family) == (9, "synth")


def test_pair_folder_alternative_nocc_names(tmp_path):
    for name in ("disp_gt_nocc.png", "nonocc.png", "mask_nonocc.png"):
        folder = _pair_folder(tmp_path / name.split(".")[0], extra=[name])
        assert discover(folder)[0].nocc == folder / name


def test_single_pair_folder_and_two_files(tmp_path):
    folder = _pair_folder(tmp_path / "kitti2015-000001_10", gt="png8")
    assert detect_layout(folder) == "pair"
    (pair,) = discover([folder])
    assert pair.name == "kitti2015-000001_10" and pair.family == "kitti2015"
    (two,) = discover([folder / "left.png", folder / "right.png"])
    assert two == Pair(name="kitti2015-000001_10", left=folder / "left.png", right=folder / "right.png", family="kitti2015")
    a, b = _img(tmp_path / "scene_a.jpg"), _img(tmp_path / "scene_b.jpg")
    assert discover([a, b])[0].name == "scene_a"


def test_family_from_name():
    assert family_from_name("middlebury2014-teddy-Q") == "middlebury2014"
    assert family_from_name("kitti2012-000000_10-colour") == "kitti2012"
    assert family_from_name("karlsruhe2010-drive0023-000000") == "road"
    assert family_from_name("sid-campus_ccw_clear_day_002") == "road"
    assert family_from_name("synth-0003") == "synth"
    assert family_from_name("teddy") == ""


# --------------------------------------------------------------------------- Middlebury 2014


def _middlebury_scene(scene: Path, *, gt=True, ndisp=8):
    _img(scene / "im0.png", colour=True, seed=1)
    _img(scene / "im1.png", colour=True, seed=2)
    (scene / "calib.txt").write_text(f"cam0=[20 0 5; 0 20 3; 0 0 1]\nbaseline=150\nwidth=10\nheight=6\nndisp={ndisp}\n")
    if gt:
        disp = np.full((6, 10), 3.25, np.float32)
        disp[0, :2] = np.inf
        io.write_pfm(scene / "disp0GT.pfm", disp)
        mask = np.full((6, 10), 255, np.uint8)
        mask[1, :] = 128
        mask[0, :2] = 0
        cv2.imwrite(str(scene / "mask0nocc.png"), mask)


def test_middlebury2014_layout(tmp_path):
    root = tmp_path / "MiddEval3"
    _middlebury_scene(root / "trainingQ" / "Teddy")
    _middlebury_scene(root / "trainingQ" / "ArtL", ndisp=6)
    _middlebury_scene(root / "trainingH" / "Teddy", ndisp=9)
    _middlebury_scene(root / "testQ" / "Australia", gt=False)
    assert detect_layout(root) == "middlebury2014"
    pairs = discover([root])
    assert [p.name for p in pairs] == [
        "middlebury2014-artl-Q", "middlebury2014-australia-Q", "middlebury2014-teddy-H", "middlebury2014-teddy-Q",
    ]
    teddy = pairs[-1]
    assert teddy.left.name == "im0.png" and teddy.right.name == "im1.png"
    assert (teddy.gt.name, teddy.nocc.name, teddy.gt_invalid, teddy.max_disparity, teddy.family) == (
        "disp0GT.pfm", "mask0nocc.png", "inf", 8, "middlebury2014")
    assert pairs[1].gt is None and pairs[1].nocc is None
    gt, mask = load_ground_truth(teddy, (6, 10, 3))
    assert np.isinf(gt[0, :2]).all() and gt[3, 3] == 3.25
    # 255 = non-occluded: the occluded row (128) and the no-GT pixels (0) are not evaluated
    assert not mask[1].any() and not mask[0, :2].any() and mask[2:].all()
    # the trainingQ folder itself and one scene folder work too
    assert [p.name for p in discover(root / "trainingQ")] == ["middlebury2014-artl-Q", "middlebury2014-teddy-Q"]
    assert discover(root / "trainingQ" / "Teddy") == [teddy]


def test_middlebury2014_missing_im1(tmp_path):
    scene = tmp_path / "trainingQ" / "Pipes"
    _img(scene / "im0.png")
    with pytest.raises(InputError, match=r"Pipes: found im0\.png but no right image im1\.png; unpack"):
        discover(tmp_path)


# --------------------------------------------------------------------------- KITTI


def test_kitti2012_layout(tmp_path):
    root = tmp_path / "kitti2012"
    train = root / "training"
    for frame in ("000000", "000001"):
        for view in ("colored_0", "colored_1"):
            _img(train / view / f"{frame}_10.png", colour=True)
            _img(train / view / f"{frame}_11.png", colour=True)  # not a stereo pair
        for view in ("image_0", "image_1"):
            _img(train / view / f"{frame}_10.png")
        _kitti_gt(train / "disp_occ" / f"{frame}_10.png")
        _kitti_gt(train / "disp_noc" / f"{frame}_10.png")
        (train / "calib").mkdir(exist_ok=True)
        (train / "calib" / f"{frame}.txt").write_text("P0: 7 0 5 0 0 7 3 0 0 0 1 0\nP1: 7 0 5 -3.5 0 7 3 0 0 0 1 0\n")
    _img(root / "testing" / "image_0" / "000000_10.png")
    _img(root / "testing" / "image_1" / "000000_10.png")
    assert detect_layout(root) == "kitti2012"
    pairs = discover([root])
    assert [p.name for p in pairs] == ["kitti2012-000000_10", "kitti2012-000001_10", "kitti2012-testing-000000_10"]
    first = pairs[0]
    assert first.left == train / "colored_0" / "000000_10.png"  # colour preferred
    assert (first.gt_scale, first.gt_invalid, first.family) == (256.0, "zero", "kitti2012")
    assert first.nocc == train / "disp_noc" / "000000_10.png" and first.calib == train / "calib" / "000000.txt"
    assert pairs[2].gt is None and pairs[2].left.parent.name == "image_0"
    gt, mask = load_ground_truth(first, (6, 10))
    assert np.isinf(gt[0, 0]) and gt[3, 4] == 4.5 and mask[3, 4] and not mask[0, 0]
    assert io.read_calib(first.calib)["baseline"] == pytest.approx(0.5)
    # the training folder given directly
    assert [p.name for p in discover(train)] == ["kitti2012-000000_10", "kitti2012-000001_10"]


def test_kitti2015_layout(tmp_path):
    train = tmp_path / "training"
    _img(train / "image_2" / "000000_10.png", colour=True)
    _img(train / "image_3" / "000000_10.png", colour=True)
    _kitti_gt(train / "disp_occ_0" / "000000_10.png")
    _kitti_gt(train / "disp_noc_0" / "000000_10.png")
    assert detect_layout(tmp_path) == "kitti2015"
    (pair,) = discover([tmp_path])
    assert (pair.name, pair.family, pair.gt.parent.name, pair.nocc.parent.name) == (
        "kitti2015-000000_10", "kitti2015", "disp_occ_0", "disp_noc_0")


def test_kitti_missing_right_frame(tmp_path):
    _img(tmp_path / "training" / "image_2" / "000007_10.png")
    (tmp_path / "training" / "image_3").mkdir()
    with pytest.raises(InputError, match=r"image_3: no right image 000007_10\.png for .*; every left frame needs"):
        discover(tmp_path)


# --------------------------------------------------------------------------- UDTIRI-Stereo, Stereo-Road


def test_udtiri_stereo_layout(tmp_path):
    root = tmp_path / "UDTIRI-Stereo"
    for split in ("train", "test"):
        for stem in ("0001", "0002"):
            _img(root / split / "left" / f"{stem}.png")
            _img(root / split / "right" / f"{stem}.png")
    (root / "train" / "disparity_noc").mkdir()
    disp = np.full((6, 10), 7.75, np.float32)
    disp[0, 0] = 0.0
    disp[0, 1] = np.nan
    np.save(root / "train" / "disparity_noc" / "0001.npy", disp)
    np.save(root / "train" / "disparity_noc" / "0002.npy", disp)
    assert detect_layout(root) == "udtiri-stereo"
    pairs = discover([root])
    assert [p.name for p in pairs] == ["udtiri-test-0001", "udtiri-test-0002", "udtiri-train-0001", "udtiri-train-0002"]
    train = pairs[2]
    assert train.family == "udtiri" and train.gt.suffix == ".npy" and pairs[0].gt is None
    gt, mask = load_ground_truth(train, (6, 10))
    # .npy: non-finite is "no ground truth" (as in PFM); 0 is read as 0, which no metric scores.
    assert gt[0, 0] == 0.0 and np.isinf(gt[0, 1]) and gt[5, 5] == 7.75 and mask is None
    # a root without splits
    flat = tmp_path / "flat"
    _img(flat / "left" / "a.png")
    _img(flat / "right" / "a.png")
    (flat / "disparity_noc").mkdir()
    np.save(flat / "disparity_noc" / "a.npy", disp)
    assert [p.name for p in discover(flat)] == ["udtiri-a"]


def test_stereo_road_layout(tmp_path):
    root = tmp_path / "stereo-road"
    _img(root / "image_L" / "road_01.png")
    _img(root / "image_R" / "road_01.png")
    (root / "calib.txt").write_text("f: 800\nbaseline: 0.12\nndisp: 40\n")
    assert detect_layout(root) == "stereo-road"
    (pair,) = discover([root])
    assert (pair.name, pair.family, pair.gt, pair.calib, pair.max_disparity) == (
        "stereo-road-road_01", "road", None, root / "calib.txt", 40)
    seq = tmp_path / "sequences"
    for name in ("seq1", "seq2"):
        _img(seq / name / "left" / "000.png")
        _img(seq / name / "right" / "000.png")
    (seq / "seq2" / "calib").mkdir()
    (seq / "seq2" / "calib" / "000.txt").write_text("f: 700\n")
    pairs = discover([seq])
    assert [p.name for p in pairs] == ["stereo-road-seq1-000", "stereo-road-seq2-000"]
    assert pairs[0].calib is None and pairs[1].calib == seq / "seq2" / "calib" / "000.txt"


def test_road_missing_right_image(tmp_path):
    _img(tmp_path / "left" / "a.png")
    _img(tmp_path / "left" / "b.png")
    _img(tmp_path / "right" / "a.png")
    with pytest.raises(InputError, match=r"right: no right image for .*b\.png; every left image needs a right image with the same name"):
        discover(tmp_path)


# --------------------------------------------------------------------------- manifests


def _write_manifest(path: Path, doc) -> Path:
    path.write_text(doc if isinstance(doc, str) else yaml.safe_dump(doc, sort_keys=False))
    return path


def test_manifest_pairs_defaults_and_relative_root(tmp_path):
    data = tmp_path / "data"
    _img(data / "a" / "im0.png")
    _img(data / "a" / "im1.png")
    _kitti_gt(data / "a" / "gt.png")
    _img(data / "b" / "l.png")
    _img(data / "b" / "r.png")
    manifests = tmp_path / "manifests"
    manifests.mkdir()
    path = _write_manifest(manifests / "m.yaml", {
        "root": "../data",
        "gt_scale": 256,
        "gt_invalid": 0,
        "family": "mine",
        "pairs": [
            {"name": "b-pair", "left": "b/l.png", "right": "b/r.png", "max_disparity": 5, "family": "other"},
            {"name": "a-pair", "left": "a/im0.png", "right": "a/im1.png", "gt": "a/gt.png", "nocc": None},
        ],
    })
    pairs = discover([path])
    assert [p.name for p in pairs] == ["a-pair", "b-pair"]
    a, b = pairs
    assert a == Pair(name="a-pair", left=data / "a" / "im0.png", right=data / "a" / "im1.png", gt=data / "a" / "gt.png",
                     gt_scale=256.0, gt_invalid="zero", family="mine")
    assert (b.family, b.max_disparity, b.gt) == ("other", 5, None)
    gt, _ = load_ground_truth(a, (6, 10))
    assert gt[3, 4] == 4.5


def test_manifest_with_layout_and_defaults(tmp_path):
    train = tmp_path / "dl" / "training"
    _img(train / "image_2" / "000000_10.png")
    _img(train / "image_3" / "000000_10.png")
    path = _write_manifest(tmp_path / "k.yml", "layout: kitti2015\nroot: dl\nmax_disparity: 7\n")
    (pair,) = discover(path)
    assert (pair.name, pair.max_disparity, pair.gt_scale) == ("kitti2015-000000_10", 7, 256.0)


MANIFEST_ERRORS = [
    ("pairs: [{name: a, left: l.png}]", r"m\.yaml pairs\[0\] \(a\): missing key 'right'; every pair needs name, left and right"),
    ("pairs: [{name: a, left: l.png, right: r.png}, {name: b, left: l.png, right: gone.png}]",
     r"m\.yaml pairs\[1\] \(b\): right file not found: .*gone\.png; fix the path \(relative to root "),
    ("pairs: [{name: a, left: l.png, right: r.png, lft: x}]", r"pairs\[0\] \(a\): unknown key 'lft'; valid keys are name, left"),
    ("pairs: [{name: a, left: l.png, right: r.png, gt_scale: -1}]", r"pairs\[0\] \(a\): gt_scale must be a number > 0"),
    ("pairs: [{name: a, left: l.png, right: r.png, max_disparity: 2.5}]", r"max_disparity must be a positive integer"),
    ("pairs: [{name: 'a/b', left: l.png, right: r.png}]", r"name 'a/b' is not filesystem-safe"),
    ("pairs: [{name: a, left: l.png, right: r.png, gt_invalid: maybe}]", r"gt_invalid 'maybe' is not understood; use 0, inf"),
    ("pairs: [notamapping]", r"pairs\[0\]: expected a mapping, got str"),
    ("root: nowhere\npairs: []", r"m\.yaml: root folder not found: .*nowhere; root: is relative to the manifest file"),
    ("root: .\n", r"m\.yaml: missing key 'pairs' \(and no 'layout'\)"),
    ("- just a list", r"m\.yaml: a manifest must be a mapping"),
    ("pairs: [{name: a\n  left: ]", r"m\.yaml:\d+: not valid YAML"),
    ("layout: kitty\n", r"unknown layout 'kitty'; use one of auto, pair-folders"),
    ("roots: .\npairs: []", r"m\.yaml: unknown key 'roots'"),
    ("pairs: [{name: a, left: l.png, right: r.png}, {name: a, left: r.png, right: l.png}]", r"pair name .a. is used twice \(pairs\[0\] at line 1 and pairs\[1\] at line 1\); give each pair its own name"),
]


@pytest.mark.parametrize("text, message", MANIFEST_ERRORS)
def test_manifest_errors(tmp_path, text, message):
    _img(tmp_path / "l.png")
    _img(tmp_path / "r.png")
    path = _write_manifest(tmp_path / "m.yaml", text)
    with pytest.raises(InputError, match=message) as err:
        discover([path])
    assert "\n" not in str(err.value)


def test_manifest_file_not_found(tmp_path):
    with pytest.raises(InputError, match=r"gone\.yaml: manifest file not found; check the path"):
        load_manifest(tmp_path / "gone.yaml")


@pytest.mark.parametrize("filename, layout", [
    ("middlebury2014.yaml", "middlebury2014"), ("kitti2012.yaml", "kitti2012"), ("kitti2015.yaml", "kitti2015"),
    ("udtiri_stereo.yaml", "udtiri-stereo"), ("stereo_road.yaml", "stereo-road"),
])
def test_public_dataset_manifests_work_on_a_download(tmp_path, filename, layout):
    doc = yaml.safe_load((MANIFEST_DIR / filename).read_text())
    assert doc["layout"] == layout and layout in LAYOUTS and "root" in doc
    download = tmp_path / "download"
    if layout == "middlebury2014":
        _middlebury_scene(download / "trainingQ" / "Teddy")
    elif layout.startswith("kitti"):
        views = ("image_2", "image_3") if layout == "kitti2015" else ("image_0", "image_1")
        for view in views:
            _img(download / "training" / view / "000000_10.png")
    else:
        for view in ("left", "right"):
            _img(download / view / "x.png")
        if layout == "udtiri-stereo":
            (download / "disparity_noc").mkdir()
    doc["root"] = "download"
    pairs = discover([_write_manifest(tmp_path / filename, doc)])
    assert len(pairs) == 1
    assert pairs[0].family == {"udtiri-stereo": "udtiri", "stereo-road": "road"}.get(layout, layout)


# --------------------------------------------------------------------------- bad inputs


def test_missing_right_image_in_pair_folder_is_listed_broken_and_the_rest_kept(tmp_path):
    _pair_folder(tmp_path / "ok")
    _img(tmp_path / "broken" / "left.png")
    _img(tmp_path / "noleft" / "right.png")
    pairs = {p.name: p for p in discover([tmp_path])}
    assert sorted(pairs) == ["broken", "noleft", "ok"] and pairs["ok"].error is None
    with pytest.raises(InputError, match=r"broken: found left\.png but no right image; add the right view as right\.png"):
        load_pair_images(pairs["broken"])
    with pytest.raises(InputError, match=r"noleft: found a right image but no left image; add left\.png"):
        load_pair_images(pairs["noleft"])
    load_pair_images(pairs["ok"])


def test_a_single_broken_pair_folder_given_directly_is_still_an_error(tmp_path):
    _img(tmp_path / "broken" / "left.png")
    with pytest.raises(InputError, match=r"broken: found left\.png but no right image"):
        discover([tmp_path / "broken"])


def test_symlink_loop_is_skipped_and_named(tmp_path, caplog):
    _pair_folder(tmp_path / "ok")
    (tmp_path / "loop").symlink_to(tmp_path / "loop")
    (tmp_path / "ok" / "self").symlink_to(tmp_path / "ok" / "self")
    with caplog.at_level("WARNING"):
        pairs = discover([tmp_path])
    assert [p.name for p in pairs] == ["ok"]
    assert any(str(tmp_path / "loop") in r.getMessage() and "skipped" in r.getMessage() for r in caplog.records)


def test_left_right_size_mismatch(tmp_path):
    folder = tmp_path / "pairs-0007"
    _img(folder / "left.png", 375 // 25, 1242 // 3)
    _img(folder / "right.png", 375 // 25, 1240 // 3)
    (pair,) = discover(folder)
    with pytest.raises(InputError, match=r"^pairs-0007: left is 15x414 but right is 15x413; a stereo pair needs equal sizes$"):
        load_pair_images(pair)


def test_mixed_bit_depth_and_grey_colour(tmp_path):
    folder = tmp_path / "p"
    _img(folder / "left.png", colour=True)
    _img(folder / "right.png")
    left, right = load_pair_images(discover(folder)[0])
    assert left.shape == right.shape == (6, 10) and left.dtype == np.uint8
    _img(folder / "right.png", dtype=np.uint16)
    with pytest.raises(InputError, match="left is 8-bit but right is 16-bit; give both views with the same bit depth"):
        load_pair_images(discover(folder)[0])


def test_corrupt_image_in_pair(tmp_path):
    folder = _pair_folder(tmp_path / "p")
    (folder / "right.png").write_bytes(b"\x89PNG garbage")
    with pytest.raises(InputError, match=r"right\.png: cannot read image \(corrupt or not an image\); "):
        load_pair_images(discover(folder)[0])


def test_empty_folder(tmp_path):
    (tmp_path / "empty").mkdir()
    (tmp_path / "empty" / "readme.txt").write_text("hi")
    with pytest.raises(InputError, match=r"^.*empty: no stereo pairs found \(expected pair folders with left\.png and right\.png.*\); check the path"):
        discover([tmp_path / "empty"])


def test_unknown_layout(tmp_path):
    _img(tmp_path / "loose" / "a.png")
    _img(tmp_path / "loose" / "b.png")
    _img(tmp_path / "loose" / "c.png")
    with pytest.raises(InputError, match=r"loose: unknown dataset layout \(found 3 image files but no left/right views"):
        discover([tmp_path / "loose"])


def test_ground_truth_of_another_size(tmp_path):
    folder = _pair_folder(tmp_path / "kitti2015-x")
    _kitti_gt(folder / "disp_gt.png", h=5, w=10)
    pair = discover(folder)[0]
    with pytest.raises(InputError, match=r"^kitti2015-x: ground truth disp_gt\.png is 5x10 but the images are 6x10; give ground truth of the left image's size$"):
        load_ground_truth(pair, (6, 10, 3))
    assert load_ground_truth(Pair("n", folder / "left.png", folder / "right.png"), (6, 10)) == (None, None)


def test_mask_of_another_size(tmp_path):
    folder = _pair_folder(tmp_path / "p", gt="pfm")
    _img(folder / "mask0nocc.png", 4, 4)
    with pytest.raises(InputError, match=r"mask mask0nocc\.png is 4x4 but the images are 6x10"):
        load_ground_truth(discover(folder)[0], (6, 10))


def test_bad_inputs_to_discover(tmp_path):
    with pytest.raises(InputError, match=r"nothing-here: no such file or folder; check the path"):
        discover([tmp_path / "nothing-here"])
    images = [_img(tmp_path / f"{n}.png") for n in "abc"]
    with pytest.raises(InputError, match=r"got 3 image files; give exactly two image files \(left, right\)"):
        discover(images)
    (tmp_path / "x.txt").write_text("")
    with pytest.raises(InputError, match=r"x\.txt: not a folder, manifest or image"):
        discover([tmp_path / "x.txt"])
    with pytest.raises(InputError, match="no inputs given"):
        discover([])


# --------------------------------------------------------------------------- max disparity


def test_resolve_max_disparity(tmp_path):
    folder = _pair_folder(tmp_path / "p", w=200)
    _kitti_gt(folder / "disp_gt.png", w=200, value=30.2)
    (folder / "SOURCE.txt").write_text("gt_scale: 256\n")
    pair = discover(folder)[0]
    assert resolve_max_disparity(pair, 200, override=50) == 50
    assert resolve_max_disparity(pair, 200) == 48  # ceil(30.2) + 4 = 35 -> next multiple of 16
    assert resolve_max_disparity(Pair("n", pair.left, pair.right, max_disparity=21), 200) == 21
    assert resolve_max_disparity(Pair("n", pair.left, pair.right), 200) == 50  # width // 4
    assert resolve_max_disparity(Pair("n", pair.left, pair.right, gt=pair.gt, gt_scale=256.0), 40) == 39  # capped


@pytest.mark.parametrize("override", [0, -3, 200, 500])
def test_resolve_max_disparity_out_of_range(tmp_path, override):
    pair = Pair("pairs-0001", tmp_path / "l.png", tmp_path / "r.png")
    with pytest.raises(InputError, match=rf"^pairs-0001: --max-disparity {override} must be in \[1, 199\]"):
        resolve_max_disparity(pair, 200, override)


def test_resolve_max_disparity_dataset_value_out_of_range(tmp_path):
    pair = Pair("p", tmp_path / "l.png", tmp_path / "r.png", max_disparity=64)
    with pytest.raises(InputError, match=r"p: max disparity 64 from the dataset must be in \[1, 49\]"):
        resolve_max_disparity(pair, 50)


# --------------------------------------------------------------------------- development data


@pytest.mark.skipif(not DEV_DATA.is_dir(), reason="D3STEREO_DATA does not name the development data folder")
def test_development_data_discovery_and_manifest():
    pairs = discover(str(DEV_DATA))
    assert len(pairs) == 29
    families = {}
    for pair in pairs:
        families[pair.family] = families.get(pair.family, 0) + 1
    assert families == {
        "road": 3, "kitti2012": 3, "kitti2015": 1, "middlebury2001": 3, "middlebury2003": 1,
        "middlebury2005": 3, "middlebury2006": 8, "middlebury2014": 7,
    }
    scales = {pair.name: pair.gt_scale for pair in pairs}
    assert scales["middlebury2001-tsukuba"] == 16 and scales["middlebury2001-venus"] == 8
    assert scales["middlebury2003-teddy-quarter"] == 4 and scales["middlebury2006-aloe-third"] == 3
    assert scales["kitti2015-000000_10"] == 256 and scales["middlebury2014-teddy-Q"] == 1
    by_name = {pair.name: pair for pair in pairs}
    assert by_name["middlebury2014-jadeplant-Q"].max_disparity == 160
    assert by_name["middlebury2014-teddy-Q"].gt_invalid == "inf" and by_name["kitti2012-000000_10-colour"].gt_invalid == "zero"
    assert sum(pair.gt is None for pair in pairs) == 3
    manifest = MANIFEST_DIR / "shared_data.yaml"
    if (manifest.parent / "../../shared/data").resolve() == DEV_DATA.resolve():  # the manifest's root
        assert discover([manifest]) == pairs
