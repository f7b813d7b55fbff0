#!/usr/bin/env bash
# arld against Stable-Baselines3 DQN, side by side in one run, on SB3's DQN configuration:
# CartPole-v1, a 64-64 network, batch 32, one gradient update per environment step, uniform replay, and SB3's
# TD target (the target network's maximum: arld's `double_q = false`; SB3's DQN has no double-DQN option), Huber
# loss, learning rate 1e-4, gamma 0.99 and epsilon from 1 to 0.05 over the first 10% (SB3's defaults).
# Both are single-threaded (torch.set_num_threads(1); one arld run uses one core) and train the same number of
# steps with no evaluation in between. Prints both speeds and their ratio, by wall clock and by CPU time (the
# steadier figure on a loaded machine), and writes bench/out/sb3_cartpole.json.
#
# Usage: [VENV=DIR] [ARLD=PATH TAG=NAME] bench/sb3_cartpole.sh [STEPS]      (default 20000; SB3 needs about 30 s per 20k steps on one core)
# SB3 runs in the virtual environment VENV if given (it must already have torch, gymnasium and stable-baselines3,
# e.g. the checkout's .venv made by .ci/run); otherwise the checkout's .venv if it has them; otherwise SB3 (with
# torch and Gymnasium) is installed into bench/.venv on the first run.
set -euo pipefail
cd "$(dirname "$0")/.."
steps="${1:-20000}"
out=bench/out
mkdir -p "$out"

source bench/sb3_venv.sh

# ARLD=PATH measures another build of arld (an earlier commit's, for a before-and-after), named TAG in the output.
arld="${ARLD:-./target/release/arld}"
[ -n "${ARLD:-}" ] || cargo build --release --quiet
tag="${TAG:+_$TAG}"
echo "== arld: CartPole-v1, dqn, plain 64-64, batch 32, train_freq 1, uniform replay, $steps steps (median of 3 runs)"
# The run's own steps/s (wall clock) and CPU seconds of its training thread (summary.json), median of three runs:
# on this class of shared virtual machine one run can be a third slower than the next.
read -r arld_sps arld_cpu < <(ARLD_BIN="$arld" python3 - "$steps" "$out/arld_cartpole" <<'PY'
import json, os, shutil, statistics, subprocess, sys
arld = os.environ["ARLD_BIN"]
steps, out = sys.argv[1], sys.argv[2]
rates, cpus = [], []
for _ in range(3):
    shutil.rmtree(out, ignore_errors=True)
    subprocess.run([arld, "train", "--env", "CartPole-v1", "--method", "dqn", "--net", "plain",
                    "--seed", "0", "--quiet", "--set", f"train_steps={steps}", "--set", "batch_size=32",
                    "--set", "train_freq=1", "--set", "prioritized=false", "--set", "learning_starts=100",
                    "--set", "double_q=false", "--set", "loss=huber", "--set", "lr=0.0001",
                    "--set", "eps_start=1.0", "--set", "eps_end=0.05", "--set", "gamma=0.99",
                    "--set", "replay_size=1000000", "--set", "target_period=10000", "--set", f"eval_period={steps}",
                    "--set", "eval_episodes=1", "-o", out], check=True, stdout=subprocess.DEVNULL)
    summary = json.load(open(f"{out}/summary.json"))
    rates.append(summary["steps_per_s"])
    cpus.append(summary["cpu_time_s"])
print(f"arld runs: {', '.join(f'{r:,.0f}' for r in rates)} steps/s", file=sys.stderr)
print(statistics.median(rates), statistics.median(cpus))
PY
)

echo "== Stable-Baselines3 DQN ($venv): the same configuration, $steps steps"
read -r sb3_sps sb3_cpu < <("$venv/bin/python" - "$steps" <<'PY'
import sys, time
import torch
torch.set_num_threads(1)
import gymnasium as gym
import stable_baselines3
from stable_baselines3 import DQN
print(f"torch {torch.__version__}, gymnasium {gym.__version__}, stable-baselines3 {stable_baselines3.__version__}",
      file=sys.stderr)
steps = int(sys.argv[1])
model = DQN("MlpPolicy", gym.make("CartPole-v1"), policy_kwargs=dict(net_arch=[64, 64]),
            batch_size=32, train_freq=1, gradient_steps=1, learning_starts=100,
            buffer_size=1_000_000, target_update_interval=10_000, seed=0, device="cpu", verbose=0)
start, cpu_start = time.perf_counter(), time.process_time()
model.learn(total_timesteps=steps)
print(steps / (time.perf_counter() - start), time.process_time() - cpu_start)
PY
)
python3 bench/ratio.py "$arld_sps" "$sb3_sps" "$arld_cpu" "$sb3_cpu" "$steps" "$out/sb3_cartpole$tag.json"
