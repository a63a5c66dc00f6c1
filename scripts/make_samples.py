"""Regenerate the bundled sample pairs in d3cli/data/samples/ (deterministic).

    python scripts/make_samples.py [--out d3cli/data/samples]

Two pairs in the pair-folder layout (left.png, right.png, disp_gt.pfm, calib.txt,
SOURCE.txt), kept small so CI stays fast and the wheel stays light (< 1.5 MB):

- ``motorcycle``: Middlebury 2014 Motorcycle as shipped by scikit-image
  (``skimage.data.stereo_motorcycle()``, already 1/4 of full size), halved again:
  images by area averaging, ground truth by a valid-aware 2x2 reduction (see
  :func:`halve_disparity`) divided by 2.
- ``road``: a synthetic road surface with exact ground truth: a textured plane whose
  disparity is linear in the row (the v-disparity line of a flat road) with a smooth
  pothole-like depression.  Both views sample one high-resolution texture painted on
  the surface; the right view is rendered by exact inverse warping (each right pixel
  finds the surface point it sees by fixed-point iteration of ``u = u' + d(u, v)``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np

from d3cli.data.formats import write_image, write_pfm

SAMPLES = Path(__file__).resolve().parents[1] / "d3cli" / "data" / "samples"

MOTORCYCLE_SOURCE = """\
provenance: Middlebury 2014 stereo dataset, scene Motorcycle (default exposure, perfect rectification),
  as shipped by scikit-image (skimage.data.stereo_motorcycle(), 741x500, 1/4 of full size),
  reduced by 2 to 370x250 by scripts/make_samples.py (images: cv2.INTER_AREA; ground truth: 2x2 blocks whose
  finite values agree within 1 px are averaged, others invalid; then divided by 2).
authors: D. Scharstein, H. Hirschmueller, Y. Kitajima, G. Krathwohl, N. Nesic, X. Wang, P. Westling,
  High-resolution stereo datasets with subpixel-accurate ground truth, GCPR 2014.
url: https://vision.middlebury.edu/stereo/data/scenes2014/
licence: Middlebury stereo data, free for research use with citation of the paper above (as redistributed by
  scikit-image, BSD-3-Clause for the scikit-image package).
family: middlebury2014
gt_scale: 1
gt_invalid: inf
"""

ROAD_SOURCE = """\
provenance: synthetic road surface made by scripts/make_samples.py (seed 2024): a textured plane with disparity
  linear in the row (d = {d_top} px at the top row to {d_bottom} px at the bottom row) and a smooth pothole-like
  depression ({depth} px deep at its centre); right view rendered by exact inverse warping of a 4x supersampled
  texture; ground truth exact at pixel centres, inf where the match falls outside the right image.
licence: CC0 (generated data)
family: synth
gt_scale: 1
gt_invalid: inf
"""


# ----------------------------------------------------------------------------- motorcycle
def halve_disparity(disp: np.ndarray, *, max_spread: float = 1.0) -> np.ndarray:
    """Reduce a ground-truth disparity map by 2 in each direction, keeping it honest.

    Each output pixel covers a 2x2 block.  When the block's finite values agree within
    ``max_spread`` pixels (one surface), their mean is kept; blocks that straddle a
    depth edge or hold fewer than two finite values become ``inf`` (no ground truth
    is better than a blend of two surfaces).  Values are then halved (disparity scales
    with the image width).

    Parameters
    ----------
    disp : ndarray, float, (H, W)
        Disparity in pixels, non-finite = unknown.

    Returns
    -------
    ndarray, float32, (H // 2, W // 2)
    """
    h, w = (disp.shape[0] // 2) * 2, (disp.shape[1] // 2) * 2
    blocks = disp[:h, :w].astype(np.float64).reshape(h // 2, 2, w // 2, 2).transpose(0, 2, 1, 3).reshape(h // 2, w // 2, 4)
    finite = np.isfinite(blocks)
    count = finite.sum(axis=2)
    total = np.where(finite, blocks, 0.0).sum(axis=2)
    hi = np.where(finite, blocks, -np.inf).max(axis=2)
    lo = np.where(finite, blocks, np.inf).min(axis=2)
    keep = (count >= 2) & (hi - lo <= max_spread)
    mean = np.divide(total, count, out=np.zeros_like(total), where=count > 0)
    return np.where(keep, mean / 2.0, np.inf).astype(np.float32)


def make_motorcycle(folder: Path) -> None:
    from skimage.data import stereo_motorcycle

    left, right, disp = stereo_motorcycle()
    size = (left.shape[1] // 2, left.shape[0] // 2)  # cv2 wants (width, height)
    left2 = cv2.resize(left, size, interpolation=cv2.INTER_AREA)
    right2 = cv2.resize(right, size, interpolation=cv2.INTER_AREA)
    gt = halve_disparity(disp)
    ndisp = int(np.ceil(np.nanmax(gt[np.isfinite(gt)]) / 8.0) * 8) + 8
    folder.mkdir(parents=True, exist_ok=True)
    write_image(folder / "left.png", left2)
    write_image(folder / "right.png", right2)
    write_pfm(folder / "disp_gt.pfm", gt)
    # skimage's calibration of the 1/4 images, halved (f, cx, cy, doffs in pixels).
    f, cx, cy, doffs = 994.978 / 2, 311.193 / 2, 254.877 / 2, 31.086 / 2
    (folder / "calib.txt").write_text(
        f"cam0=[{f:.3f} 0 {cx:.3f}; 0 {f:.3f} {cy:.3f}; 0 0 1]\n"
        f"cam1=[{f:.3f} 0 {cx + doffs:.3f}; 0 {f:.3f} {cy:.3f}; 0 0 1]\n"
        f"doffs={doffs:.3f}\nbaseline=193.001\nwidth={size[0]}\nheight={size[1]}\nndisp={ndisp}\n"
    )
    (folder / "SOURCE.txt").write_text(MOTORCYCLE_SOURCE)


# ----------------------------------------------------------------------------- road
ROAD_SIZE = (240, 320)  # (height, width)
D_TOP, D_BOTTOM = 6.0, 30.0
POTHOLE = {"u": 190.0, "v": 170.0, "ru": 38.0, "rv": 16.0, "depth": 3.0}
SUPERSAMPLE = 4


def road_disparity(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Left-view disparity (px) of the road at continuous coordinates (u, v).

    A plane (linear in v) minus a smooth bowl ``depth * (1 - r^2)^2`` inside the
    pothole ellipse: deeper surface, smaller disparity.
    """
    height = ROAD_SIZE[0]
    plane = D_TOP + (D_BOTTOM - D_TOP) * v / (height - 1)
    r2 = ((u - POTHOLE["u"]) / POTHOLE["ru"]) ** 2 + ((v - POTHOLE["v"]) / POTHOLE["rv"]) ** 2
    bowl = np.where(r2 < 1.0, POTHOLE["depth"] * (1.0 - r2) ** 2, 0.0)
    return plane - bowl


def road_texture(rng: np.random.Generator, height: int, width: int) -> np.ndarray:
    """Asphalt-like texture at SUPERSAMPLE x resolution: multi-scale noise, 0-255 float32."""
    s = SUPERSAMPLE
    tex = np.zeros((height * s, width * s), np.float32)
    for sigma, weight in ((0.7 * s, 1.0), (2.0 * s, 0.6), (8.0 * s, 0.5)):
        noise = rng.standard_normal(tex.shape).astype(np.float32)
        layer = cv2.GaussianBlur(noise, (0, 0), sigma)
        tex += weight * layer / (layer.std() + 1e-6)
    tex = 110.0 + 28.0 * tex / tex.std()
    return np.clip(tex, 0, 255).astype(np.float32)


def _sample(tex: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Bilinear texture lookup at image coordinates (pixel centres at integers)."""
    s = SUPERSAMPLE
    map_x = ((u + 0.5) * s - 0.5).astype(np.float32)
    map_y = ((v + 0.5) * s - 0.5).astype(np.float32)
    return cv2.remap(tex, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)


def _render(tex: np.ndarray, view: str) -> np.ndarray:
    """Render one view as the mean of SUPERSAMPLE^2 texture samples per pixel (area sampling)."""
    height, width = ROAD_SIZE
    s = SUPERSAMPLE
    offsets = (np.arange(s) + 0.5) / s - 0.5
    acc = np.zeros((height, width), np.float64)
    vv, uu = np.mgrid[0:height, 0:width].astype(np.float64)
    for dy in offsets:
        for dx in offsets:
            u, v = uu + dx, vv + dy
            if view == "right":
                # The surface point seen at right (u', v) has left u = u' + d(u, v);
                # |dd/du| < 1 makes the fixed-point iteration converge.
                x = u + road_disparity(u, v)
                for _ in range(30):
                    x = u + road_disparity(x, v)
                u = x
            acc += _sample(tex, u, v)
    return acc / (s * s)


def make_road(folder: Path, *, seed: int = 2024) -> None:
    height, width = ROAD_SIZE
    rng = np.random.default_rng(seed)
    margin = int(D_BOTTOM) + 4  # texture must also cover what only the right view sees
    tex_full = road_texture(rng, height, width + margin)
    left = _render(tex_full, "left")
    right = _render(tex_full, "right")
    # Mild sensor noise, independent per view.
    left = np.clip(np.rint(left + rng.normal(0, 1.0, left.shape)), 0, 255).astype(np.uint8)
    right = np.clip(np.rint(right + rng.normal(0, 1.0, right.shape)), 0, 255).astype(np.uint8)
    vv, uu = np.mgrid[0:height, 0:width].astype(np.float64)
    gt = road_disparity(uu, vv)
    gt[uu - gt < 0] = np.inf  # the match would lie left of the right image
    folder.mkdir(parents=True, exist_ok=True)
    write_image(folder / "left.png", left)
    write_image(folder / "right.png", right)
    write_pfm(folder / "disp_gt.pfm", gt.astype(np.float32))
    ndisp = int(np.ceil(D_BOTTOM / 8.0) * 8) + 8
    (folder / "calib.txt").write_text(f"width: {width}\nheight: {height}\nndisp: {ndisp}\n")
    (folder / "SOURCE.txt").write_text(ROAD_SOURCE.format(d_top=D_TOP, d_bottom=D_BOTTOM, depth=POTHOLE["depth"]))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=SAMPLES, help="samples folder (default: d3cli/data/samples)")
    args = parser.parse_args(argv)
    make_motorcycle(args.out / "motorcycle")
    make_road(args.out / "road")
    total = sum(p.stat().st_size for p in args.out.rglob("*") if p.is_file() and p.parent != args.out)
    print(f"wrote {args.out / 'motorcycle'} and {args.out / 'road'}: {total / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
