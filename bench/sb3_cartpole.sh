#!/usr/bin/env bash
# arld against Stable-Baselines3 DQN, side by side in one run, on SB3's DQN configuration:
# CartPole-v1, a 64-64 network, batch 32, one gradient update per environment step, uniform replay.
# Both are single-threaded (torch.set_num_threads(1); one arld run uses one core) and train the same number of
# steps with no evaluation in between. Prints both speeds and their ratio, and writes bench/out/sb3_cartpole.json.
#
# Usage: bench/sb3_cartpole.sh [STEPS]      (default 20000; SB3 needs about 30 s per 20k steps on one core)
# SB3 (with CPU-only torch and Gymnasium) is installed into bench/.venv on the first run.
set -euo pipefail
cd "$(dirname "$0")/.."
steps="${1:-20000}"
out=bench/out
mkdir -p "$out"

venv=bench/.venv
if [ ! -x "$venv/bin/python" ] || ! "$venv/bin/python" -c "import stable_baselines3" 2>/dev/null; then
  echo "== installing Stable-Baselines3 into $venv (CPU-only torch)"
  python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet --upgrade pip
  # PyTorch's CPU-only wheel (~200 MB); PyPI's Linux wheel needs the CUDA libraries (several GB) even to import.
  "$venv/bin/pip" install --quiet torch --index-url https://download.pytorch.org/whl/cpu ||
    "$venv/bin/pip" install --quiet torch
  "$venv/bin/pip" install --quiet stable-baselines3 gymnasium
fi

cargo build --release --quiet
echo "== arld: CartPole-v1, dqn, plain 64-64, batch 32, train_freq 1, uniform replay, $steps steps"
rm -rf "$out/arld_cartpole"
./target/release/arld train --env CartPole-v1 --method dqn --net plain --seed 0 --quiet \
  --set train_steps="$steps" --set batch_size=32 --set train_freq=1 --set prioritized=false \
  --set learning_starts=100 --set replay_size=1000000 --set target_period=10000 \
  --set eval_period="$steps" --set eval_episodes=1 -o "$out/arld_cartpole" >/dev/null
arld_sps=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['steps_per_s'])" "$out/arld_cartpole/summary.json")

echo "== Stable-Baselines3 DQN: the same configuration, $steps steps"
sb3_sps=$("$venv/bin/python" - "$steps" <<'PY'
import sys, time
import torch
torch.set_num_threads(1)
import gymnasium as gym
from stable_baselines3 import DQN
steps = int(sys.argv[1])
model = DQN("MlpPolicy", gym.make("CartPole-v1"), policy_kwargs=dict(net_arch=[64, 64]),
            batch_size=32, train_freq=1, gradient_steps=1, learning_starts=100,
            buffer_size=1_000_000, target_update_interval=10_000, seed=0, device="cpu", verbose=0)
start = time.perf_counter()
model.learn(total_timesteps=steps)
print(steps / (time.perf_counter() - start))
PY
)
python3 - "$arld_sps" "$sb3_sps" "$steps" "$out/sb3_cartpole.json" <<'PY'
import json, os, sys
arld, sb3, steps, path = float(sys.argv[1]), float(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
load = os.getloadavg()[0]
print(f"arld {arld:,.0f} steps/s, Stable-Baselines3 {sb3:,.0f} steps/s: {arld / sb3:.1f}x "
      f"({steps} steps each, load average {load:.2f} on {os.cpu_count()} cores)")
json.dump({"steps": steps, "arld_steps_per_s": arld, "sb3_steps_per_s": sb3, "ratio": arld / sb3,
           "load_average": load}, open(path, "w"), indent=2)
PY
