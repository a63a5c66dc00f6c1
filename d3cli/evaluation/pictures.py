"""Pictures people look at: colour bars, the KITTI error colouring, overlays and panels.

All drawing is OpenCV (no matplotlib): a 720p pair's pictures and panel take about
0.3 s in memory (0.32 s measured on the shared 2-core machine).  Images are RGB uint8 (H, W, 3).
Text, colour bars and legends come from :mod:`d3cli.data.legend` (letters >= 12 px,
a title with the unit on every bar, the unit on every tick label).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from ..data.formats import colorize_disparity
from ..data import legend

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

#: Colour bar title of ``error.png`` (the labels are the bin bounds at small ground truth).
ERROR_TITLE = "end-point error [px], KITTI colours (for gt > 60 px: x gt/60); dim: occluded; black: no ground truth"
#: Legend of ``valid_overlay.png``: the colours :func:`validity_overlay` blends in, and their meaning.
FILLED_RGB, NO_DISPARITY_RGB = (255, 40, 40), (40, 80, 255)
OVERLAY_LEGEND = ((FILLED_RGB, "filled"), (NO_DISPARITY_RGB, "no disparity"), ((150, 150, 150), "matched"))

# Largest float32: the ends of a colour range stay below it.
_F32_MAX = float(np.finfo(np.float32).max)


def robust_range(disp: np.ndarray, percentiles=ROBUST_PERCENTILES) -> tuple[float, float]:
    """``(vmin, vmax)``: the given percentiles of the finite values (vmax > vmin guaranteed).

    A constant map gets a range of 1 px above its value (of a millionth of it, for values
    beyond 10^6 px, where adding 1 changes nothing); both ends stay within float32.
    """
    values = np.asarray(disp, dtype=np.float64)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return 0.0, 1.0
    lo, hi = (float(v) for v in np.percentile(values, percentiles))
    if not hi > lo:
        delta = max(1.0, abs(lo) * 1e-6)
        lo, hi = (lo, lo + delta) if lo + delta <= _F32_MAX else (lo - delta, lo)
    return lo, hi


def _turbo(disp: np.ndarray, vmin: float, vmax: float) -> np.ndarray:
    """:func:`colorize_disparity` of ``disp`` over ``[vmin, vmax]``, for any finite range.

    colorize_disparity computes ``(d - vmin) / (vmax - vmin)`` in float32, which
    overflows for ends beyond about 1e30 or a range under 1 px with values near 3e38;
    such ranges are mapped to [0, 1] in float64 here first (twice as slow, same colours).
    """
    if not vmax > vmin:
        raise ValueError(f"a disparity picture needs vmax > vmin, got vmin={vmin}, vmax={vmax}")
    if vmax - vmin >= 1.0 and max(abs(vmin), abs(vmax)) < 1e30:
        return colorize_disparity(disp, vmin, vmax)
    d = np.asarray(disp, dtype=np.float64)
    t = np.clip((d - float(vmin)) / (float(vmax) - float(vmin)), 0.0, 1.0)
    return colorize_disparity(np.where(np.isfinite(d), t, np.inf).astype(np.float32), 0.0, 1.0)


def disparity_picture(disp: np.ndarray, vmin: float, vmax: float, *, how: str) -> np.ndarray:
    """TURBO disparity with a colour bar below it: ticks in px, title with how the range was chosen."""
    rgb = _turbo(disp, vmin, vmax)
    ramp = colorize_disparity(np.linspace(0.0, 1.0, 256, dtype=np.float32)[None, :], 0.0, 1.0)[0]
    width = rgb.shape[1]
    # About one tick per six letter heights: round values that fit between the ends.
    ticks = legend.range_ticks(vmin, vmax, "px", count=max(2, width // (6 * legend.text_px(width))))
    bar = legend.colour_bar(width, ramp, ticks, f"disparity [px]; colours span the {how}; black: no estimate")
    return np.vstack([rgb, bar])


def kitti_error_image(pred: np.ndarray, gt: np.ndarray, *, noc_mask: np.ndarray | None = None) -> np.ndarray:
    """Disparity error in the KITTI devkit's log colouring (blue = good, red = outlier).

    Colour from :data:`KITTI_LOG_COLOURS` of n = min(e / 3, 20 e / gt), e = |d - gt|
    (a missing estimate counts as d = 0, as in the metrics); occluded pixels (outside
    ``noc_mask``) are drawn at half brightness like the devkit; no ground truth: black.
    """
    # float64: in float32, |d - gt| and 20 e / gt overflow for values near 3e38.
    pred = np.asarray(pred, dtype=np.float64)
    gt = np.asarray(gt, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        has_gt = np.isfinite(gt) & (gt > 0)
    g = np.where(has_gt, gt, 1.0)
    e = np.abs(np.where(np.isfinite(pred), pred, 0.0) - g)
    n = np.minimum(e / 3.0, 20.0 * e / g)
    # One bin lookup instead of ten masks (faster at 720p): bin i holds
    # lo_i <= n < lo_{i+1}; index 0 of the table is black for "no ground truth".
    lower = np.array([lo for lo, _, _ in KITTI_LOG_COLOURS[1:]], np.float64)
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
    """Legend strip of the KITTI colouring: the 10 colours, their bounds in px at small gt, a title.

    A bound b of the normalised error n is an error of 3 b px where gt <= 60 px
    (3 px or 5 % of gt, whichever is larger, is n = 1), of 3 b gt / 60 px above.
    """
    colours = np.array([c for _, _, c in KITTI_LOG_COLOURS], np.uint8)
    n = len(KITTI_LOG_COLOURS)
    ticks = [(i / n, f"{3 * KITTI_LOG_COLOURS[i][0]:.2g} px") for i in range(1, n)]
    # Every other bound first, so that narrow pictures get two tidy rows of labels.
    return legend.colour_bar(width, colours, [*ticks[::2], *ticks[1::2], (0.0, "0 px")], ERROR_TITLE, max_rows=2)


def error_picture(pred, gt, *, noc_mask=None) -> np.ndarray:
    """:func:`kitti_error_image` with its legend strip below."""
    rgb = kitti_error_image(pred, gt, noc_mask=noc_mask)
    return np.vstack([rgb, error_legend(rgb.shape[1])])


def validity_overlay(left: np.ndarray, valid: np.ndarray, disp: np.ndarray | None = None) -> np.ndarray:
    """The left image (grey) with filled pixels red and pixels without disparity blue, legend below.

    Pixels the method decided itself show the plain left image, so texture-less or
    occluded regions that were filled stand out.  The legend strip
    (:data:`OVERLAY_LEGEND`) adds rows below the image.
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
    rgb[filled] = 0.45 * rgb[filled] + 0.55 * np.array(FILLED_RGB, np.float32)
    rgb[none] = 0.45 * rgb[none] + 0.55 * np.array(NO_DISPARITY_RGB, np.float32)
    picture = np.clip(rgb, 0, 255).astype(np.uint8)
    return np.vstack([picture, legend.swatch_legend(picture.shape[1], OVERLAY_LEGEND)])


def _fit(img: np.ndarray, width: int) -> np.ndarray:
    img = img if img.ndim == 3 else np.repeat(img[..., None], 3, axis=2)
    if img.dtype != np.uint8:
        img = np.clip(img.astype(np.float32) * (255.0 / max(float(img.max()), 1.0)), 0, 255).astype(np.uint8)
    h = max(1, int(round(img.shape[0] * width / img.shape[1])))
    return cv2.resize(img, (width, h), interpolation=cv2.INTER_AREA)


def panel(title: str, tiles: list[tuple[str, np.ndarray]], *, tile_width: int = legend.REFERENCE_WIDTH) -> np.ndarray:
    """Tiles side by side (each scaled to ``tile_width``) under a title line; captions above each.

    Captions and title are wrapped to the width they have; their text is as tall as
    :func:`legend.text_px` gives for one tile.  Tiles are never scaled up beyond the widest
    picture: a small pair's legends would grow larger than its pictures.
    """
    tile_width = max(1, min(tile_width, max(np.asarray(img).shape[1] for _, img in tiles)))
    fitted = [(caption, _fit(img, tile_width)) for caption, img in tiles]
    height = max(img.shape[0] for _, img in fitted)
    px = legend.text_px(tile_width)
    captions = [legend.text_block(tile_width, caption, px, centre=False) for caption, _ in fitted]
    cap_h = max(c.shape[0] for c in captions)
    cols = []
    for (_, img), caption in zip(fitted, captions):
        col = np.zeros((cap_h + height, tile_width, 3), np.uint8)
        col[: caption.shape[0]] = caption
        col[cap_h: cap_h + img.shape[0]] = img
        cols.append(col)
    gap = np.full((cap_h + height, 6, 3), 255, np.uint8)
    body = cols[0]
    for col in cols[1:]:
        body = np.hstack([body, gap, col])
    head = legend.text_block(body.shape[1], title, round(px * 1.25), bg=legend.WHITE, fg=legend.BLACK, centre=False)
    return np.vstack([head, body])
