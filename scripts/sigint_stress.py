"""Send SIGINT to ``d3stereo run`` at random moments and count how each process ended.

Usage::

    python scripts/sigint_stress.py PAIRS_DIR --make 6 --trials 60 --from 0.15 --to 8 --seed 2

Each trial starts ``python -m d3cli run PAIRS_DIR -o TMP --method d3stereo -q
--max-disparity 16`` (niced), sends SIGINT after a uniform random delay in [FROM, TO]
seconds, and records the exit status (130 = handled, 0 = the batch had finished, -2 =
killed by the signal), whether stderr holds a traceback, and its last line.  Prints one
line per trial and a tally.  Meant for a folder of a few small pairs (e.g. six 96x160
pairs: about 8 s per uninterrupted run on a loaded 2-core machine); ``--make N`` first
writes N such pairs (smoothed random texture, constant shift 3 + i, as
tests/batch/test_interrupts.py uses) into PAIRS_DIR.
"""

from __future__ import annotations

import argparse
import collections
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def make_pairs(root: Path, n: int, size=(96, 160)) -> None:
    """``root/p<i>/{left,right}.png``: smoothed random texture, right = left shifted by 3 + i px."""
    import cv2
    import numpy as np

    height, width = size
    for i in range(n):
        shift = 3 + i
        rng = np.random.default_rng(i)
        noise = rng.uniform(0, 255, size=(height, width + shift)).astype(np.float32)
        texture = np.clip(np.rint(cv2.GaussianBlur(noise, (0, 0), 0.8)), 0, 255).astype(np.uint8)
        folder = root / f"p{i}"
        folder.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(folder / "left.png"), np.ascontiguousarray(texture[:, :width]))
        cv2.imwrite(str(folder / "right.png"), np.ascontiguousarray(texture[:, shift:shift + width]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("pairs", type=Path)
    parser.add_argument("--trials", type=int, default=60)
    parser.add_argument("--from", dest="lo", type=float, default=0.15, help="earliest signal, seconds after start")
    parser.add_argument("--to", dest="hi", type=float, default=8.0, help="latest signal, seconds after start")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--method", default="d3stereo")
    parser.add_argument("--make", type=int, default=0, metavar="N", help="first write N small pairs into PAIRS")
    args = parser.parse_args()
    if args.make:
        make_pairs(args.pairs, args.make)
    # A background shell starts jobs with SIGINT ignored; the children must not inherit that.
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    rng = random.Random(args.seed)
    tally = collections.Counter()
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.trials):
            out = Path(tmp) / f"out{k}"
            cmd = ["nice", "-n", "10", sys.executable, "-m", "d3cli", "run", str(args.pairs), "-o", str(out),
                   "--method", args.method, "-q", "--max-disparity", "16"]
            proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                    env=dict(os.environ))
            delay = rng.uniform(args.lo, args.hi)
            time.sleep(delay)
            proc.send_signal(signal.SIGINT)
            _, stderr = proc.communicate()
            traceback = "Traceback" in stderr
            last = stderr.strip().splitlines()[-1] if stderr.strip() else ""
            tally[(proc.returncode, traceback)] += 1
            print(f"{k:3d} t={delay:6.3f} s  exit {proc.returncode:4d}  traceback={traceback!s:5}  {last[:90]}",
                  flush=True)
            shutil.rmtree(out, ignore_errors=True)
    print("tally (exit status, traceback): count")
    for (code, traceback), count in sorted(tally.items()):
        print(f"  ({code}, {traceback}): {count}")


if __name__ == "__main__":
    main()
