"""The finishing kernels on the task pool: the same bytes with one thread and with all,
compiled once, cached on disk and releasing the GIL."""

from __future__ import annotations

import numba
import numpy as np

from d3cli.kernels import finishing
from d3cli.method.refinement import drop_occluded, drop_speckles, fill_holes, occluded_by_uniqueness, out_of_view, \
    smooth_disparity

from tests.reference.finishing import assert_same_bytes, random_map


def test_kernels_give_the_same_bytes_with_one_thread_and_with_all():
    rng = np.random.default_rng(5)
    disp, valid = random_map(rng, (61, 77), spread=30)
    occluded = (rng.random(disp.shape) < 0.3) & ~valid
    yy, xx = np.mgrid[0:61, 0:77]
    plane = (2.0 + 0.1 * yy).astype(np.float32)

    def run():
        return [
            occluded_by_uniqueness(disp, valid),
            out_of_view(disp, valid, max_disparity=20),
            *drop_occluded(disp, valid.copy(), max_disparity=20)[::2],
            drop_speckles(disp, valid.copy(), max_size=20, max_diff=1.0)[1],
            fill_holes(disp, valid, smooth=True),
            fill_holes(disp, valid, smooth=True, occluded=occluded),
            smooth_disparity(fill_holes(disp, valid), valid, radius=5, sigma=1.5, plane=plane),
            smooth_disparity(fill_holes(disp, valid), valid, radius=3, sigma=1.5, plane=plane, kernel="box"),
        ]

    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        single = run()
    finally:
        numba.set_num_threads(threads)
    for a, b in zip(single, run()):
        assert_same_bytes(a, b)


def test_finishing_kernels_are_cached_and_release_the_gil():
    """Compiled once and cached on disk (a read-only install uses the user cache folder
    that importing d3cli.kernels.cpu chose); nogil, so that the pool threads run them
    side by side."""
    assert len(finishing.KERNELS) >= 10
    for kernel in finishing.KERNELS:
        assert isinstance(kernel, numba.core.registry.CPUDispatcher), kernel
        assert kernel.targetoptions.get("nogil") is True, kernel.py_func.__name__
        assert type(kernel._cache).__name__ == "FunctionCache", kernel.py_func.__name__

