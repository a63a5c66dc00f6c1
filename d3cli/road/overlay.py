"""``defects.png``: the left image with each defect outlined and labelled, and a legend.

What makes it readable where potholes touch, on white glare and on dark asphalt:

* Labels never overlap one another: :func:`place_labels` tries positions next to each
  defect (above, below, right, left) and then ever further out, and takes the first that
  stays inside the picture, keeps clear of every label placed before and, where it can,
  covers no defect.  A label that is not next to its defect gets a thin leader line to
  the defect's outline.
* Outlines and leader lines are drawn over a dark halo; a label is white text on a dark,
  semi-transparent box framed in its defect's colour.
* A legend strip below the picture says what the colours, the label, ``?`` and the short
  reasons after it mean (those the picture shows, :mod:`d3cli.road.confidence`).
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from .confidence import REASONS, SHORT
from ..data.legend import BLACK, WHITE, put_text, swatch_legend, text_block, text_px, text_size

POTHOLE_COLOUR = (255, 0, 0)
BUMP_COLOUR = (255, 220, 0)
#: Appended to the label of a flagged defect, before its reasons; the legend says what it means.
LOW_CONFIDENCE_MARK = "?"
_BOX_ALPHA = 0.7  # darkening of the picture under a label box


def label_text(defect) -> str:
    """``"#id -depth mm"`` (bumps ``+height``); a flagged defect gets ``?`` and its reasons in
    short (:data:`d3cli.road.confidence.SHORT`): ``"#1 -83 mm ? wet"``."""
    sign = "-" if defect.kind == "pothole" else "+"
    text = f"#{defect.id} {sign}{defect.max_depth_mm:.0f} mm"
    if not defect.low_confidence:
        return text
    why = ",".join(SHORT.get(code, code) for code in getattr(defect, "flags", ()))
    return f"{text} {LOW_CONFIDENCE_MARK}" + (f" {why}" if why else "")


def _adjacent(box, w: int, h: int, gap: int) -> list[tuple[int, int]]:
    """Top-left corners of a ``w`` x ``h`` label next to ``box``: above, below, right, left."""
    u0, v0, u1, v1 = box
    cu, cv = (u0 + u1 + 1) // 2, (v0 + v1 + 1) // 2
    above, below = v0 - gap - h, v1 + 1 + gap
    return [(u0, above), (cu - w // 2, above), (u1 + 1 - w, above),
            (u0, below), (cu - w // 2, below), (u1 + 1 - w, below),
            (u1 + 1 + gap, cv - h // 2), (u0 - gap - w, cv - h // 2)]


def _box_distance(rects: np.ndarray, box) -> np.ndarray:
    """Distance (px) from each rectangle ``(x0, y0, x1, y1)`` (exclusive ends) to ``box`` (inclusive)."""
    u0, v0, u1, v1 = box
    dx = np.maximum(np.maximum(u0 - rects[:, 2], rects[:, 0] - (u1 + 1)), 0)
    dy = np.maximum(np.maximum(v0 - rects[:, 3], rects[:, 1] - (v1 + 1)), 0)
    return np.hypot(dx, dy)


def place_labels(boxes: Sequence[Sequence[int]], sizes: Sequence[tuple[int, int]], shape: tuple[int, int], *,
                 gap: int = 4, avoid: np.ndarray | None = None) -> list[tuple[int, int, int, int] | None]:
    """Rectangles for the labels of defects, none overlapping another, all inside the picture.

    Labels are placed in the given order (the most important first: it gets the nearest
    position).  For each, the candidates are the eight positions next to its box (above:
    left-aligned, centred, right-aligned; the same below; right; left), then every
    position of a grid over the picture, nearest the box first.  The first candidate wins
    that lies inside the picture, keeps ``gap`` pixels from every label placed before and
    covers no pixel of ``avoid``; when none covers no such pixel, the first that meets the
    other two conditions.

    Parameters
    ----------
    boxes : sequence of (u0, v0, u1, v1)
        Each defect's bounding box, pixels, inclusive ends.
    sizes : sequence of (w, h)
        Each label's size, pixels (box included).
    shape : (int, int)
        ``(height, width)`` of the picture.
    gap : int, keyword-only
        Least distance (px) between two labels, and between a label and its box.
    avoid : ndarray, bool, (height, width), optional, keyword-only
        Pixels a label should not cover (the defects and their outlines); default: every
        box of ``boxes``.

    Returns
    -------
    list of (x0, y0, x1, y1) or None
        Per label, its rectangle (exclusive ends), or None where no position is free.
    """
    height, width = int(shape[0]), int(shape[1])
    if not len(boxes):
        return []
    if avoid is None:
        avoid = np.zeros((height, width), bool)
        for u0, v0, u1, v1 in boxes:
            avoid[max(int(v0), 0): max(int(v1) + 1, 0), max(int(u0), 0): max(int(u1) + 1, 0)] = True
    # Integral image: the number of avoided pixels under any rectangle in O(1).
    covered = cv2.integral(np.asarray(avoid, np.uint8), sdepth=cv2.CV_32S)  # (height + 1, width + 1), exact counts
    placed: list[tuple[int, int, int, int]] = []
    out: list[tuple[int, int, int, int] | None] = []
    for box, (w, h) in zip(boxes, sizes):
        box = tuple(int(x) for x in box)
        w, h = int(w), int(h)
        if w > width or h > height:
            out.append(None)
            continue
        step = max(2, h // 2)
        xs, ys = np.meshgrid(np.arange(0, width - w + 1, step), np.arange(0, height - h + 1, step))
        grid = np.stack([xs.ravel(), ys.ravel()], axis=1)
        grid = np.concatenate([grid, [[width - w, y] for y in range(0, height - h + 1, step)],
                               [[x, height - h] for x in range(0, width - w + 1, step)]])
        grid_rects = np.concatenate([grid, grid + [w, h]], axis=1)
        grid_rects = grid_rects[np.argsort(_box_distance(grid_rects, box), kind="stable")]
        near = np.array(_adjacent(box, w, h, gap), np.int64)
        rects = np.concatenate([np.concatenate([near, near + [w, h]], axis=1), grid_rects])
        ok = (rects[:, 0] >= 0) & (rects[:, 1] >= 0) & (rects[:, 2] <= width) & (rects[:, 3] <= height)
        if placed:
            p = np.array(placed)
            clash = ((rects[:, None, 0] < p[None, :, 2] + gap) & (p[None, :, 0] < rects[:, None, 2] + gap)
                     & (rects[:, None, 1] < p[None, :, 3] + gap) & (p[None, :, 1] < rects[:, None, 3] + gap))
            ok &= ~clash.any(axis=1)
        index = np.flatnonzero(ok)
        if not index.size:
            out.append(None)
            continue
        r = rects[index]
        x0, y0, x1, y1 = r[:, 0], r[:, 1], r[:, 2], r[:, 3]
        hidden = covered[y1, x1] - covered[y0, x1] - covered[y1, x0] + covered[y0, x0]
        clear = np.flatnonzero(hidden == 0)
        chosen = tuple(int(v) for v in r[clear[0] if clear.size else 0])
        placed.append(chosen)
        out.append(chosen)
    return out


def _nearest_on_rect(rect, point) -> tuple[int, int]:
    x0, y0, x1, y1 = rect
    return int(min(max(point[0], x0), x1 - 1)), int(min(max(point[1], y0), y1 - 1))


def _haloed_line(img, a, b, colour, thick: int) -> None:
    cv2.line(img, a, b, BLACK, thick + 2, cv2.LINE_AA)
    cv2.line(img, a, b, colour, thick, cv2.LINE_AA)


def low_confidence_text(flags: Sequence[str]) -> str:
    """The legend's line for ``?``: what it means and the short reasons of ``flags`` (the
    codes the picture shows, each once) in words, in the order of
    :data:`d3cli.road.confidence.REASONS`."""
    codes = set(flags)
    shown = [c for c in REASONS if c in codes] + sorted(codes - set(REASONS))
    if not shown:
        return f"{LOW_CONFIDENCE_MARK} after a label: depth not trusted (none here)"
    return (f"{LOW_CONFIDENCE_MARK} depth not trusted, why: "
            + ", ".join(f"{SHORT.get(c, c)} = {REASONS.get(c, c)}" for c in shown))


def legend_strip(width: int, *, flags: Sequence[str] = (), unplaced: Sequence[str] = ()) -> np.ndarray:
    """The strip below defects.png: the outline colours, what a label says, what ``?`` and
    the short reasons of the picture's ``flags`` mean.

    Depth and height are those of defects.json (``max_depth_mm``: the deepest point below
    the road around the defect).  ``unplaced``: labels with no room left in the picture,
    listed here instead.
    """
    px = text_px(width)
    swatches = swatch_legend(width, [(POTHOLE_COLOUR, "pothole -depth mm"),
                                     (BUMP_COLOUR, "bump +height mm")], px=px)
    parts = [swatches, text_block(width, low_confidence_text(flags), px, centre=False)]
    if unplaced:
        parts.append(text_block(width, "no room in the picture for the labels " + ", ".join(unplaced), px,
                                centre=False))
    return np.vstack(parts)


def _sizes(height: int, width: int) -> tuple[int, int, int, int]:
    """(line thickness, text height, label padding, gap) of defects.png for a picture of
    ``height`` x ``width`` pixels."""
    px = text_px(width)
    return max(1, height // 360), px, max(2, px // 4), max(4, px // 4)


def label_places(defects, regions, shape: tuple[int, int]) -> list:
    """Where :func:`defects_overlay` puts each defect's label in a picture of ``shape``
    (H, W): ``(index into defects, rectangle (x0, y0, x1, y1), exclusive ends, or None)``,
    deepest pothole first (the most important labels get the nearest positions), placed
    by :func:`place_labels` clear of the defects (the regions and their drawn outlines)
    where there is room."""
    height, width = shape
    thick, px, pad, gap = _sizes(height, width)
    avoid = np.zeros((height, width), np.uint8)
    for m in regions:
        avoid |= np.asarray(m, np.uint8)
    avoid = cv2.dilate(avoid, np.ones((2 * thick + 3, 2 * thick + 3), np.uint8)).astype(bool)
    sizes = [(text_size(label_text(d), px)[0] + 2 * pad, px + 2 * pad) for d in defects]
    order = sorted(range(len(defects)), key=lambda i: (defects[i].kind != "pothole", -defects[i].max_depth_mm))
    rects = place_labels([defects[i].bbox_px for i in order], [sizes[i] for i in order], (height, width),
                         gap=gap, avoid=avoid)
    return list(zip(order, rects))


def defects_overlay(left: np.ndarray, defects, regions) -> np.ndarray:
    """RGB uint8: the left image with each defect outlined and labelled, the legend below it.

    Parameters
    ----------
    left : ndarray, (H, W[, 3])
        Left image (uint8, or 16-bit values).
    defects : sequence of Defect
        :class:`d3cli.road.defects.Defect` (``id``, ``kind``, ``bbox_px``,
        ``max_depth_mm``, ``low_confidence``).
    regions : sequence of ndarray, bool, (H, W)
        Each defect's pixels, in the order of ``defects``.

    Returns
    -------
    ndarray, uint8, (H + legend, W, 3)
    """
    img = np.asarray(left)
    if img.dtype != np.uint8:
        img = np.clip(img / (257.0 if img.max(initial=0) > 255 else 1.0), 0, 255).astype(np.uint8)
    if img.ndim == 2:
        img = np.repeat(img[:, :, None], 3, axis=2)
    out = np.ascontiguousarray(img[:, :, :3]).copy()
    height, width = out.shape[:2]
    thick, px, pad, gap = _sizes(height, width)
    colours = [POTHOLE_COLOUR if d.kind == "pothole" else BUMP_COLOUR for d in defects]
    contours = [cv2.findContours(np.asarray(m, np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)[0]
                for m in regions]
    for cs, colour in zip(contours, colours):
        cv2.drawContours(out, cs, -1, BLACK, thick + 2)
        cv2.drawContours(out, cs, -1, colour, thick)
    texts = [label_text(d) for d in defects]
    places = label_places(defects, regions, (height, width))
    unplaced = [texts[i] for i, rect in places if rect is None]
    placed = [(i, rect) for i, rect in places if rect is not None]
    # Every leader line first, then every label: a line never crosses another label's text.
    for i, rect in placed:
        x0, y0, x1, y1 = rect
        points = np.concatenate([c.reshape(-1, 2) for c in contours[i]]) if contours[i] else None
        if points is not None:
            centre = ((x0 + x1) / 2, (y0 + y1) / 2)
            end = points[np.argmin(np.hypot(points[:, 0] - centre[0], points[:, 1] - centre[1]))]
            start = _nearest_on_rect(rect, end)
            if np.hypot(start[0] - end[0], start[1] - end[1]) > 2 * gap:
                _haloed_line(out, start, (int(end[0]), int(end[1])), colours[i], max(1, thick))
                cv2.circle(out, (int(end[0]), int(end[1])), thick + 2, colours[i], -1, cv2.LINE_AA)
    for i, (x0, y0, x1, y1) in placed:
        patch = out[y0:y1, x0:x1].astype(np.float32)
        out[y0:y1, x0:x1] = (patch * (1 - _BOX_ALPHA)).astype(np.uint8)
        cv2.rectangle(out, (x0, y0), (x1 - 1, y1 - 1), colours[i], max(1, thick // 2 + 1))
        put_text(out, texts[i], (x0 + pad, y1 - pad), px, WHITE, outline=BLACK)
    flags = [code for d in defects if d.low_confidence for code in getattr(d, "flags", ())]
    return np.vstack([out, legend_strip(width, flags=flags, unplaced=unplaced)])
