"""The hole filling (``d3cli.kernels.finishing.fill``, through
``d3cli.method.refinement.fill_holes``) against the NumPy formulation it replaced: rows with
nothing valid, nothing or everything valid, inf and NaN estimates, ties of signed zeros.
"""

from __future__ import annotations

import numpy as np
import pytest

from d3cli.kernels import finishing
from d3cli.method.refinement import fill_holes

from tests.reference.finishing import SHAPES, assert_same_bytes, random_map, ref_fill_holes, ref_nearest_along_rows


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("smooth", [False, True])
@pytest.mark.parametrize("inside", [False, True])
def test_fill_holes_matches_reference(shape, smooth, inside):
    rng = np.random.default_rng(hash((shape, smooth, inside)) % 2**32)
    for share in (0.0, 0.05, 0.5, 0.95, 1.0):
        disp, valid = random_map(rng, shape, valid_share=share)
        occluded = (rng.random(shape) < 0.4) & ~valid if inside else None
        got = fill_holes(disp, valid, smooth=smooth, occluded=occluded)
        want = ref_fill_holes(disp, valid, smooth=smooth, occluded=occluded)
        assert_same_bytes(got, want, f"{shape} {share} smooth={smooth} inside={inside}")


def test_fill_rows_runs_ties_and_signed_zeros_match_reference():
    """Runs of holes at both row ends, single holes, and ties of -0 and +0 between the two
    sides (np.minimum's choice), filled by whole runs."""
    rng = np.random.default_rng(8)
    disp = rng.choice(np.array([-0.0, 0.0, 1.0, 2.0], np.float32), size=(40, 23))
    valid = rng.random(disp.shape) < 0.45
    valid[:, :3] = False  # a run at the left end
    valid[::2, -4:] = False  # and at the right end
    valid[5] = False  # a row without a valid pixel
    disp[~valid & (rng.random(disp.shape) < 0.5)] = np.inf
    got = fill_holes(disp, valid, smooth=False)
    assert_same_bytes(got, ref_fill_holes(disp, valid, smooth=False), "ties")


def test_fill_inside_on_ties_and_signed_zeros_equals_the_insertion_sort():
    """The branch-free sorting network of ``fill_inside`` against the formulation it
    replaced (an insertion sort of the finite values in the order left, right, up, down;
    the row neighbours from the reference's scans): many equal values and both signed
    zeros, so that the order of equals and which neighbour a value came from show in the
    bits."""
    rng = np.random.default_rng(4)
    shape = (40, 50)
    choices = np.array([-0.0, 0.0, 1.0, 2.0, 2.5], np.float32)
    up_down = np.array([-0.0, 0.0, 1.0, 2.0, np.inf], np.float32)
    for share in (0.0, 0.2, 0.7, 1.0):
        disp = choices[rng.integers(0, 5, shape)]
        valid = rng.random(shape) < share
        occluded = (rng.random(shape) < 0.2) & ~valid
        left, right = (x.astype(np.float32) for x in ref_nearest_along_rows(disp, valid))
        up, down = (up_down[rng.integers(0, 5, shape)] for _ in range(2))
        want = np.empty(shape, np.float32)
        for y in range(shape[0]):
            for u in range(shape[1]):
                if valid[y, u]:
                    want[y, u] = disp[y, u]
                    continue
                side = left[y, u] if left[y, u] < right[y, u] else right[y, u]
                buf = []
                for v in (left[y, u], right[y, u], up[y, u], down[y, u]):
                    if np.isfinite(v):
                        i = len(buf)
                        while i > 0 and buf[i - 1] > v:
                            i -= 1
                        buf.insert(i, v)
                n = len(buf)
                if occluded[y, u] or n == 0:
                    want[y, u] = side
                elif n % 2:
                    want[y, u] = buf[n // 2]
                else:
                    want[y, u] = (buf[n // 2 - 1] + buf[n // 2]) / np.float32(2.0)
        assert_same_bytes(finishing.fill_inside(disp, valid, occluded, up, down), want, f"fill_inside {share}")


@pytest.mark.parametrize("shape", SHAPES)
def test_nearest_along_columns_equals_reference(shape):
    """The up/down neighbours of ``fill_inside`` against the reference's row scan of the
    transposed map (ties and both signed zeros)."""
    rng = np.random.default_rng(hash(shape) % 2**32)
    choices = np.array([-0.0, 0.0, 1.0, 2.0, 2.5], np.float32)
    for share in (0.0, 0.2, 0.7, 1.0):
        disp = choices[rng.integers(0, 5, shape)]
        valid = rng.random(shape) < share
        up, down = (x.T for x in ref_nearest_along_rows(disp.T, valid.T))
        up_k, down_k = finishing.nearest_along_columns(disp, valid)
        assert_same_bytes(up_k, np.ascontiguousarray(up, np.float32), f"up {shape} {share}")
        assert_same_bytes(down_k, np.ascontiguousarray(down, np.float32), f"down {shape} {share}")


def test_fill_holes_empty_rows_copy_the_nearest_row_upper_on_a_tie():
    disp = np.full((7, 4), np.inf, np.float32)
    valid = np.zeros((7, 4), bool)
    disp[1] = 1.0
    disp[5] = 5.0
    valid[[1, 5]] = True
    got = fill_holes(disp, valid, smooth=False)
    np.testing.assert_array_equal(got[:, 0], [1, 1, 1, 1, 5, 5, 5])  # row 3: tie, upper row 1
    assert_same_bytes(got, ref_fill_holes(disp, valid, smooth=False))


@pytest.mark.parametrize("shape", [(1, 1), (6, 1), (7, 13), (23, 31)])
def test_the_cpu_backends_fill_inside_matches_fill_holes(shape):
    """The backend contract's ``fill_inside`` (and its median, ``median_of_holes``) against
    ``refinement.fill_holes`` with the occluded pixels."""
    rng = np.random.default_rng(hash(shape) % 2**32)
    for share in (0.0, 0.05, 0.6, 1.0):
        disp, valid = random_map(rng, shape, valid_share=share)
        if disp.size > 3:
            disp.reshape(-1)[1], valid.reshape(-1)[1] = np.nan, True  # valid, not usable
        occluded = (rng.random(shape) < 0.4) & ~valid
        filled, use = finishing.fill_inside_holes(disp, valid, occluded)
        np.testing.assert_array_equal(use, valid & np.isfinite(disp))
        assert_same_bytes(filled, fill_holes(disp, valid, smooth=False, occluded=occluded), f"{shape} {share}")
        if min(shape) >= 5:
            assert_same_bytes(finishing.fill.median_of_holes(filled, use),
                              fill_holes(disp, valid, smooth=True, occluded=occluded), f"{shape} {share} median")
