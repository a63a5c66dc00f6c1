"""Which PT estimates survive the restore (no negative disparity among them)."""

import numpy as np

from d3cli.method.perspective import restored_validity


def test_range_ends_outside_matches_and_negative_disparities_become_holes():
    narrow = np.array([[0, 3, 5, 18], [4, 4, 4, 9]], np.float32)  # narrow range 0..18
    restored = np.array([[2.0, 1.5, -0.4, 30.0], [-7.5, 4.2, 9.0, np.nan]], np.float32)
    valid = np.ones_like(narrow, bool)
    kept, shares = restored_validity(valid, narrow, restored, narrow_range=18)
    # matches u - d left of the image: 2 at u=0, 30 at u=3, 4.2 at u=1, 9 at u=2, and NaN
    assert kept.tolist() == [[False, True, False, False], [False, False, False, False]]
    assert shares["range_end_share"] == 2 / 8      # d' = 0 and d' = 18
    assert shares["outside_share"] == 5 / 8
    assert shares["negative_share"] == 2 / 8       # -0.4, -7.5 (not already dropped)


def test_undecided_pixels_stay_undecided():
    narrow = np.full((2, 3), 4.0, np.float32)
    restored = np.full((2, 3), 1.0, np.float32)
    valid = np.zeros((2, 3), bool)
    kept, shares = restored_validity(valid, narrow, restored, narrow_range=18)
    assert not kept.any() and all(v == 0 for v in shares.values())
