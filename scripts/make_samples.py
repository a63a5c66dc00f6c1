"""Regenerate the bundled sample pairs in d3cli/data/samples/ (deterministic).

    python scripts/make_samples.py [--out d3cli/data/samples]

Two pairs in the pair-folder layout (left.png, right.png, disp_gt.pfm, calib.txt,
SOURCE.txt), kept small so CI stays fast and the wheel stays light (< 1.5 MB):

- ``motorcycle``: Middlebury 2014 Motorcycle as shipped by scikit-image
  (``skimage.data.stereo_motorcycle()``, already 1/4 of full size), halved again:
  images by area averaging, ground truth by a valid-aware 2x2 reduction (see
  :func:`halve_disparity`) divided by 2.
- ``road``: a `d3stereo synth` road pair (:func:`d3cli.data.synth.render_pair`, sun,
  asphalt, one pothole) with its exact ground truth and calibration (focal length,
  baseline), so ``d3stereo run --road-report`` shows the pothole measured.
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
provenance: synthetic road made by scripts/make_samples.py with d3cli.data.synth.render_pair(seed={seed},
  width={width}, height={height}, variant='sun', material='asphalt', potholes=1): ray-cast stereo pair with
  exact ground truth; calib.txt holds the rig (focal length and baseline), so --road-report measures the
  pothole: {shape}, {depth:.1f} mm deep, {area:.3f} m^2 deeper than 10 mm, {volume:.2f} l.
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
ROAD_SEED = 2035  # one bowl-shaped pothole, 51.7 mm deep, 0.128 m^2, in the middle of the view


def make_road(folder: Path, *, seed: int = ROAD_SEED) -> None:
    """A `d3stereo synth` road pair (sun, asphalt, one pothole) with its rig's calibration,
    so that ``--road-report`` measures the pothole in millimetres."""
    from d3cli.data.synth import render_pair

    height, width = ROAD_SIZE
    pair = render_pair(seed=seed, width=width, height=height, variant="sun", material="asphalt", potholes=1)
    folder.mkdir(parents=True, exist_ok=True)
    write_image(folder / "left.png", pair.left)
    write_image(folder / "right.png", pair.right)
    write_pfm(folder / "disp_gt.pfm", pair.disparity)
    c = pair.calib
    (folder / "calib.txt").write_text("".join(
        f"{key}: {c[key] if isinstance(c[key], int) else format(c[key], '.10g')}\n"
        for key in ("f", "baseline", "cx", "cy", "width", "height", "height_m", "pitch_deg", "roll_deg", "doffs",
                    "ndisp")))
    (gt,) = pair.defects_gt
    (folder / "SOURCE.txt").write_text(ROAD_SOURCE.format(
        seed=seed, width=width, height=height, shape=gt["shape"], depth=gt["depth_mm"], area=gt["area_m2"],
        volume=gt["volume_l"]))


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
