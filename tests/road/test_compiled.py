"""The compiled loops of the road report against the NumPy expressions they replace."""

from __future__ import annotations

import numpy as np
import pytest

from d3cli.road import compiled
from d3cli.road.pointcloud import Camera, disparity_to_points


def _points(n=5000, seed=1):
    rng = np.random.default_rng(seed)
    x, z = rng.uniform(-3, 3, n), rng.uniform(4, 30, n)
    y = 1.5 - 0.02 * z + rng.normal(0, 0.01, n)
    y[: n // 20] -= 0.08  # a pothole: outliers
    return np.stack([x, y, z], axis=1).astype(np.float32)


def _columns(points):
    return tuple(np.ascontiguousarray(points[:, i]) for i in range(3))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_weighted_scatter_is_the_tukey_round(dtype):
    pts = _points().astype(dtype)
    normal, offset = np.array([0.0, -0.9998, -0.02]), 1.5
    normal /= np.linalg.norm(normal)
    tol = np.maximum(0.01, pts[:, 2].astype(np.float64) ** 2 / 500.0)
    p = pts.astype(np.float64)
    total, centre, scatter = compiled.weighted_scatter(*_columns(p), 1.0 / tol, normal, offset, 2.0)
    r = (p @ normal + offset) / tol
    w = np.where(np.abs(r) < 2.0, (1 - (r / 2.0) ** 2) ** 2, 0.0)
    ref_centre = (p * w[:, None]).sum(0) / w.sum()
    d = (p - ref_centre) * np.sqrt(w)[:, None]
    # the tolerance is z^2 * (1 / 500) there: weights to rounding
    assert total == pytest.approx(w.sum(), rel=1e-9)
    np.testing.assert_allclose(centre, ref_centre, rtol=1e-9)
    np.testing.assert_allclose(scatter, d.T @ d, rtol=1e-8, atol=1e-10)
    assert 0 < (w == 0).sum() < len(w)  # both kinds of point were exercised


def test_weighted_scatter_without_weight_is_zero():
    pts = _points(100).astype(np.float64)
    total, centre, scatter = compiled.weighted_scatter(*_columns(pts), np.full(100, 100.0), np.array([0.0, 1.0, 0.0]),
                                                       100.0, 2.0)
    assert total == 0.0 and not centre.any() and not scatter.any()


def test_inlier_count_and_ransac_scores_match_numpy():
    pts = _points().astype(np.float64)
    tol = np.maximum(0.01, pts[:, 2] ** 2 / 500.0)
    rng = np.random.default_rng(0)
    triples = np.array([rng.choice(len(pts), 3, replace=False) for _ in range(40)] + [[3, 3, 7]], np.int64)
    scores, normals, offsets = compiled.ransac_scores(pts, triples, tol)
    for (i, j, k), score, n, c in zip(triples, scores, normals, offsets):
        a, b, c3 = pts[i], pts[j], pts[k]
        ref = np.cross(b - a, c3 - a)
        if np.linalg.norm(ref) < 1e-12:
            assert score == -1
            continue
        ref /= np.linalg.norm(ref)
        np.testing.assert_allclose(n, ref, rtol=1e-12, atol=1e-15)
        assert c == pytest.approx(-float(ref @ a), rel=1e-12, abs=1e-15)
        assert score == (np.abs(pts @ ref - float(ref @ a)) < tol).sum()
        p32 = pts.astype(np.float32).astype(np.float64)
        tol32 = np.maximum(0.01, p32[:, 2] ** 2 / 500.0)
        assert compiled.inlier_count(*_columns(p32), tol32, n, c) == (np.abs(p32 @ n + c) < tol32).sum()
    assert scores[-1] == -1


def test_height_grid_is_the_height_of_the_back_projected_points():
    rng = np.random.default_rng(3)
    disp = rng.uniform(-1, 60, (48, 64)).astype(np.float32)
    disp[rng.random(disp.shape) < 0.1] = np.inf
    valid = rng.random(disp.shape) < 0.9
    cam = Camera(f=500.0, baseline=0.3, cx=31.5, cy=20.0, doffs=0.5)
    normal, offset = np.array([0.01, -0.999, -0.03]), 1.6
    normal /= np.linalg.norm(normal)
    points, index = disparity_to_points(disp, valid, cam)
    ref = np.full(disp.shape, np.inf, np.float32)
    ref[index[:, 0], index[:, 1]] = points.astype(np.float64) @ normal + offset
    got = compiled.height_grid(disp, valid, cam.f, cam.baseline, cam.cx, cam.cy, cam.doffs, normal, offset)
    np.testing.assert_array_equal(np.isfinite(got), np.isfinite(ref))
    np.testing.assert_allclose(got, ref, rtol=1e-6, atol=1e-7)
    # a window of the map, given its origin, is the same window of the heights
    win = compiled.height_grid(disp[10:30, 20:50], valid[10:30, 20:50], cam.f, cam.baseline, cam.cx, cam.cy,
                               cam.doffs, normal, offset, 10, 20)
    np.testing.assert_array_equal(win, got[10:30, 20:50])


def _smooth_noise(rng, shape, sigma):
    import cv2

    img = cv2.GaussianBlur(rng.normal(0, 1, shape).astype(np.float32), (0, 0), sigma)
    img[rng.random(shape) < 0.2] = 0
    return img


@pytest.mark.parametrize("plateaus", [False, True])
def test_h_maxima_is_scikit_images(plateaus):
    from skimage.morphology import h_maxima

    rng = np.random.default_rng(5)
    for _ in range(40):
        img = _smooth_noise(rng, tuple(rng.integers(3, 70, 2)), rng.uniform(0.5, 4))
        if plateaus:
            img = np.round(img * 4) / 4
        for h in (0.05, np.float64(0.1), 0.3, 100.0):  # a numpy h: float64 arithmetic, as in the neck cue
            expected, got = h_maxima(img, h), compiled.h_maxima(img, h)
            assert got.dtype == expected.dtype
            np.testing.assert_array_equal(got, expected)
        logs = np.log1p(np.abs(img))
        np.testing.assert_array_equal(compiled.h_maxima(logs, -np.log(0.9)), h_maxima(logs, -np.log(0.9)))


@pytest.mark.parametrize("shape", ["ellipse", "rect", "cross"])
def test_dilation_and_opening_are_opencvs(shape):
    import cv2

    kind = {"ellipse": cv2.MORPH_ELLIPSE, "rect": cv2.MORPH_RECT, "cross": cv2.MORPH_CROSS}[shape]
    rng = np.random.default_rng(7)
    for _ in range(60):
        mask = rng.random(tuple(rng.integers(1, 120, 2))) < rng.uniform(0.001, 0.6)
        r = int(rng.integers(0, 50))
        kernel = cv2.getStructuringElement(kind, (2 * r + 1, 2 * r + 1))
        np.testing.assert_array_equal(compiled.dilate(mask, kernel), cv2.dilate(mask.astype(np.uint8), kernel) > 0)
        np.testing.assert_array_equal(compiled.opening(mask, kernel),
                                      cv2.morphologyEx(mask.astype(np.uint8), cv2.MORPH_OPEN, kernel) > 0)


def test_other_kernels_go_to_opencv():
    import cv2

    kernel = np.array([[1, 0, 1], [0, 1, 0], [1, 1, 0]], np.uint8)  # rows that are not centred runs
    assert compiled.symmetric_half_widths(kernel) is None
    mask = np.random.default_rng(2).random((20, 30)) < 0.1
    np.testing.assert_array_equal(compiled.dilate(mask, kernel), cv2.dilate(mask.astype(np.uint8), kernel) > 0)


def test_back_project_is_disparity_to_points():
    rng = np.random.default_rng(8)
    disp = rng.uniform(-2, 60, (40, 70)).astype(np.float32)
    disp[rng.random(disp.shape) < 0.1] = np.inf
    disp[0, :3] = np.nan
    valid = rng.random(disp.shape) < 0.8
    cam = Camera(f=700.0, baseline=0.2, cx=35.0, cy=19.5, doffs=1.5)
    points, _ = disparity_to_points(disp, valid, cam)
    got = compiled.back_project(disp, valid, cam.f, cam.baseline, cam.cx, cam.cy, cam.doffs)
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got, points)


def _columns(points):
    return tuple(np.ascontiguousarray(points[:, i]) for i in range(3))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_median_is_numpys(dtype):
    rng = np.random.default_rng(11)
    # sizes on both sides of numpy's own range (16384) and of odd and even counts; a spread
    # of values, ties, a heavy tail and a constant array
    for n in (5, 16384, 16385, 20000, 50001):
        for values in (rng.normal(0, 0.01, n), np.round(rng.normal(0, 3, n)), rng.standard_cauchy(n),
                       np.full(n, 0.25)):
            values = values.astype(dtype)
            got, expected = compiled.median(values), np.median(values)
            assert type(got) is type(expected) and got == expected


def test_ranks_are_the_sorted_values():
    rng = np.random.default_rng(12)
    values = rng.exponential(1.0, 30000)
    ordered = np.sort(values)
    for k0, k1 in ((0, 0), (0, 1), (14999, 15000), (29998, 29999), (100, 4000)):
        assert compiled.ranks(values, k0, k1) == (ordered[k0], ordered[k1])


def test_window_medians_are_nanmedians():
    rng = np.random.default_rng(13)
    depth = rng.normal(0.02, 0.01, (40, 50)).astype(np.float32)  # the report's depths: float32, as its means
    depth[rng.random(depth.shape) < 0.2] = np.inf
    depth[:9, :9] = np.inf  # a window with no finite value: NaN
    vs, us = rng.integers(0, 40, 60), rng.integers(0, 50, 60)
    vs[0], us[0] = 2, 2
    r = 3
    got = compiled.window_medians(depth, vs, us, r)
    finite = np.where(np.isfinite(depth), depth, np.nan)
    with np.errstate(all="ignore"), pytest.warns(RuntimeWarning):
        expected = [np.nanmedian(finite[max(v - r, 0):v + r + 1, max(u - r, 0):u + r + 1]) for v, u in zip(vs, us)]
    np.testing.assert_array_equal(got, np.array(expected, np.float64))
    assert np.isnan(got[0]) and np.isfinite(got[1:]).any()


def test_height_colours_are_the_numpy_ramp():
    rng = np.random.default_rng(14)
    height = rng.normal(0, 0.03, (30, 40)).astype(np.float32)
    height[rng.random(height.shape) < 0.1] = np.inf
    height[0, :4] = (np.nan, -np.inf, 3e38, -1e-9)
    range_mm = 50.0
    finite = np.isfinite(height)
    with np.errstate(over="ignore", invalid="ignore"):
        t = np.clip(np.where(finite, height * 1e3, 0.0) / range_mm, -1.0, 1.0)
    ramp = np.stack([np.where(t < 0, 1 + t, 1.0), 1 - np.abs(t), np.where(t > 0, 1 - t, 1.0)], axis=-1)
    expected = (ramp * 255).astype(np.uint8)
    expected[~finite] = 96
    got = np.empty(expected.shape, np.uint8)
    with np.errstate(over="ignore"):
        compiled.height_colours(height, range_mm, got)
    np.testing.assert_array_equal(got, expected)


def _camera_and_plane():
    from d3cli.road.plane import RoadPlane

    n = np.array([0.02, -0.97, -0.2])
    n /= np.linalg.norm(n)
    return Camera(f=90.5, baseline=0.3, cx=31.5, cy=30.25), RoadPlane(tuple(float(x) for x in n), 1.55, 0.9)


def test_footprint_grid_is_the_numpy_footprint():
    cam, plane = _camera_and_plane()
    h, w = 36, 64
    n = np.asarray(plane.normal)
    nr = n[0] * ((np.arange(w) - cam.cx) / cam.f)[None, :] + n[1] * ((np.arange(h) - cam.cy) / cam.f)[:, None] + n[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        z = -plane.offset / nr
        area = z ** 2 / (cam.f ** 2 * np.abs(nr))
    expected = np.where((z > 0) & np.isfinite(area), area, 0.0)
    got = compiled.footprint_grid(h, w, cam.f, cam.f ** 2, cam.cx, cam.cy, n, plane.offset)
    np.testing.assert_array_equal(got, expected)
    assert 0.3 < (got > 0).mean() < 1.0  # the horizon crosses the picture: both cases were met


def test_noise_terms_are_the_numpy_depth_and_residual():
    cam, plane = _camera_and_plane()
    rng = np.random.default_rng(15)
    smooth = rng.normal(0, 0.01, (36, 64)).astype(np.float32)
    smooth[rng.random(smooth.shape) < 0.15] = np.inf
    n = np.asarray(plane.normal)
    h, w = smooth.shape
    nr = n[0] * ((np.arange(w) - cam.cx) / cam.f)[None, :] + n[1] * ((np.arange(h) - cam.cy) / cam.f)[:, None] + n[2]
    finite = np.isfinite(smooth)
    with np.errstate(invalid="ignore"):
        depth = ((smooth.astype(np.float64) - plane.offset) / nr)[finite]
    resid = smooth[finite] * cam.f * cam.baseline / (plane.offset * np.maximum(depth, 1e-6))
    z, r = compiled.noise_terms(smooth, cam.f, cam.baseline, cam.cx, cam.cy, n, plane.offset)
    np.testing.assert_array_equal(z, depth)
    np.testing.assert_array_equal(r, resid)


def test_best_offsets_are_the_numpy_choice():
    rng = np.random.default_rng(16)
    k, h, w = 9, 20, 30
    scores = rng.uniform(-0.2, 1.0, (k, h, w)).astype(np.float32)
    scores[:, 0, :5] = 0.5  # ties: the first best
    scores[3, 1, 0] = np.nan  # a NaN counts as the largest
    scores[0, 2, :] = 2.0  # best at an end of the search: not reliable
    centre = rng.uniform(10, 50, (h, w)).astype(np.float32)
    offsets = np.arange(-1.0, 1.0 + 1e-9, 0.25, dtype=np.float32)
    raw = scores.argmax(axis=0)
    best = np.clip(raw, 1, k - 2)
    a, b, c = (np.take_along_axis(scores, (best + j)[None], axis=0)[0] for j in (-1, 0, 1))
    curvature = a - 2.0 * b + c
    with np.errstate(invalid="ignore"):
        shift = np.where(curvature < 0, 0.5 * (a - c) / np.where(curvature < 0, curvature, -1.0), 0.0)
        expected = centre + offsets[best] + shift * 0.25
        reliable = (b >= 0.9) & (raw > 0) & (raw < k - 1)
    got, got_reliable = compiled.best_offsets(scores, centre, offsets, 0.25, 0.9)
    np.testing.assert_array_equal(got, expected)
    np.testing.assert_array_equal(got_reliable, reliable)
    assert got_reliable.any() and not got_reliable.all()


def test_shifted_rows_are_opencvs_bicubic_remap_along_rows():
    """On OpenCV's 1/32-pixel positions the same values, beyond the edges too (BORDER_REFLECT);
    elsewhere within that table's rounding."""
    import cv2

    rng = np.random.default_rng(17)
    image = cv2.GaussianBlur(rng.uniform(0, 255, (50, 70)).astype(np.float32), (0, 0), 1.2)
    v0, u0, h, w = 6, 0, 30, 70
    offsets = np.arange(-3.0, 3.0 + 1e-9, 0.5, dtype=np.float32)
    vv, uu = np.mgrid[v0:v0 + h, u0:u0 + w].astype(np.float32)

    def remap(d):
        return np.stack([cv2.remap(image, uu - (d + o), vv, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT)
                         for o in offsets])

    on_table = (np.round(rng.uniform(-5, 30, (h, w)) * 32) / 32).astype(np.float32)
    on_table[:, :3] = -70.0  # beyond the right edge
    np.testing.assert_allclose(compiled.shifted_rows(image, v0, u0, on_table, offsets), remap(on_table), atol=1e-3)
    anywhere = rng.uniform(-5, 30, (h, w)).astype(np.float32)
    slope = float(np.abs(np.diff(image, axis=1)).max())
    assert np.abs(compiled.shifted_rows(image, v0, u0, anywhere, offsets) - remap(anywhere)).max() <= slope / 32


@pytest.mark.parametrize("rows, cols", [((0, 20), (0, 30)), ((4, 15), (7, 22))])
def test_zncc_scores_are_the_windows_zero_mean_ncc(rows, cols):
    """Every window of the pixels asked for, mirrored beyond the arrays without repeating the
    edge (cv2.blur's border), its standard deviations at least 1e-3."""
    rng = np.random.default_rng(18)
    left = rng.uniform(0, 255, (20, 30)).astype(np.float32)
    warps = np.stack([left + rng.normal(0, s, left.shape) for s in (5.0, 40.0, 0.0)]).astype(np.float32)
    warps[2, :6, :6] = 7.0  # a flat patch: its deviation floored
    window, r = 5, 2
    got = compiled.zncc_scores(left, warps, *rows, *cols, window)
    lp = np.pad(left.astype(np.float64), r, mode="reflect")
    expected = np.empty((3, rows[1] - rows[0], cols[1] - cols[0]))
    for k in range(3):
        wp = np.pad(warps[k].astype(np.float64), r, mode="reflect")
        for i, v in enumerate(range(*rows)):
            for j, u in enumerate(range(*cols)):
                a, b = lp[v:v + window, u:u + window].ravel(), wp[v:v + window, u:u + window].ravel()
                cov = (a * b).mean() - a.mean() * b.mean()
                expected[k, i, j] = cov / (np.sqrt(max(a.var(), 1e-6)) * np.sqrt(max(b.var(), 1e-6)))
    np.testing.assert_allclose(got, expected, atol=1e-5)
    if rows[0] == 0 and cols[0] == 0:
        assert got[2, 0, 0] == pytest.approx(0.0, abs=1e-5)  # a window on the flat patch: no covariance


def _columns(points):
    return tuple(np.ascontiguousarray(points[:, i]) for i in range(3))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_band_medians_are_the_medians_of_each_band(dtype):
    rng = np.random.default_rng(21)
    n_bands = 30
    band = rng.integers(0, n_bands - 3, 4000)  # the last bands empty: NaN
    band[:7] = n_bands - 3  # a band of 7 values: fewer than min_count, NaN
    band[7:] = np.where(band[7:] == n_bands - 3, 0, band[7:])
    values = rng.integers(0, 50, band.size).astype(dtype) / 7  # ties, odd and even counts
    got = compiled.band_medians(band, values, n_bands, 10)
    want = np.full(n_bands, np.nan)
    for b in range(n_bands):
        sel = values[band == b]
        if sel.size >= 10:
            want[b] = np.median(sel)
    np.testing.assert_array_equal(got, want)
    assert np.isnan(got[n_bands - 3:]).all() and np.isfinite(got[:n_bands - 3]).all()


def _terrace_level_reference(part, depth, footprint, t, step):
    """The terrace cue's level in NumPy and OpenCV: a labelling of the core's mask, the
    labels that hold a pit pixel, then the lost band."""
    import cv2

    pit = part & (depth > t + step)
    n, labels = cv2.connectedComponents((part & (depth > t + 0.5 * step)).astype(np.uint8), connectivity=8)
    holds_pit = np.zeros(n, bool)
    holds_pit[labels[pit]] = True
    holds_pit[0] = False
    core = holds_pit[labels]
    lost = part & (depth > t) & ~core
    return core, lost, footprint[pit].sum(), int(core.sum()), int((core & (depth < t + step)).sum()), footprint[lost].sum()


def test_terrace_level_is_the_labelling_of_the_pit_and_its_band():
    rng = np.random.default_rng(11)
    for _ in range(60):
        shape = tuple(int(x) for x in rng.integers(1, 40, 2))
        # a rough floor: shelves, pits and isolated dips, with ties at the levels
        depth = (np.round(_rough_floor(rng, shape), 2) * 0.01).astype(np.float32)
        part = rng.random(shape) < 0.9
        footprint = rng.uniform(1e-5, 2e-5, shape)
        # float64 levels, as np.arange gives them: NumPy compares the float32 depth in float64 then
        t, step = np.float64(rng.choice([0.0, 0.002, 0.004])), 0.004
        # the box of the level below (the whole part) or of any level below: a box holding the band
        above = part & (depth > t - 0.002)
        box = np.array(_bbox(above) if rng.random() < 0.5 else (0, shape[0], 0, shape[1]), np.int64)
        core, lost = np.zeros(shape, bool), np.zeros(shape, np.uint8)
        got = compiled.terrace_level(part, depth, footprint, float(t), step, core, lost,
                                     np.empty((2, part.size), np.int32), box)
        want = _terrace_level_reference(part, depth, footprint, t, step)
        np.testing.assert_array_equal(core, want[0])
        np.testing.assert_array_equal(lost.view(bool), want[1])
        assert got[1:3] == want[3:5]
        assert got[0] == pytest.approx(want[2], rel=1e-12) and got[3] == pytest.approx(want[5], rel=1e-12)
        band = part & (depth > t)
        assert tuple(box) == (_bbox(band) if band.any() else (box[0], box[0], box[2], box[2]))


def _bbox(mask):
    """(row start, row stop, column start, column stop) of a mask's pixels."""
    v, u = np.nonzero(mask)
    return (int(v.min()), int(v.max()) + 1, int(u.min()), int(u.max()) + 1) if v.size else (0, 0, 0, 0)


def _rough_floor(rng, shape):
    """Depths 0..1.2 (cm once scaled) with spatial structure: a random walk along both axes."""
    return np.clip(np.cumsum(np.cumsum(rng.normal(0, 0.3, shape), 0), 1) / 3 + 0.6, 0, 1.2)


def test_label_boxes_are_opencvs_statistics_and_the_weights_sums():
    """Of the labels 1 .. n - 1 (the background's row is zeros)."""
    import cv2

    rng = np.random.default_rng(3)
    for _ in range(40):
        shape = tuple(int(x) for x in rng.integers(1, 60, 2))
        mask = (rng.random(shape) < rng.uniform(0.1, 0.7)).astype(np.uint8)
        n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
        weights = rng.uniform(0, 1e-3, shape).astype(np.float32)
        boxes, sums = compiled.label_boxes(labels, n, weights)
        np.testing.assert_array_equal(boxes[1:], stats[1:, :4])
        assert not boxes[0].any() and sums[0] == 0
        np.testing.assert_allclose(sums[1:], np.bincount(labels.ravel(), weights.ravel().astype(np.float64), n)[1:],
                                   rtol=1e-12)
