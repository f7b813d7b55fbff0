#!/usr/bin/env bash
# Runs every fuzz target for a set time (default 60 s each; SECONDS_PER_TARGET=N, or name targets as
# arguments) and copies any input that crashed a target into fuzz/regressions/<target>/, where
# tests/fuzz_regressions.rs replays it in the ordinary test suite. Needs cargo-fuzz (`cargo install
# cargo-fuzz`); on a stable toolchain RUSTC_BOOTSTRAP=1 (set here) lets it use the nightly-only sanitizer flags,
# so no nightly toolchain is needed. One target at a time, e.g. niced on a shared machine:
#   SECONDS_PER_TARGET=900 nice -n 19 fuzz/run.sh run_dir
# Prints one line per target: its time, its executions, the coverage libFuzzer reached (edges, features) and
# what it found.
set -euo pipefail
cd "$(dirname "$0")"
seconds="${SECONDS_PER_TARGET:-60}"
targets=("$@")
[ "${#targets[@]}" -gt 0 ] || targets=(config demos checkpoint trace run_dir packed snapshot web)
export RUSTC_BOOTSTRAP=1
cargo fuzz build -O
# The snapshot target's seed is a snapshot of this arld (a snapshot records the version that wrote it, so none
# is committed): a run of the harness's configuration, killed after its first snapshot.
if [[ " ${targets[*]} " == *" snapshot "* ]]; then
  (cd .. && cargo build --release --bin arld)
  run=$(mktemp -d)
  sets=$(sed -n '/SNAPSHOT_SEED_CONFIG/,/];/p' harness.rs | grep -o '"[a-z_]*=[0-9]*"' | tr -d '"' |
    sed 's/^/--set /' | tr '\n' ' ')
  # shellcheck disable=SC2086
  ../target/release/arld train --quiet --env CartPole-v0 --method dqn --net bootstrap --seed 0 $sets \
    -o "$run/run" &
  pid=$!
  while [ ! -e "$run/run/snapshot.json" ]; do
    kill -0 "$pid" 2>/dev/null || { echo "error: the seed run ended before its first snapshot" >&2; exit 1; }
    sleep 0.05
  done
  kill -KILL "$pid"
  wait "$pid" || true
  mkdir -p seeds/snapshot
  cp "$run/run/snapshot.safetensors" seeds/snapshot/run.safetensors
  rm -rf "$run"
fi
status=0
for t in "${targets[@]}"; do
  corpus="corpus/$t"
  mkdir -p "$corpus" "artifacts/$t" "regressions/$t"
  log="artifacts/$t/last-run.log"
  # The committed seeds start the corpus; the corpus itself stays local (git-ignored).
  set +e
  cargo fuzz run -O "$t" "$corpus" "seeds/$t" -- -max_total_time="$seconds" -rss_limit_mb=2048 \
    -malloc_limit_mb=2048 -timeout=20 -print_final_stats=1 >"$log" 2>&1
  code=$?
  set -e
  execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' | tail -1)
  cov=$(grep -o 'cov: [0-9]* ft: [0-9]*' "$log" | tail -1)
  found=0
  for crash in artifacts/"$t"/crash-* artifacts/"$t"/oom-* artifacts/"$t"/timeout-* artifacts/"$t"/leak-*; do
    [ -e "$crash" ] || continue
    cp "$crash" "regressions/$t/"
    found=$((found + 1))
  done
  echo "$t: ${seconds} s, ${execs:-?} executions, ${cov:-cov: ?}, exit $code, $found crashing inputs (in regressions/$t)"
  [ "$code" -eq 0 ] || status=1
done
exit "$status"
