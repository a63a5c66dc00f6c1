#!/usr/bin/env python
"""Score road inspection outputs against the pothole ground truth of `d3stereo synth`.

Usage::

    python -m d3cli synth /tmp/road-synth --n 6 --seed 0
    python -m d3cli run /tmp/road-synth -c configs/road.yaml --road-report -o /tmp/road-out
    python scripts/bench_road.py /tmp/road-synth /tmp/road-out [--min-gt-depth-mm 20]

Matching: a predicted pothole (defects.json, kind "pothole") matches the ground-truth
pothole id (potholes_gt.png) that covers most of its bounding box, if that id covers at
least ``--min-overlap`` of the box.  The first (deepest) match of a ground-truth pothole
is a hit; further ones are counted as duplicates (split regions).  Predictions with no
overlap are false defects.  A predicted bump is true when the pair has a ground-truth bump
(SOURCE.txt ``bump: x= y= height=``, world metres) whose centre, projected with the rig
of calib.txt, lies in the bump's bounding box (+ ``--bump-margin-px``); any other bump is a
false defect too (synth roads have at most one bump, 10-25 mm high).  Ground truth counted for recall: depth > --min-gt-depth-mm
and visible in the left image.  Errors are relative: |pred - gt| / gt with pred =
max_depth_mm, area_m2, volume_l and gt = depth_mm, area_m2 (deeper than 10 mm), volume_l.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import cv2
import numpy as np


def gt_bump_px(gt_dir: Path):
    """(u, v) of the pair's ground-truth bump centre in the left image, or None."""
    from d3cli.data.io import read_calib
    from d3cli.data.synth import StereoRig

    source = gt_dir / "SOURCE.txt"
    line = next((ln for ln in source.read_text().splitlines() if ln.startswith("bump:")), "") if source.is_file() else ""
    fields = dict(kv.split("=") for kv in line[len("bump:"):].split() if "=" in kv)
    if not {"x", "y", "height"} <= set(fields):
        return None
    c = read_calib(gt_dir / "calib.txt")
    rig = StereoRig(f=float(c["f"]), baseline=float(c["baseline"]), cx=float(c["cx"]), cy=float(c["cy"]),
                    width=int(c["width"]), height=int(c["height"]), height_m=float(c["height_m"]),
                    pitch_deg=float(c["pitch_deg"]), roll_deg=float(c["roll_deg"]))
    left_c, _ = rig.centres()
    p = rig.rotation() @ (np.array([float(fields["x"]), float(fields["y"]), float(fields["height"])]) - left_c)
    return float(rig.f * p[0] / p[2] + rig.cx), float(rig.f * p[1] / p[2] + rig.cy)


def score_pair(gt_dir: Path, out_dir: Path, *, min_gt_depth_mm: float, min_overlap: float,
               bump_margin_px: float = 10.0) -> dict:
    gt = json.loads((gt_dir / "defects_gt.json").read_text())["potholes"]
    ids = cv2.imread(str(gt_dir / "potholes_gt.png"), cv2.IMREAD_UNCHANGED)
    pred_path = out_dir / "defects.json"
    preds = json.loads(pred_path.read_text())["defects"] if pred_path.is_file() else []
    pits = [d for d in preds if d["kind"] == "pothole"]
    by_id = {g["id"]: g for g in gt}
    counted = {g["id"] for g in gt if g["depth_mm"] > min_gt_depth_mm and g["visible_px"] > 0}
    hits, dup, false = {}, 0, 0
    for d in sorted(pits, key=lambda d: -d["max_depth_mm"]):
        u0, v0, u1, v1 = d["bbox_px"]
        box = ids[v0:v1 + 1, u0:u1 + 1]
        labels, counts = np.unique(box[box > 0], return_counts=True)
        if len(labels) == 0 or counts.max() < min_overlap * box.size:
            false += 1
            continue
        gid = int(labels[np.argmax(counts)])
        if gid in hits:
            dup += 1
        else:
            hits[gid] = d
    bump_at = gt_bump_px(gt_dir)
    false_bumps = 0
    for d in preds:
        if d["kind"] != "bump":
            continue
        u0, v0, u1, v1 = d["bbox_px"]
        m = bump_margin_px
        if bump_at is None or not (u0 - m <= bump_at[0] <= u1 + m and v0 - m <= bump_at[1] <= v1 + m):
            false_bumps += 1
    errors = []
    for gid, d in hits.items():
        g = by_id[gid]
        errors.append({"pair": gt_dir.name, "id": gid, "gt_depth_mm": g["depth_mm"],
                       "depth": abs(d["max_depth_mm"] - g["depth_mm"]) / g["depth_mm"],
                       "area": abs(d["area_m2"] - g["area_m2"]) / g["area_m2"] if g["area_m2"] > 0 else np.nan,
                       "volume": abs(d["volume_l"] - g["volume_l"]) / g["volume_l"],
                       "signed_depth": (d["max_depth_mm"] - g["depth_mm"]) / g["depth_mm"],
                       "signed_area": (d["area_m2"] - g["area_m2"]) / g["area_m2"] if g["area_m2"] > 0 else np.nan})
    return {"pair": gt_dir.name, "gt": len(counted), "found": len(counted & set(hits)), "predicted": len(pits),
            "matched": len(hits), "duplicates": dup, "false": false,
            "bumps": sum(d["kind"] == "bump" for d in preds), "false_bumps": false_bumps, "errors": errors,
            "has_report": pred_path.is_file()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("gt_root", type=Path, help="folder of synth pairs (defects_gt.json, potholes_gt.png)")
    ap.add_argument("out_root", type=Path, help="output folder of `run --road-report`")
    ap.add_argument("--min-gt-depth-mm", type=float, default=20.0)
    ap.add_argument("--min-overlap", type=float, default=0.2)
    ap.add_argument("--bump-margin-px", type=float, default=10.0)
    ap.add_argument("--json", type=Path, help="also write the per-pair scores here")
    args = ap.parse_args(argv)
    pairs = sorted(p for p in args.gt_root.iterdir() if (p / "defects_gt.json").is_file())
    if not pairs:
        print(f"Error: {args.gt_root}: no pair folder with defects_gt.json; generate it with `d3stereo synth`",
              file=sys.stderr)
        return 1
    rows = [score_pair(p, args.out_root / p.name, min_gt_depth_mm=args.min_gt_depth_mm,
                       min_overlap=args.min_overlap, bump_margin_px=args.bump_margin_px) for p in pairs]
    for r in rows:
        errs = ", ".join(f"#{e['id']} {e['gt_depth_mm']:.0f}mm d{100 * e['signed_depth']:+.0f}% "
                         f"a{100 * e['signed_area']:+.0f}% v{100 * e['volume']:.0f}%" for e in r["errors"])
        print(f"{r['pair']}: gt {r['gt']} found {r['found']} predicted {r['predicted']} false {r['false']} "
              f"dup {r['duplicates']} bumps {r['bumps']} (false {r['false_bumps']}){'' if r['has_report'] else ' (no defects.json)'}  {errs}")
    gt = sum(r["gt"] for r in rows)
    found = sum(r["found"] for r in rows)
    predicted = sum(r["predicted"] for r in rows)
    false = sum(r["false"] for r in rows)
    false_bumps = sum(r["false_bumps"] for r in rows)
    errors = [e for r in rows for e in r["errors"]]
    summary = {
        "pairs": len(rows), "gt_potholes": gt, "found": found,
        "recall": found / gt if gt else float("nan"),
        "precision": (predicted - false) / predicted if predicted else float("nan"),
        "false_per_pair": false / len(rows),
        "false_bumps_per_pair": false_bumps / len(rows),
        "false_defects_per_pair": (false + false_bumps) / len(rows),
        "max_false_defects_in_a_pair": max(r["false"] + r["false_bumps"] for r in rows),
        "duplicates": sum(r["duplicates"] for r in rows),
        "median_depth_error": float(np.median([e["depth"] for e in errors])) if errors else float("nan"),
        "median_area_error": float(np.nanmedian([e["area"] for e in errors])) if errors else float("nan"),
        "median_volume_error": float(np.median([e["volume"] for e in errors])) if errors else float("nan"),
    }
    print(f"recall {100 * summary['recall']:.1f} % ({found}/{gt} deeper than {args.min_gt_depth_mm:g} mm)  "
          f"precision {100 * summary['precision']:.1f} %  duplicates {summary['duplicates']}")
    print(f"false defects/pair {summary['false_defects_per_pair']:.2f} (potholes {summary['false_per_pair']:.2f}, "
          f"bumps {summary['false_bumps_per_pair']:.2f}; most in one pair: {summary['max_false_defects_in_a_pair']})")
    print(f"median error: depth {100 * summary['median_depth_error']:.1f} %  "
          f"area {100 * summary['median_area_error']:.1f} %  volume {100 * summary['median_volume_error']:.1f} %")
    if args.json:
        args.json.write_text(json.dumps({"summary": summary, "pairs": rows}, indent=2, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
