"""A GPU program's budget: one pair's launches and device-to-host copies, counted without a GPU.

Every launch costs the host tens of microseconds and every copy to the host waits for the
device; the CUDA backend keeps a level's work on the device (one cooperative kernel for all
diffusion sweeps, counts read together at the end, integral images in two launches).  The
count is taken under the CUDA simulator in a child process (the simulator must be on before
numba is imported) with :func:`d3cli.kernels.cuda_calls.count_cuda_calls`, as
``scripts/profile_cuda.py --cases tiny`` prints it.
"""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

from tests.kernels import simulator_children

ROOT = Path(__file__).resolve().parents[2]

_COUNT = textwrap.dedent(
    """
    import json
    import cv2
    import numpy as np
    from d3cli import D3Stereo, load_config
    from d3cli.kernels.cuda_calls import count_cuda_calls
    from d3cli.kernels.sgm import cuda as sgm_cuda

    from d3cli.kernels import cuda_launch

    # the simulator runs every thread of a block as a Python thread: small blocks and one lane
    # a line make the count about 3 minutes of one core; launches and copies do not depend on them
    sgm_cuda.LANES = 1
    cuda_launch.BLOCK_2D, cuda_launch.BLOCK_1D = (4, 4), 8

    rng = np.random.default_rng(0)
    wide = cv2.GaussianBlur(rng.uniform(0, 255, (32, 80)).astype(np.float32), (3, 3), 0.8)
    left, right = np.ascontiguousarray(wide[:, 0:64]), np.ascontiguousarray(wide[:, 5:69])  # disparity 5
    with count_cuda_calls() as calls:
        result = D3Stereo(load_config(overrides=["run.backend=cuda"])).compute(left, right, max_disparity=16)
    levels = result.levels[0]  # read after the count: the per-level maps are copied on demand
    inner = result.disparity[4:-4, 12:-4]
    print(json.dumps({"launches": calls.launches, "device_to_host": calls.device_to_host,
                      "by_kernel": dict(calls.by_kernel), "median": float(np.median(inner)),
                      "levels": len(result.levels), "level0": levels.shape[::-1],
                      "per_level": result.info["per_level"]}))
    """
)


simulator_children.register("test_a_small_pair_stays_within_60_launches_and_10_copies_to_the_host",
                            ["-c", _COUNT], {"NUMBA_ENABLE_CUDASIM": "1"})


def test_a_small_pair_stays_within_60_launches_and_10_copies_to_the_host():
    proc = simulator_children.result("test_a_small_pair_stays_within_60_launches_and_10_copies_to_the_host",
                                     timeout=1200)
    assert proc.returncode == 0, proc.stderr[-3000:]
    got = json.loads(proc.stdout.strip().splitlines()[-1])
    assert got["launches"] <= 60, got["by_kernel"]
    assert got["device_to_host"] <= 10, got
    # one launch per level for all the diffusion sweeps, two for the four integral images
    assert got["by_kernel"]["_diffuse_level"] == got["levels"]  # every level diffuses (ars)
    assert got["by_kernel"]["_row_prefixes"] == got["by_kernel"]["_column_prefixes"] == got["levels"]
    # and the answer is right: the pair's true disparity is 5
    assert abs(got["median"] - 5.0) < 0.25
    assert got["level0"] == [64, 32]
    for stats in got["per_level"]:
        assert isinstance(stats["sweeps"], int) and 0 < stats["decided_share"] <= 1
