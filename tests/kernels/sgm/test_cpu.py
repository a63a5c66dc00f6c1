"""Semi-global smoothing of a cost volume against a NumPy reference.

The reference states the path recursion literally, in float32 with the kernel's order of
additions (paths left, down, right, up), so the kernel must equal it exactly.
"""

from __future__ import annotations

import numpy as np
import pytest
from tests.volumes import banded

from d3cli.kernels import cpu
from d3cli.kernels.sgm import cpu as sgm_cpu
from d3cli.kernels.volume import Volume
from tests.reference.sgm import ref_sgm_paths

F32 = np.float32


def random_bands(seed, h, w, n, *, lo_below, width_below):
    """A random (H, W, n) cost and bands [lo, hi): lo < ``lo_below``, 1 <= hi - lo < ``width_below``, hi <= n."""
    rng = np.random.default_rng(seed)
    cost = rng.uniform(0, 1, (h, w, n)).astype(F32)
    lo = rng.integers(0, lo_below, (h, w))
    hi = np.minimum(n, lo + rng.integers(1, width_below, (h, w)))
    return cost, lo, hi, rng


def assert_bands_equal(flat, index, lo, hi, want):
    """Each pixel's band of a banded result (``flat`` cells, ``index`` offsets) equals ``want``'s cells there."""
    for v in range(lo.shape[0]):
        for u in range(lo.shape[1]):
            off = index[v, u, 0]
            np.testing.assert_array_equal(flat[off + lo[v, u]:off + hi[v, u]], want[v, u, lo[v, u]:hi[v, u]])


@pytest.mark.parametrize("p1, p2", [(0.0, 0.0), (0.05, 0.2), (0.4, 1.6)])
def test_dense_volume_equals_the_reference(p1, p2):
    rng = np.random.default_rng(3)
    cost = rng.uniform(0, 1, (7, 9, 6)).astype(F32)
    want, _ = ref_sgm_paths(cost, np.zeros((7, 9), int), np.full((7, 9), 6), p1, p2)
    got = cpu.sgm_smooth(cost, p1, p2)
    assert got.shape == cost.shape and got.dtype == F32
    np.testing.assert_array_equal(got, want)


def test_wide_bands_equal_the_reference():
    # bands of 1 to 21 disparities: whole blocks of the vector step, a last block that
    # overlaps the one before, and short bands alone
    h, w, n = 5, 8, 24
    cost, lo, hi, _ = random_bands(7, h, w, n, lo_below=3, width_below=22)
    want, inside = ref_sgm_paths(cost, lo, hi, 0.05, 0.3)
    got = cpu.sgm_smooth(banded(cost, lo, hi), 0.05, 0.3)
    assert_bands_equal(got.cost, got.index, lo, hi, want)
    dense = cost[:, :, :19]
    np.testing.assert_array_equal(cpu.sgm_smooth(dense, 0.05, 0.3),
                                  ref_sgm_paths(dense, np.zeros((h, w), int), np.full((h, w), 19), 0.05, 0.3)[0])


def test_banded_volume_equals_the_reference():
    cost, lo, hi, _ = random_bands(5, 6, 11, 9, lo_below=5, width_below=6)
    want, inside = ref_sgm_paths(cost, lo, hi, 0.1, 0.5)
    got = cpu.sgm_smooth(banded(cost, lo, hi), 0.1, 0.5)
    assert isinstance(got, Volume) and np.array_equal(got.index, banded(cost, lo, hi).index)
    assert_bands_equal(got.cost, got.index, lo, hi, want)


def test_without_penalties_each_path_is_the_cost_plus_nothing():
    # P2 = 0: the jump term min_k L(q, k) + P2 is the least one, so L(p, d) = C(p, d) on
    # every path and their mean is the cost itself
    cost = np.random.default_rng(8).uniform(0, 1, (4, 5, 3)).astype(F32)
    np.testing.assert_array_equal(cpu.sgm_smooth(cost, 0.0, 0.0), cost)


def test_a_lone_wrong_minimum_is_outvoted_by_its_neighbours():
    # a row of pixels whose cost says d = 2, one pixel in the middle whose cost says d = 0
    # by a small margin: with a jump penalty larger than that margin the paths carry d = 2
    cost = np.full((1, 9, 4), 0.5, F32)
    cost[0, :, 2] = 0.1
    cost[0, 4, 0] = 0.05
    assert cost[0, 4].argmin() == 0
    smoothed = cpu.sgm_smooth(cost, 0.05, 0.2)
    assert smoothed[0, 4].argmin() == 2
    assert (smoothed.argmin(axis=2) == 2).all()


def test_cells_in_no_visible_band_come_out_zero():
    # a stored volume with cells between the visible bands (as the pyramid's store around
    # them), NaN there, an empty row and an empty pixel: the bands equal the reference,
    # every other cell is 0
    h, w, n = 5, 7, 8
    cost, lo, hi, rng = random_bands(11, h, w, n, lo_below=4, width_below=5)
    hi[2, :] = lo[2, :]  # a row without cells
    hi[3, 4] = lo[3, 4]
    gaps = rng.integers(0, 3, (h, w))  # stored cells before each pixel's band
    base = np.cumsum((gaps + hi - lo).ravel()) - (hi - lo).ravel()
    index = np.stack([base.reshape(h, w) - lo, lo, hi], axis=2).astype(np.int32)
    flat = np.full(int(base[-1]) + (hi - lo)[-1, -1] + 3, np.nan, F32)  # 3 more stored cells at the end
    for v in range(h):
        for u in range(w):
            flat[index[v, u, 0] + lo[v, u]:index[v, u, 0] + hi[v, u]] = cost[v, u, lo[v, u]:hi[v, u]]
    want, inside = ref_sgm_paths(cost, lo, hi, 0.1, 0.5)
    got = cpu.sgm_smooth(Volume(flat, index, n), 0.1, 0.5).cost
    assert_bands_equal(got, index, lo, hi, want)
    visible = np.zeros(flat.shape, bool)
    for v in range(h):
        for u in range(w):
            visible[index[v, u, 0] + lo[v, u]:index[v, u, 0] + hi[v, u]] = True
    assert (~visible).sum() == gaps.sum() + 3
    assert (got[~visible] == 0).all()


@pytest.fixture
def segments(monkeypatch):
    """Sweeps cut into ``n`` segments of the columns (however narrow), more than threads."""
    def use(n):
        monkeypatch.setattr(sgm_cpu, "SGM_SEGMENTS", n)
        monkeypatch.setattr(sgm_cpu, "SGM_MIN_SEGMENT", 1)
    return use


@pytest.mark.parametrize("n_seg", [2, 3, 5, 13])
def test_segments_hand_the_row_paths_over_exactly(segments, n_seg):
    # the row paths cross 1 to 12 segment boundaries (13: a column per segment, each pixel
    # handed over), on bands that move: the result does not depend on the cut
    cost, lo, hi, _ = random_bands(21, 6, 13, 20, lo_below=6, width_below=15)
    want, _ = ref_sgm_paths(cost, lo, hi, 0.05, 0.3)
    segments(n_seg)
    assert sgm_cpu.segment_bounds(banded(cost, lo, hi).index, n_seg).shape == (n_seg + 1,)
    got = cpu.sgm_smooth(banded(cost, lo, hi), 0.05, 0.3)
    assert_bands_equal(got.cost, got.index, lo, hi, want)


def test_segments_on_one_thread_run_in_sweep_order(segments):
    # one thread takes the tasks in turn: each segment finds the one before it done
    import numba
    cost = np.random.default_rng(22).uniform(0, 1, (5, 11, 7)).astype(F32)
    want, _ = ref_sgm_paths(cost, np.zeros((5, 11), int), np.full((5, 11), 7), 0.1, 0.4)
    segments(4)
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        got = cpu.sgm_smooth(cost, 0.1, 0.4)
    finally:
        numba.set_num_threads(before)
    np.testing.assert_array_equal(got, want)


def test_segments_share_the_band_cells():
    # cells piled up on the left: the cut lies left of the middle, the shares near equal
    h, w = 4, 200
    lo = np.zeros((h, w), int)
    hi = np.where(np.arange(w)[None, :] < 50, 40, 4) + lo
    cost = np.zeros((h, w, 40), F32)
    index = banded(cost, lo, hi).index
    bounds = sgm_cpu.segment_bounds(index, 2)
    assert bounds[0] == 0 and bounds[-1] == w and bounds.shape == (3,)
    cells = (hi - lo).sum(axis=0)
    left, right = cells[:bounds[1]].sum(), cells[bounds[1]:].sum()
    assert abs(left - right) <= cells.max()
    assert bounds[1] < 50
    # narrow images: no segment narrower than SGM_MIN_SEGMENT columns
    assert sgm_cpu.segment_bounds(index, 64).shape[0] - 1 == w // sgm_cpu.SGM_MIN_SEGMENT
    assert sgm_cpu.segment_bounds(index[:, :sgm_cpu.SGM_MIN_SEGMENT + 1], 2).tolist() == [0, sgm_cpu.SGM_MIN_SEGMENT + 1]


def test_a_segment_waiting_for_one_that_failed_gives_up_on_abort():
    # segment 1 waits for segment 0's rows; segment 0 never ran (it failed, or Ctrl-C came
    # before it was taken): with abort set the wait ends instead of spinning for good
    import threading

    cost, lo, hi, _ = random_bands(23, 4, 9, 6, lo_below=2, width_below=4)
    vol = banded(cost, lo, hi)
    bounds = np.array([0, 4, 9], np.int64)
    n_disp = vol.n_disp
    acc = np.zeros_like(vol.cost)
    hand = np.zeros((1, 4, n_disp + 2), F32)
    hand_least = np.zeros((1, 4), F32)
    done = np.zeros(2, np.int64)
    abort = np.ones(1, np.int64)
    args = (1, 2, vol.cost, vol.index, bounds, F32(0.1), F32(0.5), acc, hand, hand_least, done, abort)
    worker = threading.Thread(target=sgm_cpu.forward_task, args=args, daemon=True)
    worker.start()
    worker.join(timeout=120)  # the first call compiles
    assert not worker.is_alive()
    assert done.tolist() == [0, 0] and not acc.any()  # stopped before its first row
