"""Pictures people look at: colour bars, the KITTI error colouring, overlays and panels.

All drawing is OpenCV (no matplotlib): a 720p pair's pictures and panel take about
0.3 s in memory (0.32 s measured on the shared 2-core machine).  Images are RGB uint8 (H, W, 3).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from ..data.formats import colorize_disparity

#: Percentiles of the estimate that span ``disp_color.png`` unless a range is fixed.
ROBUST_PERCENTILES = (1.0, 99.0)

#: KITTI devkit log colour scale (devkit ``errorImage``): normalised error bounds
#: ``[lo, hi)`` and RGB.  Normalised error n = min(e / 3, 20 e / gt): n = 1 is the D1
#: outlier boundary (3 px or 5 % of the true disparity, whichever is larger).
KITTI_LOG_COLOURS = (
    (0.0, 0.0625, (49, 54, 149)),
    (0.0625, 0.125, (69, 117, 180)),
    (0.125, 0.25, (116, 173, 209)),
    (0.25, 0.5, (171, 217, 233)),
    (0.5, 1.0, (224, 243, 248)),
    (1.0, 2.0, (254, 224, 144)),
    (2.0, 4.0, (253, 174, 97)),
    (4.0, 8.0, (244, 109, 67)),
    (8.0, 16.0, (215, 48, 39)),
    (16.0, math.inf, (165, 0, 38)),
)

_FONT = cv2.FONT_HERSHEY_SIMPLEX


def robust_range(disp: np.ndarray, percentiles=ROBUST_PERCENTILES) -> tuple[float, float]:
    """``(vmin, vmax)``: the given percentiles of the finite values (vmax > vmin guaranteed)."""
    values = np.asarray(disp, dtype=np.float64)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return 0.0, 1.0
    lo, hi = (float(v) for v in np.percentile(values, percentiles))
    if not hi > lo:
        hi = lo + 1.0
    return lo, hi


def _text(img, text, org, scale, colour=(255, 255, 255)):
    cv2.putText(img, text, org, _FONT, scale, colour, max(1, int(round(scale * 2))), cv2.LINE_AA)


def _strip_height(width: int) -> tuple[int, float]:
    scale = max(0.35, min(1.0, width / 1400))
    return int(40 * scale / 0.5), scale


def disparity_picture(disp: np.ndarray, vmin: float, vmax: float, *, how: str) -> np.ndarray:
    """TURBO disparity with a colour bar below it, labelled with the range and how it was chosen."""
    rgb = colorize_disparity(disp, vmin, vmax)
    width = rgb.shape[1]
    bar_h, scale = _strip_height(width)
    strip = np.zeros((bar_h, width, 3), np.uint8)
    margin = min(10, width // 8)  # tiny test images: the bar still fits
    ramp = np.linspace(vmin, vmax, width - 2 * margin, dtype=np.float32)[None, :]
    strip[2: bar_h // 2, margin: width - margin] = colorize_disparity(np.repeat(ramp, bar_h // 2 - 2, 0), vmin, vmax)
    y = bar_h - 6
    _text(strip, f"{vmin:.1f}", (10, y), scale)
    label = f"disparity (px), {how}"
    (tw, _), _ = cv2.getTextSize(label, _FONT, scale, 1)
    _text(strip, label, ((width - tw) // 2, y), scale)
    top = f"{vmax:.1f}"
    (tw, _), _ = cv2.getTextSize(top, _FONT, scale, 1)
    _text(strip, top, (width - 10 - tw, y), scale)
    return np.vstack([rgb, strip])


def kitti_error_image(pred: np.ndarray, gt: np.ndarray, *, noc_mask: np.ndarray | None = None) -> np.ndarray:
    """Disparity error in the KITTI devkit's log colouring (blue = good, red = outlier).

    Colour from :data:`KITTI_LOG_COLOURS` of n = min(e / 3, 20 e / gt), e = |d - gt|
    (a missing estimate counts as d = 0, as in the metrics); occluded pixels (outside
    ``noc_mask``) are drawn at half brightness like the devkit; no ground truth: black.
    """
    pred = np.asarray(pred, dtype=np.float32)
    gt = np.asarray(gt, dtype=np.float32)
    with np.errstate(invalid="ignore"):
        has_gt = np.isfinite(gt) & (gt > 0)
    g = np.where(has_gt, gt, np.float32(1.0))
    e = np.abs(np.where(np.isfinite(pred), pred, np.float32(0.0)) - g)
    n = np.minimum(e / np.float32(3.0), np.float32(20.0) * e / g)
    # One bin lookup instead of ten masks (faster at 720p): bin i holds
    # lo_i <= n < lo_{i+1}; index 0 of the table is black for "no ground truth".
    lower = np.array([lo for lo, _, _ in KITTI_LOG_COLOURS[1:]], np.float32)
    table = np.array([(0, 0, 0)] + [c for _, _, c in KITTI_LOG_COLOURS], np.uint8)
    if noc_mask is not None:
        # Occluded pixels at half brightness, like the devkit: a second half of the table.
        table = np.vstack([table, table[1:] // 2])
    index = np.searchsorted(lower, n, side="right").astype(np.intp) + 1
    if noc_mask is not None:
        index[np.asarray(noc_mask) == 0] += len(KITTI_LOG_COLOURS)
    index[~has_gt] = 0
    return table[index]


def error_legend(width: int) -> np.ndarray:
    """Legend strip of the KITTI colouring: the 10 bins as errors in px at small gt (3 px scale)."""
    bar_h, scale = _strip_height(width)
    strip = np.zeros((bar_h, width, 3), np.uint8)
    n = len(KITTI_LOG_COLOURS)
    cell = (width - 20) / n
    for i, (lo, hi, colour) in enumerate(KITTI_LOG_COLOURS):
        x0, x1 = int(10 + i * cell), int(10 + (i + 1) * cell) - 2
        strip[2: bar_h // 2, x0:x1] = colour
        # Lower bound of each bin in px (exact where 3 px > 5 % of gt, i.e. gt <= 60).
        label = f"{3 * lo:.2g}" + ("+ px" if math.isinf(hi) else "")
        _text(strip, label, (x0 + 2, bar_h - 6), scale * 0.8)
    return strip


def error_picture(pred, gt, *, noc_mask=None) -> np.ndarray:
    """:func:`kitti_error_image` with its legend strip below."""
    rgb = kitti_error_image(pred, gt, noc_mask=noc_mask)
    return np.vstack([rgb, error_legend(rgb.shape[1])])


def validity_overlay(left: np.ndarray, valid: np.ndarray, disp: np.ndarray | None = None) -> np.ndarray:
    """The left image (grey, dimmed) with filled pixels red and pixels without disparity blue.

    Pixels the method decided itself show the plain left image, so texture-less or
    occluded regions that were filled stand out.
    """
    left = np.asarray(left)
    grey = left if left.ndim == 2 else cv2.cvtColor(np.ascontiguousarray(left[..., :3]), cv2.COLOR_RGB2GRAY)
    grey = grey.astype(np.float32)
    if grey.max() > 255:
        grey = grey * (255.0 / grey.max())
    rgb = np.repeat(grey[..., None], 3, axis=2)
    valid = np.asarray(valid, dtype=bool)
    filled = ~valid
    none = np.zeros_like(valid) if disp is None else ~np.isfinite(np.asarray(disp))
    rgb[filled] = 0.45 * rgb[filled] + 0.55 * np.array([255.0, 40.0, 40.0])
    rgb[none] = 0.45 * rgb[none] + 0.55 * np.array([40.0, 80.0, 255.0])
    return np.clip(rgb, 0, 255).astype(np.uint8)


def _fit(img: np.ndarray, width: int) -> np.ndarray:
    img = img if img.ndim == 3 else np.repeat(img[..., None], 3, axis=2)
    if img.dtype != np.uint8:
        img = np.clip(img.astype(np.float32) * (255.0 / max(float(img.max()), 1.0)), 0, 255).astype(np.uint8)
    h = max(1, int(round(img.shape[0] * width / img.shape[1])))
    return cv2.resize(img, (width, h), interpolation=cv2.INTER_AREA)


def panel(title: str, tiles: list[tuple[str, np.ndarray]], *, tile_width: int = 480) -> np.ndarray:
    """Tiles side by side (each scaled to ``tile_width``) under a title line; captions above each."""
    fitted = [(caption, _fit(img, tile_width)) for caption, img in tiles]
    height = max(img.shape[0] for _, img in fitted)
    cap_h, scale = 26, 0.55
    cols = []
    for caption, img in fitted:
        col = np.zeros((cap_h + height, tile_width, 3), np.uint8)
        col[cap_h: cap_h + img.shape[0]] = img
        _text(col, caption, (6, 18), scale)
        cols.append(col)
    gap = np.full((cap_h + height, 6, 3), 255, np.uint8)
    body = cols[0]
    for col in cols[1:]:
        body = np.hstack([body, gap, col])
    head = np.full((34, body.shape[1], 3), 255, np.uint8)
    _text(head, title, (8, 24), 0.7, (0, 0, 0))
    return np.vstack([head, body])
