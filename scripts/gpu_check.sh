#!/usr/bin/env bash
# Every GPU check of d3stereo in one go (about 5 minutes on a data-center GPU): GPU time is
# scarce, so one prepared run gathers all the figures the docs' GPU page reports.
#
# Usage: bash scripts/gpu_check.sh DATA [LOGDIR]
#   DATA    folder of stereo pairs (the benchmark pairs middlebury2014-adirondack-Q and
#           kitti2015-000000_10 among them; every pair in it is run as a batch)
#   LOGDIR  where the logs go (default ./gpu-check); one file per step, and summary.txt
# Environment: PYTHON (default python3); WHEELS, a folder of wheels to install first with
#   pip --no-index into /tmp/d3-site (a machine without network: e.g. a numpy that the
#   installed numba-cuda supports); CPU_WORKERS for the CPU batch (default: the core count).
#
# Steps, each under its own timeout, each logged to LOGDIR/<step>.log, none stopping the rest:
#   info       d3stereo info (the CUDA probe launches a test kernel)
#   tests      the CUDA tests on the GPU (pytest -m cuda tests/kernels, and a batch's run.json
#              device record: tests/batch/test_device_record.py)
#   profile    launches, copies and their bytes, per-kernel time, host time per step: road
#              (road.yaml) and KITTI (kitti.yaml)
#   bench-cuda scripts/bench_speed.py --backend cuda on its four cases (beside OpenCV SGBM)
#   bench-cpu  the same on the CPU of this machine
#   batch      DATA as a batch: --backend cuda pipelined (--prefetch auto: reading and writing
#              in threads beside the GPU) and serial (--prefetch 0) against --backend cpu --workers N
set -u
data=${1:?usage: bash scripts/gpu_check.sh DATA [LOGDIR]}
logs=${2:-gpu-check}
py=${PYTHON:-python3}
mkdir -p "$logs"
cd "$(dirname "$0")/.."
export PYTHONUNBUFFERED=1 PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}"
summary="$logs/summary.txt"
: >"$summary"

note() { printf '%s\n' "$*" | tee -a "$summary"; }
run() {  # run NAME SECONDS COMMAND...: log, time, and record the exit status
    local name=$1 limit=$2
    shift 2
    local t0
    t0=$(date +%s.%N)
    timeout "$limit" "$@" >"$logs/$name.log" 2>&1
    local rc=$?
    note "== $name: exit $rc in $(awk -v a="$t0" -v b="$(date +%s.%N)" 'BEGIN {printf "%.1f", b - a}') s (limit $limit s)"
    return 0
}

if [ -n "${WHEELS:-}" ] && ls "$WHEELS"/*.whl >/dev/null 2>&1; then
    $py -m pip install -q --no-index --no-deps --no-compile --target /tmp/d3-site "$WHEELS"/*.whl \
        >"$logs/wheels.log" 2>&1 && export PYTHONPATH="/tmp/d3-site:$PYTHONPATH"
    note "wheels from $WHEELS installed into /tmp/d3-site (exit $?)"
fi
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader 2>/dev/null | sed 's/^/gpu: /' | tee -a "$summary"
note "cores: $(nproc)"

run info 120 $py -m d3cli info
grep -E "^(python|numba|numpy|cuda)" "$logs/info.log" | tee -a "$summary"

# the CPU kernels compile while the CUDA tests run (both are needed later)
$py -m d3cli run --backend cpu -o /tmp/d3-warm-cpu -q >"$logs/warm-cpu.log" 2>&1 &
warm=$!
# (the launch budget counts under the simulator in child processes: the same figures on any
# machine, minutes of CPU; the profile step below counts on the GPU)
run tests 240 $py -m pytest -q -m cuda tests/kernels tests/batch/test_device_record.py -p no:cacheprovider \
    --ignore=tests/kernels/test_cuda_budget.py
tail -n 3 "$logs/tests.log" | tee -a "$summary"
wait "$warm"

run profile 200 $py scripts/profile_cuda.py --data "$data" --cases road kitti --reps 5 --json "$logs/profile.json"
grep -E "^(## |launches )" "$logs/profile.log" | tee -a "$summary"

run bench-cuda 300 $py scripts/bench_speed.py --data "$data" --backend cuda --reps 5 --no-memory \
    --json "$logs/bench-cuda.json"
run bench-cpu 300 $py scripts/bench_speed.py --data "$data" --backend cpu --reps 5 --no-memory \
    --json "$logs/bench-cpu.json"
$py - "$logs" <<'PY' | tee -a "$summary"
import json, sys
from pathlib import Path
logs = Path(sys.argv[1])
rows = {}
for backend in ("cuda", "cpu"):
    path = logs / f"bench-{backend}.json"
    if path.is_file():
        for row in json.loads(path.read_text()):
            rows.setdefault(row.get("case") or row.get("pair"), {})[backend] = row
print("case | cuda ms | cpu ms | SGBM ms | md5 equal")
for case, by in rows.items():
    cu, cp = by.get("cuda", {}), by.get("cpu", {})
    ms = lambda r, k: f"{1e3 * r[k]:.1f}" if k in r else "-"
    print(f"{case} | {ms(cu, 'd3_s')} | {ms(cp, 'd3_s')} | {ms(cp or cu, 'sgbm_s')} | "
          f"{cu.get('disparity_md5') == cp.get('disparity_md5') if cu and cp else '-'}")
PY

workers=${CPU_WORKERS:-$(nproc)}
rm -rf /tmp/d3-batch-cuda /tmp/d3-batch-cuda-serial /tmp/d3-batch-cpu
# Each batch's wall time counts its start (imports, kernels loaded from the cache warmed above).
run batch-cuda 120 $py -m d3cli run "$data" --backend cuda --eval -o /tmp/d3-batch-cuda -q
run batch-cuda-serial 120 $py -m d3cli run "$data" --backend cuda --prefetch 0 --eval -o /tmp/d3-batch-cuda-serial -q
run batch-cpu 120 $py -m d3cli run "$data" --backend cpu --workers "$workers" --eval -o /tmp/d3-batch-cpu -q
grep -E "^== batch" "$summary" | awk -v workers="$workers" '{w[$2] = $6} END {
    if (w["batch-cuda:"] > 0) printf "batch wall: cuda pipelined %s s, cuda serial %s s, cpu --workers %s %s s; " \
        "cpu / cuda pipelined = %.2f (the goal: >= 3)\n", w["batch-cuda:"], w["batch-cuda-serial:"], workers,
        w["batch-cpu:"], w["batch-cpu:"] / w["batch-cuda:"] }' | tee -a "$summary"
$py - <<'PY' | tee -a "$summary"
import json
from pathlib import Path
for out in ("/tmp/d3-batch-cuda", "/tmp/d3-batch-cuda-serial", "/tmp/d3-batch-cpu"):
    path = Path(out) / "run.json"
    if path.is_file():
        run = json.loads(path.read_text())
        print(f"{out}: {run['execution']}, compile_s {run['compile_s']}, {run['n_computed']} computed, "
              f"{run['n_failed']} failed, device {run.get('device')}")
PY
$py - <<'PY' | tee -a "$summary"
import json
from pathlib import Path
a, b = Path("/tmp/d3-batch-cuda"), Path("/tmp/d3-batch-cpu")
same = total = 0
worst = 0.0
for res in sorted(a.glob("*/result.json")):
    other = b / res.parent.name / "result.json"
    if not other.is_file():
        continue
    total += 1
    ea = (json.loads(res.read_text()).get("metrics") or {}).get("epe")
    eb = (json.loads(other.read_text()).get("metrics") or {}).get("epe")
    pa, pb = res.parent / "disp.pfm", other.parent / "disp.pfm"
    same += pa.read_bytes() == pb.read_bytes()
    if ea is not None and eb is not None:
        worst = max(worst, abs(ea - eb))
print(f"batch: {same}/{total} disparity maps byte-identical (cuda vs cpu); largest EPE difference {worst:.3g}")
PY
note "done"
