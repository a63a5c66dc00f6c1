"""defects.png: labels placed without overlap, readable labels, the legend below the picture."""

import itertools

import numpy as np
import pytest

from d3cli.data.legend import text_px
from d3cli.road.defects import Defect
from d3cli.road.overlay import BUMP_COLOUR, POTHOLE_COLOUR, defects_overlay, label_places, label_text, place_labels


def intersects(a, b, gap=0):
    return a[0] < b[2] + gap and b[0] < a[2] + gap and a[1] < b[3] + gap and b[1] < a[3] + gap


def assert_apart_and_inside(rects, shape, gap):
    placed = [r for r in rects if r is not None]
    for r in placed:
        assert 0 <= r[0] < r[2] <= shape[1] and 0 <= r[1] < r[3] <= shape[0], r
    for a, b in itertools.combinations(placed, 2):
        assert not intersects(a, b, gap), (a, b)


def test_labels_of_touching_potholes_do_not_overlap():
    # Four potholes in a row, each outline touching the next (their boxes share a column):
    # the labels' natural spot (above, left-aligned) would overlap for every pair.
    boxes = [(100 + 40 * k, 100, 140 + 40 * k, 140) for k in range(4)]
    sizes = [(110, 24)] * 4
    rects = place_labels(boxes, sizes, (240, 400), gap=4)
    assert None not in rects
    assert_apart_and_inside(rects, (240, 400), 4)
    # The first (most important) label sits right above its pothole.
    assert rects[0] == (100, 100 - 4 - 24, 210, 100 - 4)


def test_labels_stay_clear_of_the_defects_where_there_is_room():
    boxes = [(100, 100, 140, 140), (141, 100, 181, 140), (120, 141, 160, 181)]
    rects = place_labels(boxes, [(90, 20)] * 3, (300, 400), gap=4)
    assert_apart_and_inside(rects, (300, 400), 4)
    for r in rects:
        assert not any(intersects(r, (u0, v0, u1 + 1, v1 + 1)) for u0, v0, u1, v1 in boxes)


def test_many_defects_in_a_small_picture():
    # 24 touching defects fill most of a 320 x 240 picture; every label that gets a place
    # keeps clear of every other, inside the picture, and most get one.
    boxes = [(40 * i, 40 * j + 40, 40 * i + 39, 40 * j + 79) for i in range(8) for j in range(3)]
    rects = place_labels(boxes, [(70, 18)] * len(boxes), (240, 320), gap=3)
    assert_apart_and_inside(rects, (240, 320), 3)
    assert sum(r is not None for r in rects) >= 12


def test_a_label_larger_than_the_picture_gets_no_place():
    assert place_labels([(0, 0, 5, 5)], [(50, 10)], (20, 40)) == [None]


def test_label_edges_and_the_top_border():
    # A pothole at the top border: its label goes below it, not off the picture.
    (rect,) = place_labels([(50, 0, 90, 30)], [(60, 20)], (100, 200), gap=4)
    assert rect[1] >= 31


def defect(i, kind, box, depth, low=False, flags=()):
    u0, v0, u1, v1 = box
    return Defect(id=i, kind=kind, centroid_px=((u0 + u1) / 2, (v0 + v1) / 2), bbox_px=box,
                  centroid_m=(0.0, 0.0, 2.0), area_m2=0.1, max_depth_mm=depth, mean_depth_mm=depth / 2,
                  volume_l=1.0, decided_share=0.9, low_confidence=low or bool(flags), flags=tuple(flags),
                  confidence="low" if low or flags else "ok")


def disc(shape, box):
    u0, v0, u1, v1 = box
    v, u = np.mgrid[: shape[0], : shape[1]]
    cu, cv, r = (u0 + u1) / 2, (v0 + v1) / 2, (u1 - u0) / 2
    return (u - cu) ** 2 + (v - cv) ** 2 <= r * r


@pytest.mark.parametrize("grey", [20, 245])  # dark asphalt, white glare
def test_picture_has_labels_readable_on_any_background_and_a_legend(grey):
    shape = (240, 400)
    boxes = [(100, 100, 140, 140), (141, 100, 181, 140), (300, 60, 340, 100)]
    defects = [defect(1, "pothole", boxes[0], 41.2), defect(2, "pothole", boxes[1], 30.0, flags=("specular", "noisy")),
               defect(3, "bump", boxes[2], 12.0)]
    left = np.full(shape, grey, np.uint8)
    img = defects_overlay(left, defects, [disc(shape, b) for b in boxes])
    assert img.shape[1] == shape[1] and img.shape[0] > shape[0] + 2 * text_px(shape[1])
    picture, legend = img[: shape[0]], img[shape[0]:]
    # The legend shows both outline colours as swatches and has text (white) on black.
    for colour in (POTHOLE_COLOUR, BUMP_COLOUR):
        assert (legend == colour).all(axis=2).sum() >= text_px(shape[1]) ** 2 // 2
    assert (legend == 255).all(axis=2).sum() > 500
    # Every label is white text on a dark box, whatever the background.
    white = (picture >= 250).all(axis=2)
    dark = (picture <= 80).all(axis=2)
    if grey > 128:
        # glare: white pixels only inside the dark boxes, which hold much dark
        assert dark.sum() > 3 * 400
    else:
        assert white.sum() > 3 * 100
    assert [label_text(d) for d in defects] == ["#1 -41 mm", "#2 -30 mm ? wet,dark", "#3 +12 mm"]


def test_labels_without_room_are_listed_in_the_legend():
    # Two labels about 100 px wide, one row of room: the second is listed in the legend.
    boxes = [(5, 2, 20, 17), (30, 2, 45, 17)]
    defects = [defect(1, "pothole", boxes[0], 41.0), defect(2, "pothole", boxes[1], 20.0)]

    def legend_height(shape):
        img = defects_overlay(np.zeros(shape, np.uint8), defects, [disc(shape, b) for b in boxes])
        return img.shape[0] - shape[0]

    assert legend_height((24, 120)) > legend_height((240, 120))


def test_the_legend_explains_the_reasons_the_picture_shows_and_only_those():
    from d3cli.road.overlay import low_confidence_text
    assert low_confidence_text(["merged", "weak_match", "weak_match"]) == (
        "? depth not trusted, why: weak = weak match on little texture, merged = possibly merged with a neighbour")
    assert low_confidence_text([]) == "? after a label: depth not trusted (none here)"


def test_leader_lines_never_cross_another_label():
    # Seven flagged discs scattered over a 640x360 picture: several labels sit away from
    # their defects, and their leader lines pass other labels.  Every line is drawn before
    # every label, so no label box holds a pixel of the outline colour at full strength
    # (a line drawn after a label crossed its text; under a label a line shows darkened).
    rng = np.random.default_rng(7)
    h, w = 360, 640
    yy, xx = np.mgrid[:h, :w]
    defects, regions = [], []
    for k in range(7):
        cx, cy, r = rng.integers(40, w - 40), rng.integers(30, h - 30), rng.integers(12, 40)
        mask = (xx - cx) ** 2 + (yy - cy) ** 2 < r * r
        vs, us = np.nonzero(mask)
        defects.append(Defect(id=k + 1, kind="pothole", centroid_px=(float(cx), float(cy)),
                              bbox_px=(int(us.min()), int(vs.min()), int(us.max()), int(vs.max())),
                              centroid_m=(0.0, 0.0, 5.0), area_m2=0.1, max_depth_mm=60.0 - 5 * k, mean_depth_mm=20.0,
                              volume_l=1.0, decided_share=1.0, low_confidence=True,
                              flags=("weak_match", "merged", "narrow")))
        regions.append(mask)
    out = defects_overlay(np.full((h, w), 128, np.uint8), defects, regions)
    rects = [r for _, r in label_places(defects, regions, (h, w)) if r is not None]
    assert len(rects) >= 5
    red = np.array(POTHOLE_COLOUR)
    for x0, y0, x1, y1 in rects:
        inner = out[y0 + 3:y1 - 3, x0 + 3:x1 - 3].astype(int)
        assert not (np.abs(inner - red).max(axis=-1) < 60).any(), (x0, y0, x1, y1)
