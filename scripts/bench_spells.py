"""d3stereo against OpenCV SGBM in the machine's fast and slow spells (a shared host).

On a shared host (a 2-vCPU virtual machine, say) the same kernel call can take about
twice as long for seconds at a time, then run at full speed again: the host's spells,
not the code.  SGBM and d3stereo slow down by different amounts in a slow spell, so the
ratio that ``scripts/bench_speed.py`` reports depends on which spells its reps fall
in.  This script tells them apart: it repeats, for ``--seconds``, a probe (the finest
level's inheritance call of the case, captured from one d3stereo call; a fixed input, so
its time is the machine's speed), then SGBM, then d3stereo; a rep whose probe took less
than ``--fast`` times the quickest probe counts as fast.  It prints, per spell, the reps,
the medians of the probe, SGBM and d3stereo, and the median of the reps' own ratios.

Usage::

    PYTHONPATH=. python scripts/bench_spells.py --cases road --seconds 40
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))


def _capture_probe(backend, run):
    """The arguments of the widest ``inherit`` call ``run()`` makes (the finest level's)."""
    calls = []
    original = backend.inherit

    def capture(*args, **kw):
        calls.append((args, kw))
        return original(*args, **kw)

    backend.inherit = capture
    try:
        run()
    finally:
        backend.inherit = original
    if not calls:
        return None
    args, kw = max(calls, key=lambda c: c[0][0].index.shape[1])
    return lambda: original(*args, **kw)


def main(argv=None) -> int:
    import bench_speed as bs

    from d3cli.batch import compute_pair
    from d3cli.kernels import cpu as backend

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", default=os.environ.get("D3STEREO_DATA", ""))
    parser.add_argument("--cases", nargs="+", default=["road"], choices=sorted(bs.CASES))
    parser.add_argument("--seconds", type=float, default=40.0, help="how long to repeat the three calls per case")
    parser.add_argument("--fast", type=float, default=1.4, help="a rep is fast when its probe took < FAST x the quickest")
    args = parser.parse_args(argv)
    for case in args.cases:
        # bench_speed's defaults: the road pairs of seed 3, SGBM with block 5
        spec = bs.case_spec(case, args.data, seed=3, backend="cpu", sgbm_block=5, overrides=[])
        if spec is None:
            continue
        left, right, dmax, _ = bs._load(spec)
        cfg = bs._config(spec)

        def d3():
            return compute_pair("d3stereo", cfg, left, right, max_disparity=dmax)

        def sgbm():
            return compute_pair("sgbm", cfg, left, right, max_disparity=dmax)

        d3()  # warm-up (kernels loaded)
        probe = _capture_probe(backend, d3)
        if probe is None:
            print(f"{case}: no inheritance call to probe with, skipped", file=sys.stderr)
            continue
        sgbm()
        reps = []
        stop = time.perf_counter() + args.seconds
        while time.perf_counter() < stop:
            times = []
            for call in (probe, sgbm, d3):
                t0 = time.perf_counter()
                call()
                times.append(time.perf_counter() - t0)
            reps.append(times)
        quickest = min(r[0] for r in reps)
        print(f"{case}: {len(reps)} reps in {args.seconds:.0f} s, quickest probe {1e3 * quickest:.1f} ms")
        for name, fast in (("fast", True), ("slow", False)):
            spell = [r for r in reps if (r[0] < args.fast * quickest) == fast]
            if not spell:
                print(f"  {name}: no reps")
                continue
            med = [statistics.median(r[k] for r in spell) for k in range(3)]
            ratio = statistics.median(r[2] / r[1] for r in spell)
            print(f"  {name}: {len(spell)} reps, probe {1e3 * med[0]:.1f} ms, SGBM {1e3 * med[1]:.1f} ms, "
                  f"d3stereo {1e3 * med[2]:.1f} ms, d3stereo / SGBM {ratio:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
