"""The re-match of a defect's zone: windows sharing one set of warps give what separate calls give."""

from __future__ import annotations

import numpy as np

from d3cli.road.rematch import WINDOWS, rematch
from tests.helpers import textured_pair


def test_shared_warps_give_the_results_of_separate_calls():
    left, right, disparity = textured_pair(6, (120, 160), seed=3)
    disp = np.asarray(disparity, np.float32) + np.float32(0.3)
    zone = np.zeros(disp.shape, bool)
    zone[40:80, 60:110] = True
    shared = {"pad_window": max(WINDOWS)}
    for window in WINDOWS:
        alone = rematch(left, right, disp, zone, window=window)
        together = rematch(left, right, disp, zone, window=window, shared=shared)
        np.testing.assert_array_equal(alone[0], together[0])
        np.testing.assert_array_equal(alone[1], together[1])
    assert shared["warps"] is not None  # the shared path was taken
    holed = disp.copy()
    holed[50, 70] = np.inf  # a pixel without an estimate: each call on its own
    shared = {"pad_window": max(WINDOWS)}
    for window in WINDOWS:
        np.testing.assert_array_equal(rematch(left, right, holed, zone, window=window)[0],
                                      rematch(left, right, holed, zone, window=window, shared=shared)[0])
