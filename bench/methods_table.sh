#!/usr/bin/env bash
# Times the paper's methods table (12 methods x 4 tasks x 20 seeds = 960 runs) on a fixed slice and extrapolates
# the whole table's wall time on two cores.
#
# Usage: bench/methods_table.sh [SEEDS] [FRACTION]
#        bench/methods_table.sh committed
#   SEEDS     seeds of every method on every task in the slice (default 2: 96 runs)
#   FRACTION  share of each task's training steps to run (default 1; e.g. 0.1 for a quick estimate, which
#             extrapolates the per-step cost linearly and so ignores how episode lengths change over training)
# The slice runs two at a time (`arld sweep --jobs 2`); the estimate is the summed per-run CPU time
# (summary.json's cpu_time_s) scaled to 960 full runs and divided by two cores. Writes bench/out/methods_table.json.
# `committed` runs nothing: it sums the CPU time of the methods-table runs under results/runs that this arld's
# numerics computed (summary.json's "numerics"), and extrapolates the tasks' means to all 960 runs.
set -euo pipefail
cd "$(dirname "$0")/.."

if [ "${1:-}" = committed ]; then
  python3 - <<'PY'
import json, pathlib
per_task = {}
for summary in sorted(pathlib.Path("results/runs").glob("*/*/seed*/summary.json")):
    s = json.loads(summary.read_text())
    if s.get("numerics") != "correctly-rounded" or s.get("cpu_time_s") is None:
        continue
    per_task.setdefault(s["env"], []).append(s["cpu_time_s"])
if not per_task:
    raise SystemExit("no methods-table run of this arld's numerics under results/runs yet")
total = 0.0
for env, times in sorted(per_task.items()):
    mean = sum(times) / len(times)
    total += mean * 240
    print(f"{env:16s} {len(times):3d}/240 runs, mean {mean:6.1f} CPU s, sum {sum(times) / 3600:5.2f} h")
print(f"whole table (960 runs) at these means: {total / 3600:.2f} core-hours = {total / 7200:.2f} h on two cores"
      + ("" if len(per_task) == 4 else f" (only {len(per_task)} of 4 tasks so far)"))
PY
  exit 0
fi
seeds="${1:-2}"
fraction="${2:-1}"
out=bench/out/methods_table
mkdir -p "$out"
cargo build --release --quiet

declare -A full_steps=([CartPole-v0]=20000 [Acrobot-v1]=200000 [MountainCar-v0]=500000 [LunarLander-v2]=500000)
start=$(date +%s)
for env in CartPole-v0 Acrobot-v1 MountainCar-v0 LunarLander-v2; do
  steps=$(python3 -c "print(max(1, round(${full_steps[$env]} * $fraction)))")
  echo "== $env: 12 methods x $seeds seeds, $steps steps each"
  ./target/release/arld sweep --env "$env" --method dqn,dqfd,gdqn,bdqn,adqn,adqnp --net bootstrap,noisy \
    --seeds "$seeds" --jobs 2 --set train_steps="$steps" -o "$out/$env" >/dev/null
done
elapsed=$(( $(date +%s) - start ))

python3 - "$out" "$seeds" "$fraction" "$elapsed" <<'PY'
import json, os, pathlib, sys
out, seeds, fraction, elapsed = pathlib.Path(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3]), int(sys.argv[4])
per_task = {}
for summary in out.glob("*/**/summary.json"):
    s = json.loads(summary.read_text())
    # CPU seconds of the training thread where the summary has them (a busy machine does not inflate them),
    # else wall-clock seconds.
    per_task.setdefault(s["env"], []).append(s.get("cpu_time_s", s["wall_time_s"]))
runs = sum(len(v) for v in per_task.values())
core_s = sum(sum(v) for v in per_task.values())
# Every task has 12 methods x 20 seeds in the table; the slice has 12 x seeds of each.
table_core_s = sum(sum(v) / len(v) * 240 for v in per_task.values()) / fraction
load = os.getloadavg()[0]
result = {
    "slice_runs": runs, "seeds": seeds, "fraction": fraction, "slice_wall_s": elapsed,
    "slice_core_s": core_s, "per_task_mean_run_s": {k: sum(v) / len(v) / fraction for k, v in per_task.items()},
    "table_core_hours": table_core_s / 3600, "table_wall_hours_two_cores": table_core_s / 2 / 3600,
    "load_average": load,
}
for env, mean in sorted(result["per_task_mean_run_s"].items()):
    print(f"{env:16s} mean run {mean:8.1f} s")
print(f"slice: {runs} runs, {core_s:.0f} core-s, {elapsed} s wall; whole table (960 runs): "
      f"{result['table_core_hours']:.2f} core-hours = {result['table_wall_hours_two_cores']:.2f} h on two cores "
      f"(load average {load:.2f})")
json.dump(result, open(out.parent / "methods_table.json", "w"), indent=2)
PY
