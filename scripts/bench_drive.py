"""A run's map scored against a synthetic drive's ground truth.

Reads ``OUT/defects.geojson`` and ``OUT/road_survey.json`` of a ``d3stereo run --road-report``
over a drive, and the drive's ``drive_gt.json`` (each true pothole's ``latitude``,
``longitude``, ``depth_mm``, ``area_m2`` and the ``frames`` that see it; a top-level list
or ``{"potholes": [...]}``).  The potholes on the map are matched one to one to the true
ones, nearest pairs first, within ``--radius`` metres (geodesic distance, WGS84).  Then:

* matched: true potholes found, with the median position error (m) and depth error (%);
* missed: true potholes seen by at least one frame and not matched (those no frame sees
  are counted apart);
* duplicates: unmatched potholes on the map within ``--dup-radius`` of a matched true
  pothole (the same pothole on the map twice: a merge that failed);
* false: the other unmatched potholes on the map;
* per km: potholes on the map and true potholes seen, per km of the track's length
  (``road_survey.json``'s ``length_km``).

Usage::

    PYTHONPATH=. python scripts/bench_drive.py OUT --gt DRIVE/drive_gt.json [--radius 0.3] [--json]

Without ``--gt`` the truth is ``drive_gt.json`` beside the track the run used.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path


def _truth(path: Path) -> list[dict]:
    data = json.loads(path.read_text(encoding="utf-8"))
    items = data.get("potholes", []) if isinstance(data, dict) else data
    return [dict(p, id=p.get("id", i + 1)) for i, p in enumerate(items)]


def _default_gt(out: Path) -> Path | None:
    try:
        track = json.loads((out / "track.geojson").read_text(encoding="utf-8"))["features"][0]["properties"]["source"]
    except (OSError, ValueError, KeyError, IndexError, TypeError):
        return None
    candidate = Path(track).parent / "drive_gt.json"
    return candidate if candidate.is_file() else None


def score_drive(out: str | Path, gt: str | Path, *, radius: float = 0.3, dup_radius: float = 1.0) -> dict:
    """The scores of the module docstring, as a dict."""
    from pyproj import Geod

    geod = Geod(ellps="WGS84")
    out = Path(out)
    features = json.loads((out / "defects.geojson").read_text(encoding="utf-8"))["features"]
    found = [f["properties"] for f in features if f["properties"].get("kind") == "pothole"]
    truth = _truth(Path(gt))
    seen = [t for t in truth if t.get("frames", [None])]
    unseen = len(truth) - len(seen)

    def dist(t, d):
        return geod.inv(t["longitude"], t["latitude"], d["longitude"], d["latitude"])[2]

    pairs = sorted((dist(t, d), i, j) for i, t in enumerate(truth) for j, d in enumerate(found))
    match_t, match_d = {}, {}
    for dd, i, j in pairs:
        if dd > radius:
            break
        if i not in match_t and j not in match_d:
            match_t[i], match_d[j] = (j, dd), (i, dd)
    duplicates, false = [], []
    for j, d in enumerate(found):
        if j in match_d:
            continue
        near = [(dist(truth[i], d), i) for i in match_t]
        if near and min(near)[0] <= dup_radius:
            duplicates.append(d.get("id"))
        else:
            false.append(d.get("id"))
    missed = [t for i, t in enumerate(truth) if i not in match_t and t in seen]
    pos_err = [dd for _, dd in match_t.values()]
    depth_err = [100.0 * (found[j]["depth_mm"] / truth[i]["depth_mm"] - 1.0) for i, (j, _) in match_t.items()
                 if truth[i].get("depth_mm") and found[j].get("depth_mm") is not None]
    try:
        km = float(json.loads((out / "road_survey.json").read_text(encoding="utf-8"))["length_km"])
    except (OSError, ValueError, KeyError, TypeError):
        km = 0.0
    return {"true_potholes": len(truth), "seen_by_a_frame": len(seen), "seen_by_no_frame": unseen,
            "on_the_map": len(found), "matched": len(match_t), "missed": [t["id"] for t in missed],
            "duplicates": duplicates, "false": false,
            "median_position_error_m": round(statistics.median(pos_err), 3) if pos_err else None,
            "median_abs_depth_error_pct": round(statistics.median(abs(e) for e in depth_err), 1) if depth_err else None,
            "length_km": km, "per_km": round(len(found) / km, 2) if km else None,
            "true_per_km": round(len(seen) / km, 2) if km else None, "radius_m": radius}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("out", type=Path, help="the run's output folder (defects.geojson, road_survey.json)")
    parser.add_argument("--gt", type=Path, default=None, help="drive_gt.json (default: beside the run's track)")
    parser.add_argument("--radius", type=float, default=0.3, help="match distance, metres (default 0.3)")
    parser.add_argument("--dup-radius", type=float, default=1.0,
                        help="an unmatched pothole this near a matched one is a duplicate, metres (default 1.0)")
    parser.add_argument("--json", action="store_true", help="print the scores as JSON")
    args = parser.parse_args(argv)
    gt = args.gt or _default_gt(args.out)
    if gt is None or not (args.out / "defects.geojson").is_file():
        print("Error: need OUT/defects.geojson (a --road-report run with a track) and --gt drive_gt.json",
              file=sys.stderr)
        return 1
    s = score_drive(args.out, gt, radius=args.radius, dup_radius=args.dup_radius)
    if args.json:
        print(json.dumps(s, indent=2))
        return 0
    print(f"true potholes {s['true_potholes']} ({s['seen_by_no_frame']} seen by no frame); on the map {s['on_the_map']}")
    print(f"matched within {s['radius_m']} m: {s['matched']} of {s['seen_by_a_frame']}; "
          f"missed {len(s['missed'])} {s['missed']}; duplicates {len(s['duplicates'])}; false {len(s['false'])}")
    print(f"median position error {s['median_position_error_m']} m; median |depth error| "
          f"{s['median_abs_depth_error_pct']} %")
    print(f"per km: {s['per_km']} on the map, {s['true_per_km']} true ({s['length_km']} km)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
