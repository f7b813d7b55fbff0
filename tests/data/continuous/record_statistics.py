"""Records the statistics that the continuous tasks' tests compare with.

    python record_statistics.py OUT_DIR

writes OUT_DIR/scripted_returns.json, the per-seed returns of the scripted controllers of Pendulum-v1 and
MountainCarContinuous-v0 (src/env/pendulum.rs `swing_up`, src/env/mountain_car_continuous.rs `momentum`, written
again here in NumPy's types) on Gymnasium's tasks, seeds 100..129 (tests/continuous_conformance.rs), and
OUT_DIR/lander_statistics.json (tests/lunar_lander.rs): the per-seed returns and lengths of Gymnasium's
`LunarLanderContinuous-v3` under uniform random actions (seeds 0..299; the actions of seed s drawn by
numpy.random.Generator(PCG64(s)).uniform(-1, 1, 2) and cast to float32) and under Gymnasium's heuristic
controller in continuous mode (seeds 0..199). Needs gymnasium (1.4.0 was used), numpy and box2d.
"""

import json
import math
import platform
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
from gymnasium.envs.box2d.lunar_lander import heuristic

RANDOM_SEEDS = 300
HEURISTIC_SEEDS = 200


def play(env, seed, choose):
    obs, _ = env.reset(seed=seed)
    total, length = 0.0, 0
    while True:
        obs, reward, terminated, truncated, _ = env.step(choose(obs))
        total += float(reward)
        length += 1
        if terminated or truncated:
            return total, length


def random_policy(seed):
    draw = np.random.Generator(np.random.PCG64(seed))
    return lambda _obs: draw.uniform(-1.0, 1.0, 2).astype(np.float32)


def swing_up(obs):
    cos, sin, theta_dot = (float(x) for x in obs)
    if cos > 0.8:
        u = -(10.0 * math.atan2(sin, cos) + 2.0 * theta_dot)
    else:
        energy = 0.5 * theta_dot * theta_dot + 15.0 * (cos - 1.0)
        u = (2.0 * (-1.0 if theta_dot < 0.0 else 1.0)) if energy < 0.0 else 0.0
    return np.array([np.clip(np.float32(u), -2.0, 2.0)], dtype=np.float32)


def momentum(throttle):
    return lambda obs: np.array([-throttle if obs[1] < 0.0 else throttle], dtype=np.float32)


SCRIPTED_SEEDS = range(100, 130)


def record_scripted(out):
    returns = {}
    for env_id, name, policy in [
        ("Pendulum-v1", "swing_up", swing_up),
        ("MountainCarContinuous-v0", "momentum(0.6)", momentum(np.float32(0.6))),
        ("MountainCarContinuous-v0", "momentum(1.0)", momentum(np.float32(1.0))),
    ]:
        env = gym.make(env_id)
        returns[f"{env_id} {name}"] = [play(env, seed, policy)[0] for seed in SCRIPTED_SEEDS]
    document = {
        "gymnasium": gym.__version__,
        "numpy": np.__version__,
        "seeds": [SCRIPTED_SEEDS.start, SCRIPTED_SEEDS.stop],
        "returns": returns,
    }
    (out / "scripted_returns.json").write_text(json.dumps(document, indent=1) + "\n")


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    record_scripted(Path(sys.argv[1]))
    env = gym.make("LunarLanderContinuous-v3")
    samples = {}
    for name, seeds, policy in [
        ("random", RANDOM_SEEDS, random_policy),
        ("heuristic", HEURISTIC_SEEDS, lambda _seed: lambda obs: heuristic(env.unwrapped, obs)),
    ]:
        runs = [play(env, seed, policy(seed)) for seed in range(seeds)]
        samples[name] = {
            "seeds": [0, seeds],
            "returns": [round(r, 6) for r, _ in runs],
            "lengths": [n for _, n in runs],
        }
    document = {
        "env": "LunarLanderContinuous-v3",
        "gymnasium": gym.__version__,
        "numpy": np.__version__,
        "python": platform.python_version(),
        "random": {"actions": "Generator(PCG64(seed)).uniform(-1, 1, 2).astype(float32)", **samples["random"]},
        "heuristic": {"actions": "gymnasium.envs.box2d.lunar_lander.heuristic", **samples["heuristic"]},
    }
    (Path(sys.argv[1]) / "lander_statistics.json").write_text(json.dumps(document, indent=1) + "\n")


if __name__ == "__main__":
    main()
