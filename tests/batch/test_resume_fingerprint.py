"""A rerun recomputes whatever changed, and keeps what did not.

Each test changes one thing the outputs depend on (an input file, the manifest's range,
the range the ground truth gives, ``gt_scale`` in SOURCE.txt, a method setting, the
camera, the calibration, the package version) and checks that the rerun computes the
pair again; an unchanged rerun skips it.  CLI runs use ``--method sgbm`` on tiny pairs.
"""

from __future__ import annotations

import dataclasses
import json
import os
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from tests.helpers import textured_pair, write_png

import d3cli.batch.fingerprint
from d3cli.cli import main
from d3cli.data.formats import read_pfm, write_pfm
from d3cli.road.pointcloud import read_ply


def invoke(*args):
    result = CliRunner().invoke(main, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    return result


def statuses(out):
    return [p["status"] for p in json.loads((out / "run.json").read_text())["pairs"]]


def stored(out, name="p"):
    return json.loads((out / name / "result.json").read_text())


def touch_later(path: Path) -> None:
    """A new modification time, certainly different from the one stored (coarse clocks)."""
    st = path.stat()
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns + 2_000_000_000))


@pytest.fixture
def one_pair(tmp_path, make_pair_folder):
    root = tmp_path / "pairs"
    make_pair_folder(root, "p", shift=6, size=(48, 96))
    return root


def test_unchanged_rerun_skips_changed_image_recomputes(tmp_path, one_pair):
    out = tmp_path / "out"
    invoke("run", one_pair, "-o", out, "--method", "sgbm")
    invoke("run", one_pair, "-o", out, "--method", "sgbm")
    assert statuses(out) == ["skipped"]
    before = read_pfm(out / "p" / "disp.pfm")
    left, right, _ = textured_pair(10, (48, 96), seed=5)  # other images, same names and size
    write_png(one_pair / "p" / "left.png", left)
    write_png(one_pair / "p" / "right.png", right)
    touch_later(one_pair / "p" / "left.png")
    invoke("run", one_pair, "-o", out, "--method", "sgbm")
    assert statuses(out) == ["ok"]
    after = read_pfm(out / "p" / "disp.pfm")
    assert np.nanmedian(np.where(np.isfinite(after), after, np.nan)[8:-8, 30:-8]) == pytest.approx(10, abs=0.5)
    assert not np.array_equal(before, after, equal_nan=True)


def test_touched_right_image_alone_recomputes(tmp_path, one_pair):
    out = tmp_path / "out"
    invoke("run", one_pair, "-o", out, "--method", "sgbm")
    touch_later(one_pair / "p" / "right.png")
    invoke("run", one_pair, "-o", out, "--method", "sgbm")
    assert statuses(out) == ["ok"]


def _pgm_pair(folder: Path, shift: int, seed: int) -> None:
    """A pair as PGM files (their size depends on the image size only) with its ground truth."""
    from d3cli.data.formats import write_image

    folder.mkdir(parents=True, exist_ok=True)
    left, right, gt = textured_pair(shift, (48, 96), seed=seed)
    write_image(folder / "left.pgm", left)
    write_image(folder / "right.pgm", right)
    write_pfm(folder / "disp_gt.pfm", gt)
    (folder / "SOURCE.txt").write_text("gt_scale: 1\ngt_invalid: inf\n")


def _same_times(source: Path, target: Path) -> None:
    """Give every file of ``target`` the times of its namesake in ``source`` (``cp -p``, ``rsync -a``)."""
    for path in source.rglob("*"):
        if path.is_file():
            st = path.stat()
            os.utime(target / path.relative_to(source), ns=(st.st_atime_ns, st.st_mtime_ns))


def _median_disparity(out: Path) -> float:
    disp = read_pfm(out / "p" / "disp.pfm")[8:-8, 30:-8]
    return float(np.nanmedian(np.where(np.isfinite(disp), disp, np.nan)))


def test_another_dataset_with_the_same_names_sizes_and_times_recomputes(tmp_path):
    """Same pair names, file sizes and modification times, other pixels, another folder:
    other inputs, computed again (it was "skipped as complete" with the first maps)."""
    first, second, out = tmp_path / "one", tmp_path / "two", tmp_path / "out"
    _pgm_pair(first / "p", shift=6, seed=0)
    _pgm_pair(second / "p", shift=11, seed=7)
    _same_times(first, second)
    invoke("run", first, "-o", out, "--method", "sgbm", "--max-disparity", "16")
    assert _median_disparity(out) == pytest.approx(6, abs=0.5)
    invoke("run", second, "-o", out, "--method", "sgbm", "--max-disparity", "16")
    assert statuses(out) == ["ok"]
    assert _median_disparity(out) == pytest.approx(11, abs=0.5)
    assert stored(out)["inputs"]["left"] == str(second / "p" / "left.pgm")
    invoke("run", second, "-o", out, "--method", "sgbm", "--max-disparity", "16")
    assert statuses(out) == ["skipped"]


def test_files_replaced_in_place_with_their_times_kept_recompute(tmp_path):
    """Other pixels under the same paths, sizes and times (a dataset copied over another
    with ``rsync -a``): the content differs, the pair is computed again."""
    data, other, out = tmp_path / "data", tmp_path / "other", tmp_path / "out"
    _pgm_pair(data / "p", shift=6, seed=0)
    invoke("run", data, "-o", out, "--method", "sgbm", "--max-disparity", "16")
    _pgm_pair(other / "p", shift=11, seed=7)
    _same_times(data, other)
    for path in other.rglob("*"):
        if path.is_file():
            target = data / path.relative_to(other)
            st = target.stat()
            target.write_bytes(path.read_bytes())
            os.utime(target, ns=(st.st_atime_ns, st.st_mtime_ns))
            assert target.stat().st_size == st.st_size
    invoke("run", data, "-o", out, "--method", "sgbm", "--max-disparity", "16")
    assert statuses(out) == ["ok"]
    assert _median_disparity(out) == pytest.approx(11, abs=0.5)


def test_the_same_files_under_another_spelling_are_skipped(tmp_path, one_pair, monkeypatch):
    """A relative and an absolute path, or a link to the pair's folder, name the same files."""
    out = tmp_path / "out"
    invoke("run", one_pair, "-o", out, "--method", "sgbm")
    monkeypatch.chdir(tmp_path)
    invoke("run", "pairs", "-o", out, "--method", "sgbm")
    assert statuses(out) == ["skipped"]
    (tmp_path / "link").symlink_to(one_pair)
    invoke("run", tmp_path / "link", "-o", out, "--method", "sgbm")
    assert statuses(out) == ["skipped"]


def test_manifest_max_disparity_change_recomputes(tmp_path, one_pair):
    manifest = tmp_path / "m.yaml"

    def write_manifest(dmax):
        manifest.write_text(f"root: pairs\npairs:\n  - name: p\n    left: p/left.png\n    right: p/right.png\n"
                            f"    max_disparity: {dmax}\n")

    out = tmp_path / "out"
    write_manifest(16)
    invoke("run", manifest, "-o", out, "--method", "sgbm")
    assert stored(out)["max_disparity"] == 16
    invoke("run", manifest, "-o", out, "--method", "sgbm")
    assert statuses(out) == ["skipped"]
    write_manifest(32)
    invoke("run", manifest, "-o", out, "--method", "sgbm")
    assert statuses(out) == ["ok"] and stored(out)["max_disparity"] == 32


def test_range_from_changed_ground_truth_recomputes(tmp_path, one_pair):
    out = tmp_path / "out"
    invoke("run", one_pair, "-o", out, "--method", "sgbm")
    assert stored(out)["max_disparity"] == 16  # 16 * ceil((6 + 4) / 16)
    gt = read_pfm(one_pair / "p" / "disp_gt.pfm")
    write_pfm(one_pair / "p" / "disp_gt.pfm", np.where(np.isfinite(gt), gt + 20.0, gt).astype(np.float32))
    touch_later(one_pair / "p" / "disp_gt.pfm")
    invoke("run", one_pair, "-o", out, "--method", "sgbm")
    assert statuses(out) == ["ok"] and stored(out)["max_disparity"] == 32  # 16 * ceil((26 + 4) / 16)


def test_gt_scale_fixed_in_source_txt_rescores(tmp_path, one_pair):
    out = tmp_path / "out"
    invoke("run", one_pair, "-o", out, "--method", "sgbm", "--eval", "--max-disparity", "16")
    epe = stored(out)["metrics"]["epe"]
    assert epe < 1.0
    source = one_pair / "p" / "SOURCE.txt"
    source.write_text(source.read_text().replace("gt_scale: 1", "gt_scale: 2"))
    invoke("run", one_pair, "-o", out, "--method", "sgbm", "--eval", "--max-disparity", "16")
    assert statuses(out) == ["ok"]
    assert stored(out)["metrics"]["epe"] == pytest.approx(3.0, abs=0.6)  # gt now 3 px, estimate 6 px
    summary = json.loads((out / "summary.json").read_text())
    assert summary["overall"]["means"]["epe"] == pytest.approx(stored(out)["metrics"]["epe"])


def test_nocc_mask_change_recomputes(tmp_path, one_pair):
    out = tmp_path / "out"
    mask = np.full((48, 96), 255, np.uint8)
    write_png(one_pair / "p" / "disp_gt_nocc.png", mask)
    invoke("run", one_pair, "-o", out, "--method", "sgbm", "--eval")
    mask[:, :48] = 0
    write_png(one_pair / "p" / "disp_gt_nocc.png", mask)
    touch_later(one_pair / "p" / "disp_gt_nocc.png")
    invoke("run", one_pair, "-o", out, "--method", "sgbm", "--eval")
    assert statuses(out) == ["ok"]


def test_pt_sgm_pyramid_levels_change_recomputes(tmp_path, make_pair_folder):
    root = tmp_path / "pairs"
    make_pair_folder(root, "p", shift=6, size=(96, 192))
    out = tmp_path / "out"
    invoke("run", root, "-o", out, "--method", "pt-sgm", "--set", "pyramid.levels=2")
    invoke("run", root, "-o", out, "--method", "pt-sgm", "--set", "pyramid.levels=2")
    assert statuses(out) == ["skipped"]
    invoke("run", root, "-o", out, "--method", "pt-sgm", "--set", "pyramid.levels=3")
    assert statuses(out) == ["ok"]
    # sgbm is handed only its own section: a pyramid setting cannot change it.
    invoke("run", root, "-o", out, "--method", "sgbm")
    invoke("run", root, "-o", out, "--method", "sgbm", "--set", "pyramid.levels=2")
    assert statuses(out) == ["skipped"]


def test_package_version_change_recomputes(tmp_path, one_pair, monkeypatch):
    out = tmp_path / "out"
    invoke("run", one_pair, "-o", out, "--method", "sgbm")
    real = d3cli.batch.fingerprint.package_versions
    monkeypatch.setattr(d3cli.batch.fingerprint, "package_versions", lambda: {**real(), "d3stereo": "999.0"})
    invoke("run", one_pair, "-o", out, "--method", "sgbm")
    assert statuses(out) == ["ok"]


def test_old_result_without_input_fingerprint_is_recomputed(tmp_path, one_pair):
    out = tmp_path / "out"
    invoke("run", one_pair, "-o", out, "--method", "sgbm")
    data = stored(out)
    del data["fingerprint"]  # a result.json of an earlier d3stereo (settings only)
    (out / "p" / "result.json").write_text(json.dumps(data))
    invoke("run", one_pair, "-o", out, "--method", "sgbm")
    assert statuses(out) == ["ok"]


# ----------------------------------------------------------------------------- clouds
MIDDLEBURY_CALIB = "cam0=[{f} 0 47.5; 0 {f} 23.5; 0 0 1]\ncam1=[{f} 0 47.5; 0 {f} 23.5; 0 0 1]\n" \
                   "doffs=0\nbaseline={b}\nwidth=96\nheight=48\n"


def cloud_depth(out):
    points, _ = read_ply(out / "p" / "cloud.ply")
    return float(np.median(points[:, 2]))


def test_cloud_follows_camera_settings_map_is_kept(tmp_path, one_pair):
    out = tmp_path / "out"
    cam = ["--set", "camera.baseline=0.5"]
    invoke("run", one_pair, "-o", out, "--method", "sgbm", "--pointcloud", *cam, "--set", "camera.f=100")
    assert cloud_depth(out) == pytest.approx(100 * 0.5 / 6, rel=0.05)
    stamp = (out / "p" / "disp.pfm").stat().st_mtime_ns
    invoke("run", one_pair, "-o", out, "--method", "sgbm", "--pointcloud", *cam, "--set", "camera.f=200")
    assert statuses(out) == ["skipped"]  # the map does not depend on the camera ...
    assert (out / "p" / "disp.pfm").stat().st_mtime_ns == stamp
    assert cloud_depth(out) == pytest.approx(200 * 0.5 / 6, rel=0.05)  # ... the cloud does
    assert stored(out)["cloud"]["camera"]["f"] == 200.0
    invoke("run", one_pair, "-o", out, "--method", "sgbm", "--pointcloud", *cam, "--set", "camera.f=200",
           "--set", "camera.baseline=1.0")
    assert cloud_depth(out) == pytest.approx(200 * 1.0 / 6, rel=0.05)
    # Unchanged: cloud.ply is not written again.
    stamp = (out / "p" / "cloud.ply").stat().st_mtime_ns
    invoke("run", one_pair, "-o", out, "--method", "sgbm", "--pointcloud", *cam, "--set", "camera.f=200",
           "--set", "camera.baseline=1.0")
    assert (out / "p" / "cloud.ply").stat().st_mtime_ns == stamp


def test_cloud_follows_the_calibration_file(tmp_path, one_pair):
    calib = one_pair / "p" / "calib.txt"
    calib.write_text(MIDDLEBURY_CALIB.format(f=120, b=500))  # baseline in mm
    out = tmp_path / "out"
    invoke("run", one_pair, "-o", out, "--method", "sgbm", "--pointcloud")
    assert cloud_depth(out) == pytest.approx(120 * 0.5 / 6, rel=0.05)
    calib.write_text(MIDDLEBURY_CALIB.format(f=240, b=500))
    touch_later(calib)
    invoke("run", one_pair, "-o", out, "--method", "sgbm", "--pointcloud")
    assert cloud_depth(out) == pytest.approx(240 * 0.5 / 6, rel=0.05)


def test_cloud_keeps_only_points_within_the_depth_range(tmp_path, one_pair):
    """No point outside [camera.min_depth_m, camera.max_depth_m] is written (the pair is at
    6 px = 8.33 m; filled pixels spread around it)."""
    out = tmp_path / "out"
    cam = ["--set", "camera.f=100", "--set", "camera.baseline=0.5"]
    invoke("run", one_pair, "-o", out, "--method", "sgbm", "--pointcloud", *cam)
    points, _ = read_ply(out / "p" / "cloud.ply")
    n_all = points.shape[0]
    assert points[:, 2].max() <= 100.0  # default camera.max_depth_m
    invoke("run", one_pair, "-o", out, "--method", "sgbm", "--pointcloud", *cam,
           "--set", "camera.max_depth_m=8.5", "--set", "camera.min_depth_m=8.0")
    points, _ = read_ply(out / "p" / "cloud.ply")
    assert 0 < points.shape[0] < n_all
    assert points[:, 2].min() >= 8.0 and points[:, 2].max() <= 8.5
    assert stored(out)["cloud"]["depth_range_m"] == [8.0, 8.5]
    assert stored(out)["cloud"]["points"] == points.shape[0]


# ----------------------------------------------------------------------------- every key
def _changed(value):
    if isinstance(value, bool):
        return not value
    if isinstance(value, int):
        return value + 1
    if isinstance(value, float):
        return value * 2 + 1
    if isinstance(value, str):
        return value + "-other"
    if isinstance(value, tuple):
        return (*value, value[-1] if value else 1)
    return 1.0  # None


def _every_key():
    from d3cli.config import Config

    cfg = Config()
    for section in dataclasses.fields(cfg):
        sec = getattr(cfg, section.name)
        for key in dataclasses.fields(sec):
            yield section.name, key.name


#: Keys that cannot change a map (see d3cli/batch/fingerprint.py); method and max_disparity
#: are hashed as resolved (arguments of settings_fingerprint).
NOT_IN_MAP = {("run", "backend"), ("run", "max_memory_gb"), ("run", "method"), ("run", "max_disparity")}


@pytest.mark.parametrize("section, key", list(_every_key()))
def test_every_config_key_the_method_reads_changes_the_fingerprint(section, key):
    from d3cli.batch import settings_fingerprint
    from d3cli.config import Config

    cfg = Config()
    sec = getattr(cfg, section)
    other = dataclasses.replace(cfg, **{section: dataclasses.replace(sec, **{key: _changed(getattr(sec, key))})})
    for method in ("d3stereo", "pt-sgm", "sgbm", "elas"):
        reads = {"sgbm": section == "sgbm", "elas": section == "peers"}.get(
            method, section not in ("run", "camera", "road"))
        reads = reads or (section, key) == ("run", "color_range")  # disp_color.png of every method
        same = settings_fingerprint(cfg, method, None) == settings_fingerprint(other, method, None)
        assert same != reads, (method, section, key)
        if (section, key) in NOT_IN_MAP:
            assert same
