#!/usr/bin/env bash
# arld against Stable-Baselines3's TD3 or SAC, side by side in one run, on Pendulum-v1 with one configuration:
# hidden layers WIDTH-WIDTH for actor and critics, batch 256, one gradient step per environment step
# (train_freq 1), uniform replay of one-step returns, two critics, learning from step 100, random actions before
# that, SB3's learning rates (TD3 1e-3, SAC 3e-4) and its other defaults (tau 0.005, gamma 0.99; TD3: policy
# delay 2, target noise 0.2 clipped at 0.5, Gaussian exploration noise 0.1; SAC: automatic temperature).
# arld steps Pendulum-v1 in Rust; SB3 steps Gymnasium's. Both are single-threaded (torch.set_num_threads(1); an
# arld run uses one core) and train the same number of steps with no evaluation in between. Prints both speeds and
# their ratio, by wall clock and by CPU time (the steadier figure on a loaded machine), and writes
# bench/out/sb3_ALGO_WIDTH.json.
#
# Usage: [VENV=DIR] [ARLD=PATH TAG=NAME] bench/sb3_box.sh [td3|sac] [WIDTH] [STEPS]     (defaults: td3 64 5000)
set -euo pipefail
cd "$(dirname "$0")/.."
algo="${1:-td3}"
width="${2:-64}"
steps="${3:-5000}"
case "$algo" in td3) lr=0.001 ;; sac) lr=0.0003 ;; *) echo "algo must be td3 or sac, got $algo" >&2; exit 2 ;; esac
out=bench/out
mkdir -p "$out"
source bench/sb3_venv.sh

# ARLD=PATH measures another build of arld (an earlier commit's, for a before-and-after), named TAG in the output.
arld="${ARLD:-./target/release/arld}"
[ -n "${ARLD:-}" ] || cargo build --release --quiet
tag="${TAG:+_$TAG}"
echo "== arld: Pendulum-v1, $algo, $width-$width, batch 256, train_freq 1, uniform replay, $steps steps (median of 3 runs)"
read -r arld_sps arld_cpu < <(ARLD_BIN="$arld" python3 - "$steps" "$out/arld_${algo}_$width" "$algo" "$width" "$lr" <<'PY'
import json, os, shutil, statistics, subprocess, sys
arld = os.environ["ARLD_BIN"]
steps, out, algo, width, lr = sys.argv[1:6]
rates, cpus = [], []
for _ in range(3):
    shutil.rmtree(out, ignore_errors=True)
    subprocess.run([arld, "train", "--env", "Pendulum-v1", "--method", "dqn", "--algo", algo,
                    "--seed", "0", "--quiet", "--set", f"train_steps={steps}", "--set", "batch_size=256",
                    "--set", f"hidden=[{width}, {width}]", "--set", "heads=2", "--set", "train_freq=1",
                    "--set", "prioritized=false", "--set", "n_step=1", "--set", "learning_starts=100",
                    "--set", f"lr={lr}", "--set", "gamma=0.99", "--set", "replay_size=1000000",
                    "--set", f"eval_period={steps}", "--set", "eval_episodes=1", "-o", out],
                   check=True, stdout=subprocess.DEVNULL)
    summary = json.load(open(f"{out}/summary.json"))
    rates.append(summary["steps_per_s"])
    cpus.append(summary["cpu_time_s"])
print(f"arld runs: {', '.join(f'{r:,.0f}' for r in rates)} steps/s", file=sys.stderr)
print(statistics.median(rates), statistics.median(cpus))
PY
)

echo "== Stable-Baselines3 $algo ($venv): the same configuration, $steps steps"
read -r sb3_sps sb3_cpu < <("$venv/bin/python" - "$steps" "$algo" "$width" <<'PY'
import sys, time
import numpy as np
import torch
torch.set_num_threads(1)
import gymnasium as gym
import stable_baselines3
from stable_baselines3 import SAC, TD3
from stable_baselines3.common.noise import NormalActionNoise
print(f"torch {torch.__version__}, gymnasium {gym.__version__}, stable-baselines3 {stable_baselines3.__version__}",
      file=sys.stderr)
steps, algo, width = int(sys.argv[1]), sys.argv[2], int(sys.argv[3])
env = gym.make("Pendulum-v1")
common = dict(policy_kwargs=dict(net_arch=[width, width]), batch_size=256, train_freq=1, gradient_steps=1,
              learning_starts=100, buffer_size=1_000_000, seed=0, device="cpu", verbose=0)
if algo == "td3":
    noise = NormalActionNoise(np.zeros(1), 0.1 * np.ones(1))
    model = TD3("MlpPolicy", env, action_noise=noise, **common)
else:
    model = SAC("MlpPolicy", env, **common)
start, cpu_start = time.perf_counter(), time.process_time()
model.learn(total_timesteps=steps)
print(steps / (time.perf_counter() - start), time.process_time() - cpu_start)
PY
)
python3 bench/ratio.py "$arld_sps" "$sb3_sps" "$arld_cpu" "$sb3_cpu" "$steps" "$out/sb3_${algo}_$width$tag.json"
