"""What a rerun adds to a complete pair from its files: ``cloud.ply`` and the road outputs.

Both are made from what was written (disp.pfm, valid.png), so a rerun with
``--pointcloud`` or ``road.report`` adds them to pairs computed earlier without computing
the maps again.
"""

from __future__ import annotations

import dataclasses
import logging
from pathlib import Path

from ..config import method_spec, output_groups
from ..data import formats as io, layouts as datasets
from ..road.pointcloud import camera_from, save_pair_cloud
from ..road.outputs import road_report
from .fingerprint import cloud_fingerprint
from .outputs import CLOUD_FILE, write_result
from .steps import step

log = logging.getLogger(__name__)


def _stored_map(pair, pair_dir: Path, cfg):
    """(left image, right image, camera or None, disparity, valid) of a complete pair, from its files.

    Clouds and road outputs are made from what was written (disp.pfm, valid.png), so a
    rerun adds them to pairs computed earlier without computing them again.
    """
    left, right = datasets.load_pair_images(pair)
    calib = io.read_calib(pair.calib) if pair.calib is not None else None
    camera = camera_from(calib, cfg, left.shape[:2])
    return left, right, camera, io.read_pfm(pair_dir / "disp.pfm"), io.read_mask(pair_dir / "valid.png")


def _with_warnings(pair, pair_dir: Path, stored: dict, texts, *, changed: bool = False) -> dict:
    """``stored`` with the warnings of ``texts`` it does not hold yet (logged); result.json
    rewritten when there are any or ``changed``."""
    new = [text for text in texts if text not in stored.get("warnings", [])]
    if not (new or changed):
        return stored
    for text in new:
        log.warning("%s: %s", pair.name, text)
    stored = {**stored, "warnings": [*stored.get("warnings", []), *new]}
    return write_result(pair_dir, stored)  # the sizes and hashes of the files added too


def write_extras(pair, pair_dir: Path, stored: dict, cfg, *, pointcloud: bool) -> dict:
    """``cloud.ply`` (when asked and missing or made with another camera) and the road outputs
    (``road.report``) of a complete pair, from one read of its files; returns ``stored``
    with any new warnings."""
    cloud_path = pair_dir / CLOUD_FILE
    cloud_fp = cloud_fingerprint(cfg, pair)
    cloud_done = cloud_path.is_file() and (stored.get("cloud") or {}).get("fingerprint") == cloud_fp
    want_cloud = pointcloud and not cloud_done
    if not (want_cloud or cfg.road.report):
        return stored
    with step("reading the stored map"):
        left, right, camera, disparity, valid = _stored_map(pair, pair_dir, cfg)
    warnings = []
    if want_cloud:
        cloud_path.unlink(missing_ok=True)  # made with another camera: never left beside the new settings
        stored = {**stored, "cloud": None}
    if want_cloud and camera is None:
        warnings.append("no cloud.ply: focal length or baseline unknown; add calib.txt to the pair "
                        "or set camera.f and camera.baseline")
    elif want_cloud:
        depth_range = (cfg.camera.min_depth_m, cfg.camera.max_depth_m)
        with step("the point cloud"):
            n_points = save_pair_cloud(cloud_path, disparity, valid, left, camera, depth_range=depth_range)
        log.info("%s: cloud.ply with %d points", pair.name, n_points)
        stored = {**stored, "cloud": {"fingerprint": cloud_fp, "points": n_points,
                                      "depth_range_m": list(depth_range),
                                      "camera": dataclasses.asdict(camera)}}
    if cfg.road.report:  # all the logic in d3cli.road.outputs
        with step("road report"):
            spec = method_spec(stored.get("method", ""))
            averaging = spec.averaging(cfg) if spec is not None else None
            warnings += road_report(pair_dir, left, disparity, valid, camera, stored.get("info", {}), cfg.road,
                                    right=right, groups=output_groups(cfg.run.outputs), averaging_px=averaging)[1]
    # Rewritten after the road outputs too: result.json records the files' sizes and hashes.
    return _with_warnings(pair, pair_dir, stored, warnings, changed=want_cloud or cfg.road.report)
