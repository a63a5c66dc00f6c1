"""CPU time per kernel call of d3stereo on the bench_speed cases, in one process.

Every CPU backend driver the pipeline calls (NCC, RBF weights and filter, the smoothing,
seeds, inheritance, diffusion, ...) is wrapped to add its ``time.process_time`` (all
threads) to a per-call-site total, keyed by the driver and the width of its level (so
the finest level's NCC is told from the coarse ones').  One warm-up call, then ``--reps``
calls; the medians over the calls are printed, with the total CPU time of a call and the
md5 of the disparity map (the same as bench_speed's).

``--capture DIR`` also saves the inputs of the finest level's NCC, inheritance and
diffusion calls of the last rep and of its RBF weights at the widest level that runs the
filter (the shipped configs run none at full resolution)
(``DIR/<case>_ncc.npz``, ``_rbf``, ``_inherit``, ``_diffuse``; the last two hold the volume's ``cost``, ``index``, ``n_disp`` and the
call's other arguments as ``a1``, ``a2``, ...), for kernel A/B timings of an old and a
new driver in one process.

Usage::

    PYTHONPATH=. python scripts/profile_kernels.py --data DATA --cases kitti middlebury --reps 5
"""

from __future__ import annotations

import argparse
import hashlib
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

#: The CPU backend's drivers that are timed.
DRIVERS = ("band_indexes", "ncc_cost_volume", "rbf_weights", "rbf_filter", "invalidate_out_of_view", "sgm_smooth",
           "decisive_seeds", "inherit", "diffuse", "subpixel", "min_cost", "merge_sparse", "pt_warp", "pt_restore")


def _width(args) -> int:
    """The image width of a driver call (its level), from its first array argument."""
    for a in args:
        shape = getattr(a, "shape", None) or getattr(getattr(a, "index", None), "shape", None)
        if shape is not None and len(shape) >= 2:
            return int(shape[1])
    return 0


def _wrap(backend, totals: dict, captured: dict, names=DRIVERS) -> None:
    """Replace every driver of ``names`` (default :data:`DRIVERS`) on ``backend`` by a timed one."""
    for name in names:
        if not hasattr(backend, name):
            continue

        def timed(*args, _name=name, _f=getattr(backend, name), **kw):
            if _name in ("ncc_cost_volume", "rbf_weights", "inherit", "diffuse"):
                captured.setdefault(_name, []).append((args, kw))
            t0 = time.process_time()
            out = _f(*args, **kw)
            key = f"{_name}@{_width(args)}"
            totals[key] = totals.get(key, 0.0) + time.process_time() - t0
            return out

        setattr(backend, name, timed)


def _save(captured: dict, folder: Path, case: str) -> None:
    """The finest level's NCC, inheritance and diffusion inputs of the last call and the RBF
    weights' of the widest level that has them, as .npz files."""
    import numpy as np

    args, kw = max(captured["ncc_cost_volume"], key=lambda c: c[0][0].shape[1])
    left, right, dmax, window, min_var = args
    np.savez(folder / f"{case}_ncc.npz", left=left, right=right, max_disparity=dmax, window=window,
             min_variance=min_var, index=kw.get("index") if kw.get("index") is not None else np.zeros(0))
    img_args, _ = max(captured["rbf_weights"], key=lambda c: c[0][0].shape[1])
    np.savez(folder / f"{case}_rbf.npz", image=img_args[0], sigma_space=img_args[1], sigma_color=img_args[2])
    for name in ("inherit", "diffuse"):
        if name not in captured:
            continue
        args, kw = max(captured[name], key=lambda c: _width(c[0]))
        vol = args[0]
        rest = {f"a{i}": (np.zeros(0) if a is None else np.asarray(a)) for i, a in enumerate(args[1:], 1)}
        np.savez(folder / f"{case}_{name}.npz", cost=vol.cost, index=vol.index, n_disp=vol.n_disp, **rest)


def main(argv=None) -> int:
    import bench_speed as bs
    import numpy as np

    from d3cli.batch import compute_pair
    from d3cli.kernels import cpu as backend
    from d3cli.method import pipeline

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", default=os.environ.get("D3STEREO_DATA", ""))
    parser.add_argument("--cases", nargs="+", default=list(bs.DEFAULT_CASES), choices=sorted(bs.CASES))
    parser.add_argument("--reps", type=int, default=5)
    parser.add_argument("--capture", help="folder for the finest level's kernel inputs")
    args = parser.parse_args(argv)
    totals: dict = {}
    captured: dict = {}
    _wrap(backend, totals, captured)
    _wrap(pipeline, totals, captured, ("band_indexes",))  # from the host facade, not the backend
    for case in args.cases:
        spec = dict(bs.CASES[case], case=case, data=args.data, seed=3, reps=args.reps, backend="cpu",
                    sgbm_block=5, overrides=[])
        left, right, dmax, _ = bs._load(spec)
        cfg = bs._config(spec)
        compute_pair("d3stereo", cfg, left, right, max_disparity=dmax)  # warm-up
        runs, whole = [], []
        for _ in range(args.reps):
            totals.clear()
            captured.clear()
            t0 = time.process_time()
            res = compute_pair("d3stereo", cfg, left, right, max_disparity=dmax)
            whole.append(time.process_time() - t0)
            runs.append(dict(totals))
        md5 = hashlib.md5(np.ascontiguousarray(res.disparity, dtype=np.float32).tobytes()).hexdigest()
        print(f"{case}: CPU {1e3 * statistics.median(whole):.0f} ms per call (median of {args.reps}), md5 {md5}")
        for key in sorted(runs[0], key=lambda k: -statistics.median(r.get(k, 0.0) for r in runs)):
            print(f"  {key:28s} {1e3 * statistics.median(r.get(key, 0.0) for r in runs):8.1f} ms")
        if args.capture:
            Path(args.capture).mkdir(parents=True, exist_ok=True)
            _save(captured, Path(args.capture), case)
    return 0


if __name__ == "__main__":
    sys.exit(main())
