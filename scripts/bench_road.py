#!/usr/bin/env python
"""Score road inspection outputs against the pothole ground truth of `d3stereo synth`.

Usage::

    python -m d3cli synth /tmp/road-synth --n 6 --seed 0
    python -m d3cli run /tmp/road-synth -c road --road-report -o /tmp/road-out
    python scripts/bench_road.py /tmp/road-synth /tmp/road-out [--min-gt-depth-mm 20]

Matching, ``--rule deep`` (the default; docs/road.md, "The match rule"): a detection's pixels
are its ``outline_px`` polygons (defects.json; its bounding box for outputs without them), a
ground-truth pothole's pixels are its id in potholes_gt.png (the surface it lowers by more than
1 mm, deeper pothole wins where two overlap; nested potholes are one defect under the deepest
one's id, the others' entries say ``part_of`` and have no pixels, so they are not counted); its
*deep part* is those pixels lowered by more than ``--threshold-mm`` (10, the report's
``road.min_depth_mm``), its *deepest point* the pixel lowered most (the synth road rebuilt from
SOURCE.txt's pair_seed: ``d3cli.data.synth.pothole_depth_image``).  A detection at least half of
which lies on pothole pixels stands for the pothole holding most of its pixels, and matches it
when it covers at least half of its deep part or its deepest point.  One to one: of several
detections matching a pothole the one covering most of its deep part wins (then the one with
more pixels on it).  ``--rule footprint`` is the overlap rule: a detection and a pothole can
match when at least ``--min-inside`` (0.5) of the detection lies on that pothole and it covers at
least ``--min-cover`` (0.3) of the pothole's pixels, largest overlap first.  Under both rules a
detection that matches nothing is a **false defect** when less than half of it lies on pothole
pixels of any id, else a **duplicate** (a fragment of a pothole, or one region spanning two
potholes: a split or merge error); a pothole joined with its neighbour into one region counts for
at most one of them, and a pothole cut into pieces is found once.

Bumps: a predicted bump is true when the pair has a ground-truth bump (SOURCE.txt
``bump: x= y= height=``, world metres) whose centre, projected with the rig of calib.txt,
lies in the bump's bounding box (+ ``--bump-margin-px``); any other bump is a false defect
too (synth roads have at most one bump, 10-25 mm high).  Ground truth counted for recall:
depth > --min-gt-depth-mm and visible in the left image.  Errors are relative: |pred - gt| /
gt with pred = max_depth_mm, area_m2, volume_l and gt = depth_mm, area_m2 (deeper than
10 mm), volume_l.  "spurious" per pair = false potholes + false bumps + duplicates.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import cv2
import numpy as np

from d3cli.evaluation.html import detection_mask  # a detection's pixels, as report.html scores them


def gt_bump_px(gt_dir: Path):
    """(u, v) of the pair's ground-truth bump centre in the left image, or None."""
    from d3cli.data.formats import read_calib
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


def match_potholes(ids: np.ndarray, pits: list, *, min_inside: float, min_cover: float):
    """One-to-one matching of detections to ground-truth pothole ids (module docstring).

    Returns
    -------
    hits : dict gt id -> detection
    duplicates, false : int
    """
    gt_px = {int(k): int(c) for k, c in zip(*np.unique(ids[ids > 0], return_counts=True))}
    masks = [detection_mask(d, ids.shape) for d in pits]
    overlaps = []
    for i, m in enumerate(masks):
        labels, counts = np.unique(ids[m], return_counts=True)
        size = max(int(m.sum()), 1)
        for k, c in zip(labels, counts):
            if k > 0 and c >= min_inside * size and c >= min_cover * gt_px[int(k)]:
                overlaps.append((int(c), i, int(k)))
    return _assign(ids, masks, pits, overlaps)


def match_deep(ids: np.ndarray, depth_mm: np.ndarray, pits: list, *, threshold_mm: float):
    """One-to-one matching by the deep part and the deepest point (module docstring).

    Parameters
    ----------
    ids : ndarray, uint8, (H, W)
        Ground-truth pothole id per pixel (0: none).
    depth_mm : ndarray, float, (H, W)
        How far the potholes lower the road at each pixel (nan: unknown).
    pits : list of dict
        Predicted potholes (defects.json entries).
    threshold_mm : float
        The report's depth threshold: a pothole's deep part is deeper than this.

    Returns
    -------
    hits : dict gt id -> detection
    duplicates, false : int
    """
    depth = np.nan_to_num(np.asarray(depth_mm, np.float64), nan=-np.inf)
    masks = [detection_mask(d, ids.shape) for d in pits]
    claims = []
    for i, m in enumerate(masks):
        on = ids[m]
        on = on[on > 0]
        if on.size < 0.5 * max(int(m.sum()), 1):
            continue
        labels, counts = np.unique(on, return_counts=True)
        k = int(labels[np.argmax(counts)])
        pothole = ids == k
        deep = pothole & (depth > threshold_mm)
        deepest = np.unravel_index(np.argmax(np.where(pothole, depth, -np.inf)), ids.shape)
        cover = int((m & deep).sum())
        if (deep.any() and cover >= 0.5 * int(deep.sum())) or m[deepest]:
            claims.append((cover, int(counts.max()), i, k))
    return _assign(ids, masks, pits, [((cover, inside), i, k) for cover, inside, i, k in claims])


def _assign(ids: np.ndarray, masks: list, pits: list, candidates: list):
    """One-to-one assignment, best ``(score, detection, pothole)`` first (a detection and a
    pothole each taken once); the detections left over are duplicates when at least half of
    them lies on pothole pixels, else false defects.  (hits, duplicates, false)."""
    hits, used = {}, set()
    for _, i, k in sorted(candidates, reverse=True):
        if i not in used and k not in hits:
            hits[k] = pits[i]
            used.add(i)
    duplicates = false = 0
    for i, m in enumerate(masks):
        if i in used:
            continue
        if (ids[m] > 0).sum() >= 0.5 * max(int(m.sum()), 1):
            duplicates += 1
        else:
            false += 1
    return hits, duplicates, false


def gt_depth_mm(gt_dir: Path, shape) -> np.ndarray:
    """How far the potholes lower the road at each left pixel of a synth pair, mm (nan where
    the pair has no SOURCE.txt pair_seed or no exact disparity)."""
    from d3cli.data.formats import read_pfm
    from d3cli.data.synth import pothole_depth_image

    fields = source_fields(gt_dir)
    if "pair_seed" not in fields or not (gt_dir / "disp_gt.pfm").is_file():
        return np.full(shape, np.nan)
    width, height = (int(x) for x in fields["image_size"].split("x"))
    return pothole_depth_image(seed=int(fields["pair_seed"]), width=width, height=height,
                               disparity=read_pfm(gt_dir / "disp_gt.pfm"))


def score_pair(gt_dir: Path, out_dir: Path, *, min_gt_depth_mm: float, min_inside: float = 0.5,
               min_cover: float = 0.3, bump_margin_px: float = 10.0, min_decided_share: float = 0.0,
               rule: str = "deep", threshold_mm: float = 10.0, depth_mm: np.ndarray | None = None) -> dict:
    """Scores of one pair (module docstring); ``depth_mm`` (how far the potholes lower the
    road per pixel, for ``rule="deep"``) is rebuilt from the pair's SOURCE.txt when None."""
    gt = json.loads((gt_dir / "defects_gt.json").read_text())["potholes"]
    ids = cv2.imread(str(gt_dir / "potholes_gt.png"), cv2.IMREAD_UNCHANGED)
    pred_path = out_dir / "defects.json"
    preds = json.loads(pred_path.read_text())["defects"] if pred_path.is_file() else []
    # What-if filter: score as if defects with a smaller decided share had been dropped
    # (find_defects measures each region independently, so dropping one changes no other).
    preds = [d for d in preds if d.get("decided_share", 1.0) >= min_decided_share]
    pits = [d for d in preds if d["kind"] == "pothole"]
    by_id = {g["id"]: g for g in gt}
    counted = {g["id"] for g in gt if g["depth_mm"] > min_gt_depth_mm and g["visible_px"] > 0}
    if rule == "deep":
        if depth_mm is None:
            depth_mm = gt_depth_mm(gt_dir, ids.shape)
        hits, dup, false = match_deep(ids, depth_mm, pits, threshold_mm=threshold_mm)
    else:
        hits, dup, false = match_potholes(ids, pits, min_inside=min_inside, min_cover=min_cover)
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
    matched_ids = {id(d) for d in hits.values()}
    detections = []  # every predicted defect: its class under the match rule and its confidence
    for d in pits:
        if id(d) in matched_ids:
            status = "match"
        else:
            m = detection_mask(d, ids.shape)
            status = "duplicate" if (ids[m] > 0).sum() >= 0.5 * max(int(m.sum()), 1) else "false"
        detections.append({"kind": "pothole", "status": status, "ok": is_ok(d), "flags": list(d.get("flags", []))})
    for d in preds:
        if d["kind"] == "bump":
            u0, v0, u1, v1 = d["bbox_px"]
            m = bump_margin_px
            true = bump_at is not None and u0 - m <= bump_at[0] <= u1 + m and v0 - m <= bump_at[1] <= v1 + m
            detections.append({"kind": "bump", "status": "match" if true else "false", "ok": is_ok(d),
                               "flags": list(d.get("flags", []))})
    for gid, d in hits.items():
        g = by_id[gid]
        errors.append({"pair": gt_dir.name, "id": gid, "shape": g.get("shape", "classic"), "gt_depth_mm": g["depth_mm"],
                       "depth": abs(d["max_depth_mm"] - g["depth_mm"]) / g["depth_mm"],
                       "area": abs(d["area_m2"] - g["area_m2"]) / g["area_m2"] if g["area_m2"] > 0 else np.nan,
                       "volume": abs(d["volume_l"] - g["volume_l"]) / g["volume_l"],
                       "signed_depth": (d["max_depth_mm"] - g["depth_mm"]) / g["depth_mm"],
                       "signed_area": (d["area_m2"] - g["area_m2"]) / g["area_m2"] if g["area_m2"] > 0 else np.nan,
                       "counted": gid in counted, "ok": is_ok(d), "flags": list(d.get("flags", [])),
                       "evidence": d.get("evidence", {}), "lighting": lighting(gt_dir)})
    return {"pair": gt_dir.name, "gt": len(counted), "found": len(counted & set(hits)), "predicted": len(pits),
            "matched": len(hits), "duplicates": dup, "false": false,
            "gt_shapes": [by_id[i].get("shape", "classic") for i in sorted(counted)],
            "found_shapes": [by_id[i].get("shape", "classic") for i in sorted(counted & set(hits))],
            "bumps": sum(d["kind"] == "bump" for d in preds), "false_bumps": false_bumps, "errors": errors,
            "has_report": pred_path.is_file(), "lighting": lighting(gt_dir), "detections": detections,
            "gt_potholes": [{"id": i, "shape": by_id[i].get("shape", "classic"), "found": i in hits,
                             "ok": i in hits and is_ok(hits[i])} for i in sorted(counted)]}


def is_ok(defect: dict) -> bool:
    """A defect reported ``ok`` (defects.json ``confidence``; outputs without it: not
    ``low_confidence``)."""
    if "confidence" in defect:
        return defect["confidence"] == "ok"
    return not defect.get("low_confidence", False)


def source_fields(gt_dir: Path) -> dict:
    """The ``key: value`` lines of the pair's SOURCE.txt ({} without one)."""
    source = gt_dir / "SOURCE.txt"
    if not source.is_file():
        return {}
    return dict(ln.split(": ", 1) for ln in source.read_text().splitlines() if ": " in ln)


def lighting(gt_dir: Path) -> str:
    """The pair's lighting (SOURCE.txt ``variant``: sun, dusk, wet), "unknown" without it."""
    return source_fields(gt_dir).get("variant", "").strip() or "unknown"


def confidence_summary(rows: list) -> dict:
    """The targets of the confidence check (docs/road.md) over scored pairs: the share of
    true potholes found by an ``ok`` defect, the worst depth error of an ``ok`` match, the
    false ``ok`` defects per pair, and the median errors of all matches and of ``ok`` ones."""
    counted = [g for r in rows for g in r["gt_potholes"]]
    matches = [e for r in rows for e in r["errors"]]
    ok = [e for e in matches if e["ok"]]
    false_ok = sum(1 for r in rows for d in r["detections"] if d["status"] == "false" and d["ok"])
    dup_ok = sum(1 for r in rows for d in r["detections"] if d["status"] == "duplicate" and d["ok"])

    def med(errs, key):
        return float(np.nanmedian([e[key] for e in errs])) if errs else float("nan")
    return {"pairs": len(rows), "potholes": len(counted), "found_ok": sum(g["ok"] for g in counted),
            "found_ok_share": sum(g["ok"] for g in counted) / len(counted) if counted else float("nan"),
            "ok_matches": len(ok), "ok_over_20": sum(e["depth"] > 0.2 for e in ok),
            "worst_ok_depth": max((e["depth"] for e in ok), default=float("nan")),
            "false_ok_per_pair": false_ok / len(rows) if rows else float("nan"), "false_ok": false_ok,
            "duplicates_ok": dup_ok,
            "depth": med(matches, "depth"), "area": med(matches, "area"), "volume": med(matches, "volume"),
            "ok_depth": med(ok, "depth"), "ok_area": med(ok, "area"), "ok_volume": med(ok, "volume")}


def confidence_table(rows: list, by: str) -> list[dict]:
    """Per pothole family (``by="family"``) or lighting (``by="lighting"``), and overall: true
    potholes, found, found ``ok``, matches flagged and why, the median and worst |depth
    error| of the ``ok`` matches and their median area and volume errors."""
    def group_of(r, e):
        return e.get("shape", "classic") if by == "family" else r["lighting"]
    groups = sorted({group_of(r, g) for r in rows for g in r["gt_potholes"]}
                    | {group_of(r, e) for r in rows for e in r["errors"]})
    table = []
    for group in [*groups, "overall"]:
        def keep(r, e):
            return group == "overall" or group_of(r, e) == group
        counted = [g for r in rows for g in r["gt_potholes"] if keep(r, g)]
        matches = [e for r in rows for e in r["errors"] if keep(r, e)]
        ok = [e for e in matches if e["ok"]]
        reasons: dict = {}
        for e in matches:
            for f in e["flags"]:
                reasons[f] = reasons.get(f, 0) + 1

        def med(key, errs=ok):
            return float(np.nanmedian([e[key] for e in errs])) if errs else float("nan")
        table.append({"group": group, "gt": len(counted), "found": sum(g["found"] for g in counted),
                      "found_ok": sum(g["ok"] for g in counted), "matches": len(matches),
                      "flagged": len(matches) - len(ok), "reasons": reasons,
                      "ok_depth": med("depth"), "ok_worst": max((e["depth"] for e in ok), default=float("nan")),
                      "ok_area": med("area"), "ok_volume": med("volume")})
    return table


def family_table(rows: list) -> list[dict]:
    """Per pothole family (defects_gt.json ``shape``) and overall: ground truth, found,
    recall and the median relative errors (|depth|, signed depth, |area|, |volume|)."""
    shapes = sorted({s for r in rows for s in r.get("gt_shapes", [])})
    table = []
    for shape in [*shapes, "overall"]:
        def keep(s):
            return shape == "overall" or s == shape
        gt = sum(keep(s) for r in rows for s in r.get("gt_shapes", []))
        found = sum(keep(s) for r in rows for s in r.get("found_shapes", []))
        errs = [e for r in rows for e in r["errors"] if keep(e.get("shape", "classic"))]

        def med(key, errs=errs):
            return float(np.nanmedian([e[key] for e in errs])) if errs else float("nan")
        table.append({"family": shape, "gt": gt, "found": found, "recall": found / gt if gt else float("nan"),
                      "depth": med("depth"), "signed_depth": med("signed_depth"), "area": med("area"),
                      "volume": med("volume")})
    return table


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("gt_root", type=Path, help="folder of synth pairs (defects_gt.json, potholes_gt.png)")
    ap.add_argument("out_root", type=Path, help="output folder of `run --road-report`")
    ap.add_argument("--min-gt-depth-mm", type=float, default=20.0)
    ap.add_argument("--rule", choices=("deep", "footprint"), default="deep",
                    help="match rule: deep (half the deep part or the deepest point) or footprint (overlap shares)")
    ap.add_argument("--threshold-mm", type=float, default=10.0,
                    help="the report's depth threshold (road.min_depth_mm): a pothole's deep part is deeper")
    ap.add_argument("--min-inside", type=float, default=0.5,
                    help="footprint rule: share of a detection that must lie on the pothole it matches")
    ap.add_argument("--min-cover", type=float, default=0.3,
                    help="footprint rule: share of a pothole's visible pixels its matching detection must cover")
    ap.add_argument("--bump-margin-px", type=float, default=10.0)
    ap.add_argument("--min-decided-share", type=float, default=0.0,
                    help="what-if: ignore defects whose decided_share is below this (0: score all)")
    ap.add_argument("--confidence", action="store_true",
                    help="also print the confidence check (docs/road.md): ok defects, flags, per family and lighting")
    ap.add_argument("--json", type=Path, help="also write the per-pair scores here")
    args = ap.parse_args(argv)
    pairs = sorted(p for p in args.gt_root.iterdir() if (p / "defects_gt.json").is_file())
    if not pairs:
        print(f"Error: {args.gt_root}: no pair folder with defects_gt.json; generate it with `d3stereo synth`",
              file=sys.stderr)
        return 1
    rows = [score_pair(p, args.out_root / p.name, min_gt_depth_mm=args.min_gt_depth_mm,
                       min_inside=args.min_inside, min_cover=args.min_cover, bump_margin_px=args.bump_margin_px,
                       min_decided_share=args.min_decided_share, rule=args.rule,
                       threshold_mm=args.threshold_mm) for p in pairs]
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
        # A duplicate is no correct detection either: precision = matched / predicted.
        "precision": sum(r["matched"] for r in rows) / predicted if predicted else float("nan"),
        "false_per_pair": false / len(rows),
        "false_bumps_per_pair": false_bumps / len(rows),
        "false_defects_per_pair": (false + false_bumps) / len(rows),
        "max_false_defects_in_a_pair": max(r["false"] + r["false_bumps"] for r in rows),
        "duplicates": sum(r["duplicates"] for r in rows),
        "max_spurious_in_a_pair": max(r["false"] + r["false_bumps"] + r["duplicates"] for r in rows),
        "median_depth_error": float(np.median([e["depth"] for e in errors])) if errors else float("nan"),
        "median_area_error": float(np.nanmedian([e["area"] for e in errors])) if errors else float("nan"),
        "median_volume_error": float(np.median([e["volume"] for e in errors])) if errors else float("nan"),
    }
    print(f"recall {100 * summary['recall']:.1f} % ({found}/{gt} deeper than {args.min_gt_depth_mm:g} mm)  "
          f"precision {100 * summary['precision']:.1f} %  duplicates {summary['duplicates']}")
    print(f"false defects/pair {summary['false_defects_per_pair']:.2f} (potholes {summary['false_per_pair']:.2f}, "
          f"bumps {summary['false_bumps_per_pair']:.2f}; most in one pair: {summary['max_false_defects_in_a_pair']}; "
          f"false + duplicates, most in one pair: {summary['max_spurious_in_a_pair']})")
    print(f"median error: depth {100 * summary['median_depth_error']:.1f} %  "
          f"area {100 * summary['median_area_error']:.1f} %  volume {100 * summary['median_volume_error']:.1f} %")
    table = family_table(rows)
    print("| family | gt | found | recall | median abs depth err | median signed depth err | median abs area err "
          "| median abs volume err |\n|---|---|---|---|---|---|---|---|")
    for t in table:
        print(f"| {t['family']} | {t['gt']} | {t['found']} | {100 * t['recall']:.0f} % | {100 * t['depth']:.1f} % | "
              f"{100 * t['signed_depth']:+.1f} % | {100 * t['area']:.1f} % | {100 * t['volume']:.1f} % |")
    if args.confidence:
        print_confidence(rows)
    if args.json:
        args.json.write_text(json.dumps({"summary": summary, "families": table, "pairs": rows}, indent=2,
                                        default=float))
    return 0


def _pct(x) -> str:
    return "–" if x is None or x != x else f"{100 * x:.1f} %"


def confidence_markdown(c: dict, tables: dict, *, targets: bool) -> list[str]:
    """Markdown lines of the confidence check: the figures of its targets (``c``:
    :func:`confidence_summary`; ``targets``: with the targets of docs/road.md beside them),
    then one table per lighting and per family (``tables["lighting"]``, ``tables["family"]``:
    :func:`confidence_table`)."""
    def aim(text):
        return f" (target {text})" if targets else ""
    lines = [f"- true potholes deeper than 20 mm found by a defect reported `ok`: {c['found_ok']} of "
             f"{c['potholes']}, {_pct(c['found_ok_share'])}" + aim("at least 85 %"),
             f"- `ok` matches off by more than 20 % in depth: {c['ok_over_20']} of {c['ok_matches']} "
             f"(worst {_pct(c['worst_ok_depth'])})" + aim("none"),
             f"- false defects reported `ok`: {c['false_ok']}, {c['false_ok_per_pair']:.2f} per pair"
             + aim("at most 0.05") + f"; duplicates reported `ok`: {c['duplicates_ok']}",
             f"- medians over all matches: |depth| {_pct(c['depth'])}, area {_pct(c['area'])}, volume "
             f"{_pct(c['volume'])}" + aim("10 %, 15 %, 15 %") + f"; over the `ok` ones: {_pct(c['ok_depth'])}, "
             f"{_pct(c['ok_area'])}, {_pct(c['ok_volume'])}", ""]
    for by in ("lighting", "family"):
        lines += [f"| {by} | potholes > 20 mm | found | found `ok` | matches flagged | why (a defect can have "
                  "several) | `ok`: median abs depth err | `ok`: worst abs depth err | `ok`: median abs area err | "
                  "`ok`: median abs volume err |", "|---|---|---|---|---|---|---|---|---|---|"]
        for t in tables[by]:
            why = ", ".join(f"{k} {v}" for k, v in sorted(t["reasons"].items(), key=lambda kv: (-kv[1], kv[0]))) or "–"
            lines.append(f"| {t['group']} | {t['gt']} | {t['found']} | {t['found_ok']} | {t['flagged']} of "
                         f"{t['matches']} | {why} | {_pct(t['ok_depth'])} | {_pct(t['ok_worst'])} | "
                         f"{_pct(t['ok_area'])} | {_pct(t['ok_volume'])} |")
        lines.append("")
    return lines


def print_confidence(rows: list) -> None:
    """The confidence check as printed by ``--confidence`` (:func:`confidence_markdown` of
    the scored ``rows``, with the targets)."""
    tables = {by: confidence_table(rows, by) for by in ("lighting", "family")}
    print("\n".join(confidence_markdown(confidence_summary(rows), tables, targets=True)).rstrip())

if __name__ == "__main__":
    raise SystemExit(main())
