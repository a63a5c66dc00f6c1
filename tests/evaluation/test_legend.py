"""Text and colour bars of the pictures: letters at least 12 px tall, titles and units everywhere."""

import cv2
import numpy as np
import pytest

from d3cli.data import legend
from d3cli.evaluation import pictures
from d3cli.road.outputs import height_colour


def ink_rows(img, *, dark=False):
    """Heights of the runs of rows holding grey text ink (white on black, or black on white)."""
    img = np.asarray(img).astype(np.int16)
    grey = (img.max(axis=2) - img.min(axis=2)) < 40
    ink = grey & ((img.max(axis=2) < 100) if dark else (img.min(axis=2) > 150))
    rows = ink.any(axis=1)
    runs, start = [], None
    for y, on in enumerate([*rows, False]):
        if on and start is None:
            start = y
        elif not on and start is not None:
            runs.append(y - start)
            start = None
    return runs


@pytest.mark.parametrize("width", [40, 160, 480, 1242, 2880])
def test_a_capital_letter_is_at_least_12_px_tall(width):
    px = legend.text_px(width)
    img = np.zeros((200, 400, 3), np.uint8)
    legend.put_text(img, "H", (10, 150), px)
    (rows,) = ink_rows(img)
    assert px <= rows <= px + 1 and px >= 12
    assert legend.text_px(width) == max(13, -(-13 * width // 480))


def test_text_of_a_wide_picture_stays_12_px_tall_in_a_panel_tile():
    img = np.zeros((220, 1242, 3), np.uint8)
    legend.put_text(img, "H", (10, 150), legend.text_px(1242))
    tile = cv2.resize(img, (480, 85), interpolation=cv2.INTER_AREA)
    assert ink_rows(tile)[0] >= 12


def recorded_text(monkeypatch):
    drawn = []
    real = legend.put_text

    def spy(img, text, org, px, *args, **kwargs):
        drawn.append((text, px))
        real(img, text, org, px, *args, **kwargs)

    monkeypatch.setattr(legend, "put_text", spy)
    return drawn


def test_disparity_bar_has_a_title_and_px_on_every_tick(monkeypatch):
    drawn = recorded_text(monkeypatch)
    disp = np.tile(np.linspace(3.9, 56.0, 320, dtype=np.float32), (60, 1))
    pic = pictures.disparity_picture(disp, 3.9, 56.0, how="1-99th percentile")
    texts = [t for t, _ in drawn]
    assert texts[:4] == ["3.9 px", "56.0 px", "20 px", "40 px"]
    assert " ".join(texts[4:]) == "disparity [px]; colours span the 1-99th percentile; black: no estimate"
    assert {px for _, px in drawn} == {13}
    strip = pic[60:]
    assert len(ink_rows(strip)) >= 3 and min(ink_rows(strip)) >= 12  # ticks and two title lines


def test_error_legend_names_the_error_and_has_px_on_every_label(monkeypatch):
    drawn = recorded_text(monkeypatch)
    strip = pictures.error_legend(480)
    labels = [t for t, _ in drawn]
    bounds = ["0.19 px", "0.38 px", "0.75 px", "1.5 px", "3 px", "6 px", "12 px", "24 px", "48 px"]
    assert sorted(labels[:9], key=lambda t: float(t.split()[0])) == bounds
    assert " ".join(labels[10:]).startswith("end-point error [px], KITTI colours")
    assert all(t.endswith(" px") for t in labels[:10])
    assert min(ink_rows(strip[20:])) >= 12


def test_overlay_and_panel_text_is_at_least_12_px():
    left = np.full((96, 160), 90, np.uint8)
    valid = np.ones((96, 160), bool)
    out = pictures.validity_overlay(left, valid, np.ones((96, 160), np.float32))
    assert out.shape[1] == 160 and out.shape[0] > 96
    assert min(ink_rows(out[96:])) >= 12
    tiles = [("left", left), ("validity (red filled, blue none)", out)]
    panel = pictures.panel("pair   EPE 1.23 px", tiles, tile_width=480)
    assert panel.shape[1] == 2 * 160 + 6  # not scaled up: the legends keep their size
    head = panel[: np.argmax((panel[:, :160, 0] < 10).all(axis=1))]  # white head above the black tiles
    assert min(ink_rows(head, dark=True)) >= 12
    caption = panel[head.shape[0]: head.shape[0] + 20, :160]
    assert min(ink_rows(caption)) >= 12


def test_height_colour_bar_is_titled_with_mm_on_every_tick(monkeypatch):
    drawn = recorded_text(monkeypatch)
    h = np.zeros((240, 320), np.float32)
    img = height_colour(h, range_mm=50.0)
    texts = [t for t, _ in drawn]
    assert " ".join(texts[:-5]) == "height above road plane [mm]; grey: no estimate"
    assert [t for t in texts if t.endswith("mm") and t[0] in "+-0"] == ["+50 mm", "+25 mm", "0 mm", "-25 mm", "-50 mm"]
    # The tick labels: every column right of the colour bar (the last column holding colour).
    rgb = img.astype(np.int16)
    coloured = ((rgb.max(axis=2) - rgb.min(axis=2)) >= 40).any(axis=0)
    labels = img[:, np.flatnonzero(coloured).max() + 1:]
    assert len(ink_rows(labels, dark=True)) == 5 and min(ink_rows(labels, dark=True)) >= 12


def test_range_ticks_are_round_between_exact_ends():
    assert legend.range_ticks(0.0, 50.0, "px", count=5) == [(0.0, "0.0 px"), (1.0, "50.0 px"), (0.4, "20 px"),
                                                            (0.8, "40 px")]
    assert legend.range_ticks(3e38, 3.0003e38, "px")[:2] == [(0.0, "3e+38 px"), (1.0, "3e+38 px")]
    assert legend.wrap("disparity [px] of the pair", 13, 120) == ["disparity [px]", "of the pair"]
