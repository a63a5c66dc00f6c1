"""Precomputed feature maps from ``.npz`` (``features.npz``): keys ``left_<i>``,
``right_<i>`` of shape (H / 2^i, W / 2^i, C) for pyramid level i.

The features here are the NCC-equivalent vectors (the 25 pixels of the 5x5 window of the
level image minus their mean), computed with NumPy: their cosine cost is the NCC cost, so
the disparity must match the NCC path's.
"""

from __future__ import annotations

import numpy as np
import pytest
from tests.helpers import textured_pair

from d3cli import D3Stereo, load_config
from d3cli.errors import InputError
from d3cli.kernels import cpu
from d3cli.method.features import load_feature_npz
from d3cli.method.pyramid import build_pyramid

WINDOW = 5


def window_features(img: np.ndarray) -> np.ndarray:
    """(H, W, 25): the edge-padded 5x5 window of every pixel minus its mean."""
    r = WINDOW // 2
    padded = np.pad(img.astype(np.float64), r, mode="edge")
    h, w = img.shape
    stack = np.stack([padded[dy:dy + h, dx:dx + w] for dy in range(WINDOW) for dx in range(WINDOW)], axis=2)
    return (stack - stack.mean(axis=2, keepdims=True)).astype(np.float32)


def write_npz(path, left, right, levels, **changes):
    arrays = {}
    pyr_l = build_pyramid(left.astype(np.float32), levels)
    pyr_r = build_pyramid(right.astype(np.float32), levels)
    for i in range(levels):
        arrays[f"left_{i}"] = window_features(pyr_l[i])
        arrays[f"right_{i}"] = window_features(pyr_r[i])
    arrays.update(changes)
    np.savez(path, **{k: v for k, v in arrays.items() if v is not None})
    return path


def npz_config(path, **extra):
    return load_config(overrides=["run.backend=cpu", "cost.kind=features", f"features.npz={path}",
                                  *[f"{k}={v}" for k, v in extra.items()]])


def test_npz_levels_give_the_ncc_cost_inside_the_image(tmp_path):
    left, right, _ = textured_pair(6, (48, 96), seed=2)
    path = write_npz(tmp_path / "f.npz", left, right, 3)
    pyr_l, pyr_r = build_pyramid(left.astype(np.float32), 3), build_pyramid(right.astype(np.float32), 3)
    levels = load_feature_npz(path, left.shape[:2], [p.shape for p in pyr_l])
    for i, level in enumerate(levels):
        assert level.left.shape == pyr_l[i].shape + (25,)
        np.testing.assert_allclose(np.linalg.norm(level.left, axis=2)[level.left_norm > 0], 1, atol=1e-5)
        ncc = cpu.ncc_cost_volume(pyr_l[i], pyr_r[i], 8, WINDOW, 0.0)
        cos = cpu.cosine_cost_volume(level.left, level.right, level.left_norm, level.right_norm, 8)
        r = WINDOW // 2
        inner = (slice(r, pyr_l[i].shape[0] - r), slice(r + 8, pyr_l[i].shape[1] - r))
        np.testing.assert_allclose(cos[inner], ncc[inner], atol=2e-5)


def test_npz_path_matches_the_ncc_path_end_to_end(tmp_path):
    left, right, gt = textured_pair(7, (64, 128), seed=5)
    path = write_npz(tmp_path / "f.npz", left, right, 4)
    ncc = D3Stereo(load_config(overrides=["run.backend=cpu"])).compute(left, right, max_disparity=24)
    feat = D3Stereo(npz_config(path)).compute(left, right, max_disparity=24)
    assert feat.info["feature_levels"] == [1, 2, 3, 4]
    ok = np.isfinite(gt)
    r = WINDOW // 2
    ok[:r], ok[-r:], ok[:, -r:] = False, False, False
    epe_ncc = np.abs(ncc.disparity[ok] - gt[ok]).mean()
    epe_feat = np.abs(feat.disparity[ok] - gt[ok]).mean()
    assert epe_feat <= 1.1 * epe_ncc + 0.02, (epe_feat, epe_ncc)


def test_relative_npz_is_found_in_the_pair_folder_and_missing_levels_use_ncc(tmp_path):
    left, right, _ = textured_pair(6, (48, 96), seed=3)
    write_npz(tmp_path / "feat.npz", left, right, 3, left_0=None, right_0=None)  # like VGG: no stride-1 map
    result = D3Stereo(npz_config("feat.npz")).compute(left, right, max_disparity=16, pair_dir=tmp_path)
    assert result.info["feature_levels"] == [2, 3]
    assert np.isfinite(result.disparity).all()


def test_a_map_one_pixel_larger_is_cropped(tmp_path):
    left, right, _ = textured_pair(6, (48, 96), seed=3)
    big = np.ones((25, 49, 4), np.float32)  # level 1 of 48x96 is 24x48; a ceil-stride map
    path = write_npz(tmp_path / "f.npz", left, right, 2, left_1=big, right_1=2 * big)
    levels = load_feature_npz(path, (48, 96), [(48, 96), (24, 48)])
    assert levels[1].left.shape == (24, 48, 4)
    np.testing.assert_allclose(levels[1].right, 0.5)


@pytest.mark.parametrize("change, message", [
    ({"right_1": None}, "left_1 has no partner right_1"),
    ({"left_0": None}, "right_0 has no partner left_0"),
    ({"left_0": np.ones((48, 96), np.float32)}, "left_0 has shape (48, 96)"),
    ({"left_1": np.ones((12, 48, 25), np.float32)}, "left_1 is 12x48 but level 1"),
    ({"right_0": np.full((48, 96, 25), np.nan, np.float32)}, "right_0 has NaN or inf values"),
    ({"right_0": np.ones((48, 96, 7), np.float32)}, "left_0 is (48, 96, 25) but right_0 is (48, 96, 7)"),
])
def test_bad_npz_files_are_one_line_input_errors(tmp_path, change, message):
    left, right, _ = textured_pair(6, (48, 96), seed=3)
    path = write_npz(tmp_path / "bad.npz", left, right, 2, **change)
    with pytest.raises(InputError) as info:
        D3Stereo(npz_config(path, **{"pyramid.levels": 2})).compute(left, right, max_disparity=12)
    text = str(info.value)
    assert "\n" not in text and text.startswith(str(path)) and message in text, text
    assert "left_0, right_0, left_1" in text  # says how to write the file


def test_missing_npz_and_no_feature_keys(tmp_path):
    left, right, _ = textured_pair(6, (48, 96), seed=3)
    with pytest.raises(InputError, match="features.npz not found"):
        D3Stereo(npz_config(tmp_path / "none.npz")).compute(left, right, max_disparity=12)
    np.savez(tmp_path / "other.npz", a=np.zeros(3))
    with pytest.raises(InputError, match=r"no left_<i>/right_<i> arrays \(keys: a\)"):
        D3Stereo(npz_config(tmp_path / "other.npz")).compute(left, right, max_disparity=12)
    (tmp_path / "text.npz").write_text("not a zip")
    with pytest.raises(InputError, match="cannot be read as .npz"):
        D3Stereo(npz_config(tmp_path / "text.npz")).compute(left, right, max_disparity=12)


def test_cli_prints_one_error_line_for_a_nan_feature_file(tmp_path, make_pair_folder):
    import subprocess
    import sys

    folder = make_pair_folder(tmp_path, "pair", shift=6, size=(48, 96))
    left, right, _ = textured_pair(6, (48, 96), seed=0)
    write_npz(folder / "feat.npz", left, right, 2, right_1=np.full((24, 48, 25), np.inf, np.float32))
    proc = subprocess.run([sys.executable, "-m", "d3cli", "run", str(folder / "left.png"), str(folder / "right.png"),
                           "-o", str(tmp_path / "out"), "--set", "cost.kind=features",
                           "--set", f"features.npz={folder / 'feat.npz'}", "--set", "pyramid.levels=2",
                           "--set", "run.backend=cpu"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode != 0
    assert "Traceback" not in proc.stderr
    # the batch names the pair's failure in one line, then ends with one Error: line
    failed = [line for line in proc.stderr.splitlines() if "failed: pair:" in line]
    assert len(failed) == 1 and "feat.npz: right_1 has NaN or inf values" in failed[0], proc.stderr
    assert [line for line in proc.stderr.splitlines() if line.startswith("Error:")] == [
        f"Error: 1 of 1 pair failed (see {tmp_path / 'out' / 'run.json'})"], proc.stderr
