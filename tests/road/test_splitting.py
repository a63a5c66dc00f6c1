"""Cutting joined potholes apart leaves no inner fragment (d3cli.road.splitting)."""

import cv2
import numpy as np

from d3cli.road.splitting import split_parts


def _floor_with_spots():
    # A 25 mm flat floor (radius 80 px, walls to 100 px) with five spots 20 mm deeper: one
    # in the middle, four 60 px around it (a broken floor, or specular blobs on a wet one).
    # Each spot stands 20 mm above the saddles: the depth-saddle cue cuts five pieces, the
    # middle one enclosed by the other four.
    v, u = np.mgrid[0:260, 0:260].astype(float)
    depth = np.where(np.hypot(u - 130, v - 130) < 100, 0.025 * np.clip((100 - np.hypot(u - 130, v - 130)) / 20, 0, 1),
                     -0.001)
    for cu, cv_ in ((130, 130), (190, 130), (70, 130), (130, 190), (130, 70)):
        depth += 0.02 * np.clip(1 - np.hypot(u - cu, v - cv_) / 14, 0, None)
    return depth.astype(np.float32)


def test_a_fragment_enclosed_by_the_other_parts_is_merged_into_one_of_them():
    depth = _floor_with_spots()
    region = depth > 0.01
    n, labels = cv2.connectedComponents(region.astype(np.uint8))
    parts = list(split_parts(labels, n, depth, np.full(depth.shape, 1e-5), level=0.01, prominence=0.006,
                             smooth_px=2.0, neck=0.9, min_part_m2=0.01, step=0.01))
    # Was five parts, the middle spot's (3572 px) bordering no road at all: a duplicate
    # that measured one pothole's deepest spot.
    assert sorted(int(p.sum()) for p in parts) == [6101, 6170, 14290]
    assert np.array_equal(np.logical_or.reduce(parts), region)
    rim = cv2.dilate((~region).astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    assert all((p & rim).any() for p in parts)


def test_parts_cut_to_their_boxes_are_the_whole_image_parts():
    depth = _floor_with_spots()
    region = (depth > 0.01) | (np.hypot(*np.mgrid[-20:240, -20:240]) < 12)  # and a blob at the corner
    n, labels = cv2.connectedComponents(region.astype(np.uint8))
    kw = dict(level=0.01, prominence=0.006, smooth_px=2.0, neck=0.9, min_part_m2=0.01, step=0.01)
    whole = list(split_parts(labels, n, depth, np.full(depth.shape, 1e-5), **kw))
    boxed = list(split_parts(labels, n, depth, np.full(depth.shape, 1e-5), boxes=True, **kw))
    assert len(whole) == len(boxed) == 4
    for mask, (piece, box) in zip(whole, boxed):
        assert piece.shape == mask[box].shape and np.array_equal(mask[box], piece) and mask.sum() == piece.sum()


def test_the_smoothed_depth_of_a_box_is_the_whole_maps_there():
    from d3cli.road.splitting import smoothed_depth

    rng = np.random.default_rng(3)
    depth = rng.normal(0.0, 0.01, (150, 230)).astype(np.float32)
    depth[rng.random(depth.shape) < 0.1] = np.inf  # no estimate: 0 in the smoothing
    whole = smoothed_depth(depth, 12.0)
    for box in ((slice(0, 150), slice(0, 230)), (slice(0, 20), slice(0, 30)), (slice(60, 90), slice(100, 160)),
                (slice(130, 150), slice(200, 230)), (slice(5, 145), slice(70, 71))):
        np.testing.assert_array_equal(smoothed_depth(depth, 12.0, box), whole[box])  # bit for bit
    np.testing.assert_array_equal(smoothed_depth(depth, 0.0, (slice(3, 9), slice(4, 8))),
                                  np.where(np.isfinite(depth), depth, 0.0)[3:9, 4:8])


def test_the_median_test_of_the_terrace_cue_is_numpys():
    from d3cli.road.splitting import median_below

    rng = np.random.default_rng(5)
    for _ in range(2000):
        values = (rng.integers(0, 6, (6, 5)) / 4).astype(np.float32)  # ties at the threshold
        mask = rng.random(values.shape) < 0.5
        if not mask.any():
            continue
        x = float(rng.integers(0, 6)) / 4 + float(rng.choice([0.0, 0.1, -0.1]))
        assert median_below(values, mask, x) == bool(np.median(values[mask]) < x)
