"""A GPU program's budget: one pair's launches, copies and bytes, counted without a GPU.

Every launch costs the host tens of microseconds and every copy to the host waits for the
device; the CUDA backend takes the two images in (uint8, uploaded once), builds the pyramid
and the band indexes on the device, keeps every level there (one cooperative kernel for
all diffusion sweeps, counts read together at the end) and sends back the sub-pixel map,
the decided pixels and the counts packed in one buffer (one copy).  The count is taken
under the CUDA simulator in child processes (the simulator must be on before numba is
imported) with :func:`d3cli.kernels.cuda_calls.count_cuda_calls`, for the bundled configs
on a 64x32 uint8 pair (``scripts/profile_cuda.py --cases tiny`` prints the same figures)
and, marked ``slow``, for the road config on a 160x96 synthetic road, while every CPU
kernel of the matching steps raises, and so do those of the occlusion check, of the
speckle filter, of the filling (row-wise and inside surfaces) and of the smoothing where
the config runs them: the CUDA run computes on the device only (the road fit runs on the
host by design, on the coarsest level's small map, ``docs/gpu.md``).
"""

from __future__ import annotations

import json
import textwrap

import pytest

from tests.kernels import simulator_children

pytestmark = pytest.mark.cuda

H, W = 32, 64

_COUNT = textwrap.dedent(
    """
    import json
    import sys
    import time
    import cv2
    import numpy as np
    import numba
    from d3cli import D3Stereo, load_config
    from d3cli.kernels import cuda_launch, host
    from d3cli.kernels.cuda_calls import count_cuda_calls
    from d3cli.kernels.sgm import cuda as sgm_cuda
    import d3cli.kernels.cpu as cpu_backend
    from d3cli.kernels.aggregation import cpu as a1, cpu_rows as a2, cpu_vector as a3
    from d3cli.kernels.cost import band as c1, cpu as c2
    from d3cli.kernels.decisive import cpu_diffusion as d1, cpu_inheritance as d2, cpu_seeds as d3
    from d3cli.kernels.perspective import cpu as p1
    from d3cli.kernels.pyramid import cpu as y1, halve as y2
    from d3cli.kernels.sgm import cpu as s1
    from d3cli.kernels.subpixel import cpu as u1
    from d3cli.kernels import cpu_common
    from d3cli.kernels.finishing import fill as f1, occlusion as f2, speckle as f3, range_box as f4, smoothing as f5
    from d3cli.method import pyramid as method_pyramid

    # the simulator runs every thread of a block as a Python thread: small blocks and one lane
    # a line; launches, copies and bytes do not depend on them
    sgm_cuda.LANES = 1
    cuda_launch.BLOCK_2D, cuda_launch.BLOCK_1D = (4, 4), 8

    def forbidden(name):
        def raiser(*a, **k):
            raise AssertionError(f"CPU kernel {name} called during a CUDA compute")
        return raiser

    # every CPU kernel of the matching steps raises: the backend's functions, the compiled
    # kernels of the steps' CPU modules, and the host facade's pyramid, band and warp
    for name in cpu_backend.__all__:
        if name not in ("to_device", "to_host", "counts_to_host"):
            setattr(cpu_backend, name, forbidden(name))
    for module in (a1, a2, a3, c1, c2, d1, d2, d3, p1, y1, y2, s1, u1, cpu_common):
        for name, value in list(vars(module).items()):
            if isinstance(value, numba.core.registry.CPUDispatcher) or name in (
                    "band_indexes", "halve_area", "pyramid", "pt_warp", "pt_restore"):
                setattr(module, name, forbidden(f"{module.__name__}.{name}"))
    for name in ("band_indexes", "halve_area", "pt_warp", "pt_restore"):
        setattr(host, name, forbidden(f"host.{name}"))
    method_pyramid.halve_area = forbidden("method.pyramid.halve_area")

    # the finishing's steps that run on the device (D3Stereo._finish_on_backend): their CPU
    # kernels raise during a compute whose settings run them there
    OCCLUSION = {f2: ("_uniqueness_task", "_out_of_view_task", "_drop_occluded_task"),
                 host: ("uniqueness_occluded", "out_of_view_mask", "drop_occluded")}
    FILL = {f1: ("_usable_task", "_fill_rows_task", "copy_nearest_rows", "_keep_valid_task", "_median_holes_task",
                 "_nearest_columns_task", "_fill_inside_task"),
            host: ("usable", "fill_rows_smaller_side", "copy_nearest_rows", "keep_valid", "nearest_along_columns",
                   "fill_inside")}
    SPECKLES = {f3: ("_fixed_task", "_fixed_finite_task", "_drop_marked_task", "filter_speckles"),
                host: ("fixed_point_16", "fixed_point_16_finite", "drop_marked"), cv2: ("filterSpeckles",)}
    SMOOTH = {f4: ("_masked_task", "_residual_task", "_smooth_task"),
              f5: ("_residual_task", "_range_levels_task", "_smooth_group_task", "_combine_task", "_plane_task",
                   "_clamp_task"),
              host: ("box_smooth_disparity", "gaussian_smooth", "unsmoothed", "shift_plane_f32", "residual_and_range",
                     "range_levels", "smooth_groups", "combine_shares", "clamp_negative")}

    def forbid(table):
        saved = []
        for module, names in table.items():
            for name in names:
                saved.append((module, name, getattr(module, name)))
                setattr(module, name, forbidden(f"{module.__name__}.{name}"))
        return saved

    rng = np.random.default_rng(0)
    wide = cv2.GaussianBlur(rng.uniform(0, 255, (32, 80)).astype(np.float32), (3, 3), 0.8)
    wide = np.round(wide).astype(np.uint8)
    textured = np.ascontiguousarray(wide[:, 0:64]), np.ascontiguousarray(wide[:, 5:69])  # disparity 5
    # the road config on a synthetic road (a flat road seen from above: the road model holds);
    # --road-size=WxH: a larger one alone, its range the one its dataset folder names (as
    # `d3stereo run -c road` reads it)
    from d3cli.data.synth import render_pair
    configs = sys.argv[1:]
    w, h, dmax = 64, 32, 16
    if configs[0].startswith("--road-size="):
        w, h = (int(x) for x in configs.pop(0).split("=")[1].split("x"))
    settings = [arg.split("=", 1)[1] for arg in configs if arg.startswith("--set=")]  # config overrides
    configs = [arg for arg in configs if not arg.startswith("--set=")]
    synth = render_pair(seed=1, width=w, height=h, variant="sun", flat=True, noise=False, supersample=1)
    if (w, h) != (64, 32):
        dmax = synth.calib["ndisp"]
    for config in configs:
        left, right = (synth.left, synth.right) if config == "road" else textured
        stereo = D3Stereo(load_config(config, overrides=["run.backend=cuda", *settings]))
        refine = stereo.cfg.refine
        on_device = {"occlusion": refine.occlusion_check, "fill": refine.fill,
                     "speckles": refine.speckle_size > 0,
                     "fill_inside": refine.fill and refine.fill_inside and refine.occlusion_check,
                     "smooth": refine.smooth_radius > 0}
        saved = ((forbid(OCCLUSION) if on_device["occlusion"] else []) + (forbid(FILL) if on_device["fill"] else [])
                 + (forbid(SPECKLES) if on_device["speckles"] else []) + (forbid(SMOOTH) if on_device["smooth"] else []))
        t0 = time.perf_counter()
        with count_cuda_calls() as calls:
            result = stereo.compute(left, right, max_disparity=dmax)
        seconds = time.perf_counter() - t0
        for module, name, value in saved:
            setattr(module, name, value)
        inner = result.disparity[4:-4, 12:-4]
        print(json.dumps({"config": config, "launches": calls.launches, "d2h": calls.device_to_host,
                          "h2d": calls.host_to_device, "h2d_bytes": calls.host_to_device_bytes,
                          "d2h_bytes": calls.device_to_host_bytes, "by_kernel": dict(calls.by_kernel),
                          "sites": {f"{k[0]} {k[1]}": v for k, v in calls.by_site.items()},
                          "median": float(np.median(inner)), "levels": len(result.levels),
                          "valid_share": float(result.valid.mean()), "pt": result.info.get("pt"),
                          "level0": list(result.levels[0].shape[::-1]), "per_level": result.info["per_level"],
                          "on_device": on_device, "seconds": round(seconds, 1)}),
              flush=True)
    """
)

#: child test name -> configs it counts (two children: they run beside each other)
GROUPS = {"test_budget_of_the_default_and_paper_configs": ["default", "paper"],
          "test_budget_of_the_kitti_and_road_configs": ["kitti", "road"]}
for _name, _configs in GROUPS.items():
    simulator_children.register(_name, ["-c", _COUNT, *_configs], {"NUMBA_ENABLE_CUDASIM": "1"})
#: the road config on a 160x96 synthetic road, three levels: minutes under the simulator.
#: At the config's four levels the coarsest map (20x12, disparities 1-2 at scale 8) gives
#: no plane that grows towards the image bottom, and the pair falls back to default.yaml
#: (on the CPU as well); with three levels (40x24) the road model holds.
LARGE_ROAD = (160, 96)
simulator_children.register("test_budget_of_the_road_config_at_160x96",
                            ["-c", _COUNT, "--road-size={}x{}".format(*LARGE_ROAD), "--set=pyramid.levels=3", "road"],
                            {"NUMBA_ENABLE_CUDASIM": "1"})


def outputs(h: int, w: int) -> int:
    """Bytes of the requested outputs of an (h, w) pair: float32 disparity, bool validity,
    one pool of counts (64 int64 slots)."""
    return 4 * h * w + h * w + 64 * 8


#: config -> (launches, device-to-host copies) asserted (the road config's on both of its
#: pairs: with three levels the launches do not depend on the image size); the
#: device-to-host bytes: the outputs + 4 KB.  The road config (a synthetic road pair) also
#: downloads its coarsest map for the road fit (int8) and reads the counts of its narrow
#: match before the finishing (the road check): two more copies.
BUDGET = {"default": (80, 1), "paper": (80, 1), "kitti": (80, 1), "road": (100, 3)}


def d2h_budget(row: dict) -> int:
    """Device-to-host bytes allowed for ``row``'s pair."""
    w, h = row["level0"]
    allowed = outputs(h, w) + 4096
    if row["config"] == "road":  # the int8 coarse map and the narrow match's pool of counts
        k = row["levels"] - 1
        allowed += (h >> k) * (w >> k) + 64 * 8
    return allowed


def _rows(test_name: str, timeout: float = 1800) -> dict:
    proc = simulator_children.result(test_name, timeout=timeout)
    assert proc.returncode == 0, proc.stderr[-3000:]
    rows = [json.loads(line) for line in proc.stdout.strip().splitlines() if line.startswith("{")]
    for row in rows:
        print(f"{row['config']} {row['level0'][0]}x{row['level0'][1]} (finishing on the device: {row['on_device']}): "
              f"{row['launches']} launches, {row['d2h']} device-to-host copies ({row['d2h_bytes']} bytes), "
              f"{row['h2d']} host-to-device copies ({row['h2d_bytes']} bytes); {row['seconds']} s")
    return {row["config"]: row for row in rows}


def _check(row: dict, size=(W, H)) -> None:
    w, h = size
    launches, copies = BUDGET[row["config"]]
    assert row["h2d_bytes"] <= 2 * h * w + 16 * 1024, row["sites"]  # the two uint8 images, little else
    assert row["d2h_bytes"] <= d2h_budget(row), row["sites"]
    assert row["d2h"] <= copies, row["sites"]
    assert row["launches"] <= launches, row["by_kernel"]
    # one launch per level for all the diffusion sweeps (and the road's coarse pass), two for
    # the four integral images
    assert row["by_kernel"]["_diffuse_level"] <= row["levels"] + (row["config"] == "road")
    assert row["by_kernel"]["_row_prefixes"] == row["by_kernel"]["_column_prefixes"]
    assert row["level0"] == [w, h]
    # the map, the validity and the counts packed into one buffer: one launch
    assert row["by_kernel"]["_pack_kernel"] == 1
    # (occlusion check, filling, speckle filter, filling inside surfaces, smoothing)
    expected = {"default": (True, True, False, False, True), "paper": (False, True, False, False, False),
                "road": (True, True, False, False, True), "kitti": (True, True, True, True, True)}
    on_device = row["on_device"]
    assert (on_device["occlusion"], on_device["fill"], on_device["speckles"], on_device["fill_inside"],
            on_device["smooth"]) == expected[row["config"]]
    if on_device["occlusion"]:
        assert row["by_kernel"]["_drop_occluded_kernel"] == 1
    if on_device["speckles"]:  # the union-find: four launches whatever the map
        for kernel in ("_speckle_init_kernel", "_speckle_merge_kernel", "_speckle_size_kernel",
                       "_drop_speckles_kernel"):
            assert row["by_kernel"][kernel] == 1, kernel
    if on_device["fill_inside"]:
        for kernel in ("_nearest_columns_kernel", "_fill_inside_kernel", "_copy_inside_rows_kernel"):
            assert row["by_kernel"][kernel] == 1, kernel
        assert "_fill_rows_kernel" not in row["by_kernel"]
    elif on_device["fill"]:
        assert row["by_kernel"]["_fill_rows_kernel"] == row["by_kernel"]["_copy_rows_kernel"] == 1
    if on_device["fill"]:
        assert row["by_kernel"]["_median_holes_kernel"] == 1
    smooth_launches = {k: v for k, v in row["by_kernel"].items() if k.startswith("_smooth_")}
    if row["config"] in ("default", "kitti"):  # the box range kernel: the residual, the sums
        assert smooth_launches == {"_smooth_box_residual_kernel": 1, "_smooth_box_kernel": 1}
    elif row["config"] == "road":  # the Gaussian: residual, range, levels, one pair for every level, the blend
        assert smooth_launches == {"_smooth_residual_kernel": 1, "_smooth_range_kernel": 1,
                                   "_smooth_levels_kernel": 1, "_smooth_row_sums_kernel": 1,
                                   "_smooth_column_kernel": 1, "_smooth_combine_kernel": 1}
    else:
        assert smooth_launches == {}
    if row["config"] == "road":  # the road model held: the narrow match, restored on the device
        assert row["pt"]["road_like"] and not row["pt"].get("fallback") and row["valid_share"] > 0.5
    elif row["config"] == "paper":  # seeds at the coarsest level only: none on this small pair (so on the CPU)
        assert row["valid_share"] == 0.0
    else:  # and the answer is right: the pair's true disparity is 5
        assert abs(row["median"] - 5.0) < 0.25
    for stats in row["per_level"]:
        assert isinstance(stats["sweeps"], int) and 0 <= stats["decided_share"] <= 1
        assert stats["decided_share"] > 0 or row["config"] == "paper"


def test_budget_of_the_default_and_paper_configs():
    rows = _rows("test_budget_of_the_default_and_paper_configs")
    assert sorted(rows) == ["default", "paper"]
    for row in rows.values():
        _check(row)
    # the default pair: the images in, the maps and the counts out
    assert rows["default"]["h2d"] == 2 and rows["default"]["h2d_bytes"] == 2 * H * W
    assert rows["default"]["by_kernel"]["_diffuse_level"] == rows["default"]["levels"]  # every level (ars)


def test_budget_of_the_kitti_and_road_configs():
    rows = _rows("test_budget_of_the_kitti_and_road_configs")
    assert sorted(rows) == ["kitti", "road"]
    for row in rows.values():
        _check(row)


@pytest.mark.slow
def test_budget_of_the_road_config_at_160x96():
    """The road config on a 160x96 synthetic road (``render_pair(seed=1, width=160,
    height=96, variant="sun", flat=True, noise=False, supersample=1)``, its range 23 as its
    dataset folder names it, three levels: :data:`LARGE_ROAD`): the same launch and copy
    budgets as the 64x32 pair, the byte budgets scaled to the image.  One compute takes
    6.5-8 minutes under the simulator, so the test is marked ``slow`` and left out of the
    suite's simulator child
    (``tests/kernels/test_cuda_simulator.py`` runs ``-m "cuda and not slow"``); run it with
    ``NUMBA_ENABLE_CUDASIM=1 python -m pytest -q -s -m "cuda and slow" tests/kernels/test_cuda_budget.py``."""
    rows = _rows("test_budget_of_the_road_config_at_160x96", timeout=5400)
    assert sorted(rows) == ["road"]
    _check(rows["road"], size=LARGE_ROAD)
    assert rows["road"]["levels"] == 3 and rows["road"]["h2d"] == 2
