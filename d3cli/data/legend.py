"""Text, colour bars and legends shared by every picture d3stereo writes.

One place decides how big text is and how a colour bar looks, so that ``disp_color.png``,
``error.png``, ``valid_overlay.png``, ``panel.png`` and the road pictures read alike:

* Text is OpenCV's Hershey simplex (no font files, no new dependency), white on black
  (or black on white), its capital letters and digits at least :data:`MIN_TEXT_PX`
  pixels tall at 100 %.  Pictures wider than :data:`REFERENCE_WIDTH` get proportionally
  larger text, so that the text stays that tall where ``panel.png`` scales a picture
  down to a tile of :data:`REFERENCE_WIDTH` pixels.
* Every colour bar has a title that names the quantity and its unit in brackets
  ("disparity [px]"), and every tick label carries its unit ("12.5 px").
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import cv2
import numpy as np

#: Smallest height (px) of a capital letter or digit at 100 %.
MIN_TEXT_PX = 12
#: Width of a tile of ``panel.png``: text scales with the width above it.
REFERENCE_WIDTH = 480
#: The font (Hershey simplex: its capital "H" is 20 px tall at scale 1, thickness 1-2).
FONT = cv2.FONT_HERSHEY_SIMPLEX
WHITE = (255, 255, 255)
BLACK = (0, 0, 0)

# One pixel above the minimum: resampling a picture into a panel tile may blur an edge row.
_BASE_PX = MIN_TEXT_PX + 1
_CAP_AT_SCALE_1 = 20.0


def text_px(width: int) -> int:
    """Cap height (px) of the text of a picture ``width`` pixels wide.

    :data:`MIN_TEXT_PX` + 1 up to :data:`REFERENCE_WIDTH`, proportionally more above it
    (a 1242 px wide KITTI picture gets 34 px), so that the text of a picture shrunk to a
    ``panel.png`` tile is still at least :data:`MIN_TEXT_PX` tall.
    """
    return max(_BASE_PX, math.ceil(_BASE_PX * int(width) / REFERENCE_WIDTH))


def _scale(px: int) -> float:
    return px / _CAP_AT_SCALE_1


def _thickness(px: int) -> int:
    # Strokes about a tenth of the letter height: thin text blurs away when scaled down.
    return max(1, int(round(px / 10)))


def text_size(text: str, px: int) -> tuple[int, int]:
    """``(width, height)`` in pixels of ``text`` drawn by :func:`put_text` (height: capitals)."""
    (w, h), _ = cv2.getTextSize(text, FONT, _scale(px), _thickness(px))
    return w, h


def line_height(px: int) -> int:
    """Distance (px) between the baselines of two lines of text: room for descenders."""
    return int(math.ceil(px * 1.7))


def put_text(img: np.ndarray, text: str, org: tuple[int, int], px: int,
             colour: tuple[int, int, int] = WHITE, *, outline: tuple[int, int, int] | None = None) -> None:
    """Draw ``text`` into ``img`` (in place) with its baseline's left end at ``org``.

    Parameters
    ----------
    img : ndarray, uint8, (H, W, 3)
        RGB picture.
    text : str
        ASCII text (the Hershey fonts have no other characters).
    org : (int, int)
        ``(x, y)`` of the baseline's left end.
    px : int
        Cap height in pixels (:func:`text_px`).
    colour : (int, int, int)
        RGB colour of the letters.
    outline : (int, int, int), optional, keyword-only
        Colour of a halo drawn first, for text over a photograph.
    """
    org = (int(org[0]), int(org[1]))
    thick = _thickness(px)
    if outline is not None:
        cv2.putText(img, text, org, FONT, _scale(px), outline, thick + 2 * max(1, thick // 2), cv2.LINE_AA)
    cv2.putText(img, text, org, FONT, _scale(px), colour, thick, cv2.LINE_AA)


def wrap(text: str, px: int, width: int) -> list[str]:
    """``text`` broken at spaces into lines no wider than ``width`` (a longer word keeps its line)."""
    lines: list[str] = []
    for word in text.split():
        if lines and text_size(f"{lines[-1]} {word}", px)[0] <= width:
            lines[-1] = f"{lines[-1]} {word}"
        else:
            lines.append(word)
    return lines or [""]


def text_block(width: int, text: str, px: int, *, bg=BLACK, fg=WHITE, centre: bool = True) -> np.ndarray:
    """A strip ``width`` wide holding ``text`` wrapped into lines (centred by default)."""
    pad = max(2, px // 3)
    lines = wrap(text, px, width - 2 * pad)
    step = line_height(px)
    strip = np.empty((step * len(lines) + pad, width, 3), np.uint8)
    strip[:] = bg
    for i, line in enumerate(lines):
        w, _ = text_size(line, px)
        x = max(pad, (width - w) // 2) if centre else pad
        put_text(strip, line, (x, pad + px + i * step), px, fg)
    return strip


def _label_rows(width: int, ticks: Sequence[tuple[float, str]], px: int, x0: int, x1: int,
                max_rows: int) -> list[list[tuple[int, str]]]:
    """Tick labels assigned to rows: each at its position, in the first row where it overlaps no label.

    Earlier ticks win; a label that fits in none of ``max_rows`` rows is left out.
    """
    gap = max(2, px // 3)
    rows: list[list[tuple[int, int, str]]] = []
    for frac, label in ticks:
        w, _ = text_size(label, px)
        centre = x0 + float(frac) * (x1 - x0)
        left = int(round(min(max(centre - w / 2, 0), max(width - w, 0))))
        for row in rows:
            if all(left + w + gap <= a or b + gap <= left for a, b, _ in row):
                row.append((left, left + w, label))
                break
        else:
            if len(rows) < max_rows:
                rows.append([(left, left + w, label)])
    return [[(a, label) for a, _, label in row] for row in rows]


def colour_bar(width: int, colours: np.ndarray, ticks: Sequence[tuple[float, str]], title: str, *,
               px: int | None = None, max_rows: int = 1, bg=BLACK, fg=WHITE) -> np.ndarray:
    """A horizontal colour bar strip, ``width`` wide, to put below a picture.

    Parameters
    ----------
    width : int
        Width of the picture (px).
    colours : ndarray, uint8, (N, 3)
        RGB colours from the left end to the right end; stretched to the bar's length
        (N equal blocks for a binned legend).
    ticks : sequence of (float, str)
        Position along the bar (0 = left end, 1 = right end) and label, units included
        ("12.5 px"), most important first: where two labels would overlap, the later
        one goes to the next row, or is left out beyond ``max_rows`` rows.
    title : str
        Quantity and unit ("disparity [px]"), wrapped onto several lines when too long.
    px : int, optional, keyword-only
        Cap height of the text; default :func:`text_px` of ``width``.
    max_rows : int, keyword-only
        Rows of tick labels at most.
    bg, fg : (int, int, int), keyword-only
        RGB background and text colours.

    Returns
    -------
    ndarray, uint8, (h, width, 3)
        Bar, tick labels below it, then the title.
    """
    px = text_px(width) if px is None else int(px)
    pad = max(2, px // 3)
    bar_h = int(round(1.2 * px))
    x0, x1 = min(pad, width // 8), width - min(pad, width // 8)
    colours = np.asarray(colours, np.uint8).reshape(-1, 3)
    rows = _label_rows(width, ticks, px, x0, x1 - 1, max_rows)
    step = line_height(px)
    strip = np.empty((pad + bar_h + step * len(rows), width, 3), np.uint8)
    strip[:] = bg
    if x1 > x0:
        index = np.minimum((np.arange(x1 - x0) * len(colours)) // (x1 - x0), len(colours) - 1)
        strip[pad: pad + bar_h, x0:x1] = colours[index][None, :, :]
    for r, row in enumerate(rows):
        for left, label in row:
            put_text(strip, label, (left, pad + bar_h + px + pad + r * step), px, fg)
    return np.vstack([strip, text_block(width, title, px, bg=bg, fg=fg)])


def vertical_colour_bar(height: int, colours: np.ndarray, ticks: Sequence[tuple[float, str]], title: str, *,
                        px: int | None = None, bg=WHITE, fg=BLACK) -> np.ndarray:
    """A vertical colour bar, ``height`` tall, to put right of a picture.

    Parameters
    ----------
    height : int
        Height of the picture (px).
    colours : ndarray, uint8, (N, 3)
        RGB colours from the top to the bottom, stretched to the bar's length.
    ticks : sequence of (float, str)
        Position (0 = top, 1 = bottom) and label with its unit ("+50 mm").
    title : str
        Quantity and unit, written upwards along the left side of the bar.
    px : int, optional, keyword-only
        Cap height of the text; default :data:`MIN_TEXT_PX` + 1.
    bg, fg : (int, int, int), keyword-only
        RGB background and text colours.

    Returns
    -------
    ndarray, uint8, (height, w, 3)
        Title column, bar, tick labels.
    """
    px = _BASE_PX if px is None else int(px)
    pad = max(2, px // 3)
    # np.rot90 turns the text a quarter counter-clockwise: it reads upwards along the bar.
    title_col = np.rot90(text_block(height, title, px, bg=bg, fg=fg)).copy()
    bar_w = int(round(1.2 * px))
    label_w = max((text_size(label, px)[0] for _, label in ticks), default=0) + 2 * pad
    top, bottom = min(px, height // 4), height - min(px, height // 4)
    col = np.empty((height, pad + bar_w + label_w, 3), np.uint8)
    col[:] = bg
    colours = np.asarray(colours, np.uint8).reshape(-1, 3)
    if bottom > top:
        index = np.minimum((np.arange(bottom - top) * len(colours)) // (bottom - top), len(colours) - 1)
        col[top:bottom, pad: pad + bar_w] = colours[index][:, None, :]
    for frac, label in ticks:
        y = int(round(top + float(frac) * (bottom - 1 - top))) + px // 2
        put_text(col, label, (pad + bar_w + pad, min(max(y, px), height - 2)), px, fg)
    gap = np.empty((height, pad, 3), np.uint8)
    gap[:] = bg
    return np.hstack([gap, title_col, col])


def swatch_legend(width: int, items: Sequence[tuple[tuple[int, int, int], str]], *, px: int | None = None,
                  bg=BLACK, fg=WHITE) -> np.ndarray:
    """A strip of colour swatches, each followed by its label, flowing onto new lines as needed."""
    px = text_px(width) if px is None else int(px)
    pad = max(2, px // 3)
    step = line_height(px)
    placed: list[tuple[int, int, tuple[int, int, int], str]] = []
    x, line = pad, 0
    for colour, label in items:
        w = px + pad + text_size(label, px)[0]
        if x > pad and x + w > width - pad:
            x, line = pad, line + 1
        placed.append((x, line, colour, label))
        x += w + 2 * px
    strip = np.empty((pad + step * (line + 1), width, 3), np.uint8)
    strip[:] = bg
    for x, line, colour, label in placed:
        y = pad + px + line * step
        strip[y - px: y, x: x + px] = colour
        put_text(strip, label, (x + px + pad, y), px, fg)
    return strip


def format_value(value: float, decimals: int) -> str:
    """``value`` with ``decimals`` decimals; in exponent notation when that would be unreadable."""
    value = float(value)
    if not math.isfinite(value):
        return str(value)
    if value != 0 and not 1e-3 <= abs(value) < 1e6:
        return f"{value:.3g}"
    return f"{value:.{max(0, decimals)}f}"


def range_ticks(vmin: float, vmax: float, unit: str, *, count: int = 5) -> list[tuple[float, str]]:
    """Tick positions and labels of a linear bar from ``vmin`` to ``vmax``.

    The two ends first (their exact values), then round values between them (steps of
    1, 2 or 5 times a power of ten, about ``count`` ticks); every label ends in ``unit``.
    """
    vmin, vmax = float(vmin), float(vmax)
    span = vmax - vmin
    if not (math.isfinite(span) and span > 0):
        return [(0.0, f"{format_value(vmin, 1)} {unit}"), (1.0, f"{format_value(vmax, 1)} {unit}")]
    raw = span / max(count - 1, 1)
    power = 10.0 ** math.floor(math.log10(raw))
    step = next(m * power for m in (1, 2, 5, 10) if m * power >= raw)
    decimals = max(0, -int(math.floor(math.log10(step))))
    ticks = [(0.0, f"{format_value(vmin, decimals + 1)} {unit}"), (1.0, f"{format_value(vmax, decimals + 1)} {unit}")]
    first = math.ceil(vmin / step)
    for k in range(first, first + count + 2):
        value = k * step
        frac = (value - vmin) / span
        if 0.05 < frac < 0.95:
            ticks.append((frac, f"{format_value(value, decimals)} {unit}"))
    return ticks
