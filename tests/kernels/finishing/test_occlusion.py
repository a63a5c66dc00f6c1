"""The occlusion tests of the finishing (``d3cli.kernels.finishing.occlusion``, through
``d3cli.method.refinement`` and ``d3cli.method.perspective``) against the NumPy formulation
they replaced: the same bytes on random maps and on the edge cases (nothing or everything
valid, inf and NaN estimates, half-integer matches, widths and heights 1..5).
"""

from __future__ import annotations

import numpy as np
import pytest

from d3cli.kernels import road_model
from d3cli.method.perspective import match_in_right_image, restored_shares, restored_validity, restored_validity_counts
from d3cli.method.refinement import drop_occluded, occluded_by_uniqueness, out_of_view

from tests.reference.finishing import (SHAPES, assert_same_bytes, random_map, ref_drop_occluded,
                                       ref_occluded_by_uniqueness, ref_out_of_view, ref_restored_validity,
                                       ref_right_image)


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("integers", [False, True])
def test_uniqueness_matches_reference(shape, integers):
    rng = np.random.default_rng(hash((shape, integers)) % 2**32)
    for share in (0.0, 0.5, 0.9, 1.0):
        disp, valid = random_map(rng, shape, valid_share=share, spread=min(shape[1], 8), integers=integers)
        for tolerance in (0.0, 0.5, 1.0):
            got = occluded_by_uniqueness(disp, valid, tolerance=tolerance)
            want = ref_occluded_by_uniqueness(disp, valid, tolerance=tolerance)
            np.testing.assert_array_equal(got, want, err_msg=f"{shape} {share} {tolerance}")


def test_uniqueness_with_inf_and_nan_marked_valid_matches_reference():
    """Non-finite estimates flagged valid: NumPy casts their target to int64 min, which
    clips to column 0; a NaN wins the maximum there (np.maximum propagates it)."""
    rng = np.random.default_rng(3)
    disp, _ = random_map(rng, (9, 17), spread=6)
    valid = np.ones(disp.shape, bool)
    disp[2, 5] = np.inf
    disp[3, 0] = -np.inf
    disp[4, 7] = np.nan
    disp[5, 2] = 1e30
    disp[5, 3] = -1e30
    got = occluded_by_uniqueness(disp, valid)
    np.testing.assert_array_equal(got, ref_occluded_by_uniqueness(disp, valid))


@pytest.mark.parametrize("shape", SHAPES)
def test_out_of_view_matches_reference(shape):
    rng = np.random.default_rng(hash(shape) % 2**32)
    for share in (0.0, 0.3, 1.0):
        disp, valid = random_map(rng, shape, valid_share=share, spread=shape[1] + 2)
        for max_disparity in range(0, shape[1] + 3):
            got = out_of_view(disp, valid, max_disparity=max_disparity)
            want = ref_out_of_view(disp, valid, max_disparity=max_disparity)
            np.testing.assert_array_equal(got, want, err_msg=f"{shape} {share} {max_disparity}")


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("in_place", [False, True])
def test_drop_occluded_matches_the_two_tests_and_the_masking(shape, in_place):
    rng = np.random.default_rng(hash((shape, in_place, 1)) % 2**32)
    # (rows with more than 1/8 holes take the kernel's select loop, the others its branches)
    for share in (0.0, 0.5, 0.9, 1.0):
        for integers in (False, True):
            disp, valid = random_map(rng, shape, valid_share=share, spread=min(shape[1], 8), integers=integers)
            for max_disparity in (0, 1, shape[1] // 2, shape[1] + 2):
                occ, want_valid, want_out, share_want = ref_drop_occluded(disp, valid, max_disparity=max_disparity)
                got_valid = valid.copy()
                src = disp.copy()
                got_occ, count, got_out = drop_occluded(src, got_valid, max_disparity=max_disparity,
                                                        out=src if in_place else None)
                msg = f"{shape} {share} {max_disparity}"
                np.testing.assert_array_equal(got_occ, occ, err_msg=msg)
                np.testing.assert_array_equal(got_valid, want_valid, err_msg=msg)
                assert_same_bytes(got_out, want_out, msg)
                assert count / disp.size == share_want and (got_out is src) == in_place


def test_drop_occluded_with_inf_and_nan_marked_valid_matches_reference():
    rng = np.random.default_rng(4)
    disp, _ = random_map(rng, (9, 17), spread=6)
    valid = np.ones(disp.shape, bool)
    disp[2, 5], disp[3, 0], disp[4, 7], disp[5, 2], disp[5, 3] = np.inf, -np.inf, np.nan, 1e30, -1e30
    occ, want_valid, want_out, _ = ref_drop_occluded(disp, valid, max_disparity=4)
    got_occ, _, got_out = drop_occluded(disp, valid, max_disparity=4)
    np.testing.assert_array_equal(got_occ, occ)
    np.testing.assert_array_equal(valid, want_valid)
    assert_same_bytes(got_out, want_out)


@pytest.mark.parametrize("narrow_dtype", [np.int32, np.float32, np.float64])
@pytest.mark.parametrize("narrow_range", [18, 18.0, 17.3, np.float64(17.3)])
def test_restored_validity_kernel_matches_the_numpy_formulation(narrow_dtype, narrow_range):
    rng = np.random.default_rng(11)
    h, w = 37, 53
    narrow = (rng.random((h, w)) * 21 - 1).astype(np.float32)
    narrow[rng.random((h, w)) < 0.3] = 17.3
    narrow = narrow.astype(narrow_dtype)
    restored = (rng.random((h, w)) * 70 - 10).astype(np.float32)
    cols = np.arange(w, dtype=np.float32)
    restored[:, 5] = cols[5] + 0.5  # exactly half a pixel left of the image: kept
    restored[:, 6] = np.nextafter(cols[6] + np.float32(0.5), np.float32(np.inf))
    restored[1, :] = np.inf
    restored[2, :] = -np.inf
    restored[3, :] = np.nan
    restored[4, :] = -0.0
    valid = rng.random((h, w)) < 0.8
    want_valid, want_shares, want_masked = ref_restored_validity(valid, narrow, restored, narrow_range=narrow_range)
    got_valid, got_shares = restored_validity(valid, narrow, restored, narrow_range=narrow_range)
    np.testing.assert_array_equal(got_valid, want_valid)
    assert got_shares == want_shares and all(type(v) is float for v in got_shares.values())
    kept, counts, masked = restored_validity_counts(valid, narrow, restored, narrow_range=narrow_range, masked=True)
    np.testing.assert_array_equal(kept, want_valid)
    assert restored_shares(counts, kept.size) == want_shares
    assert_same_bytes(masked, want_masked)
    # a float64 map of the same values: the same verdicts (u - d is exact near the bound)
    restored64 = restored.astype(np.float64)
    got64, shares64 = restored_validity(valid, narrow, restored64, narrow_range=narrow_range)
    want64, want_shares64, _ = ref_restored_validity(valid, narrow, restored64, narrow_range=narrow_range)
    np.testing.assert_array_equal(got64, want64)
    assert shares64 == want_shares64



@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_the_right_image_mask_is_the_road_models_rule(dtype):
    """One rule for PT's validity and the road report: the match ``u - d`` at or right of
    -0.5 (the area of the first right pixel), computed in float64 over a map; NaN and +inf
    are not in the image, -inf only without ``finite``."""
    rng = np.random.default_rng(5)
    h, w = 23, 41
    disp = (rng.random((h, w)) * 60 - 5).astype(dtype)
    cols = np.arange(w, dtype=dtype)
    disp[:, 7] = cols[7] + dtype(0.5)  # exactly half a pixel left of the image: in
    disp[:, 8] = np.nextafter(cols[8] + dtype(0.5), dtype(np.inf))  # just beyond: out
    disp[1, :] = np.inf
    disp[2, :] = -np.inf
    disp[3, :] = np.nan
    want = ref_right_image(disp)
    np.testing.assert_array_equal(match_in_right_image(disp), want)
    np.testing.assert_array_equal(match_in_right_image(disp, finite=True), want & np.isfinite(disp))
    assert want[4:, 7].all() and not want[4:, 8].any() and want[2].all() and not want[[1, 3]].any()
    assert road_model.RIGHT_IMAGE_SLACK == 0.5
    rule = road_model.build(lambda f: f)  # the per-pixel form, plain Python
    assert rule.in_right_image(3, 3.5) and not rule.in_right_image(3, 3.75) and not rule.in_right_image(0, np.nan)


@pytest.mark.parametrize("narrow_range", [6, 9])
def test_the_cpu_backends_pt_validity_is_the_pipelines_restored_validity(narrow_range):
    """``pt_validity`` and ``count_range_ends`` (the CPU backend's) give what the host
    formulation gives: :func:`restored_validity_counts` and :func:`band_end_share`."""
    from d3cli.kernels import cpu
    from d3cli.method.perspective import band_end_share, restored_validity_counts

    rng = np.random.default_rng(narrow_range)
    narrow = rng.integers(-1, 11, (13, 29)).astype(np.int32)
    restored = (rng.random((13, 29)) * 30.0 - 3.0).astype(np.float32)
    restored[0, :4] = [np.inf, np.nan, -0.0, 0.5]
    kept, masked, counts = cpu.pt_validity(narrow, restored, narrow_range)
    want_kept, want_counts, want_masked = restored_validity_counts(narrow >= 0, narrow, restored,
                                                                   narrow_range=narrow_range, masked=True)
    np.testing.assert_array_equal(kept, want_kept)
    assert masked.tobytes() == want_masked.tobytes() and counts == [int(c) for c in want_counts]
    share = band_end_share(narrow, narrow_range=narrow_range)
    assert float(cpu.count_range_ends(narrow, narrow_range)) / narrow.size == share
