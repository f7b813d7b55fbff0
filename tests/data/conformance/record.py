#!/usr/bin/env python3
"""Record the conformance data arld's environments are tested against, from Gymnasium itself.

Pinned versions (the committed files were recorded with exactly these):
    python 3.11.7, gymnasium==1.4.0, numpy==2.4.6, box2d==2.3.10 (pybox2d, bundling Box2D 2.3.0), pygame==2.6.1 (imported by the box2d package)

Set-up and use, from the repository root:
    python3 -m venv .venv-gym
    .venv-gym/bin/pip install gymnasium==1.4.0 numpy==2.4.6 box2d==2.3.10 pygame==2.6.1
    .venv-gym/bin/python tests/data/conformance/record.py tests/data/conformance

It writes three files into the given directory:
  classic_control.jsonl  CartPole-v1, Acrobot-v1, MountainCar-v0 episodes (format below)
  lunar_lander.jsonl     LunarLander-v3 episodes under random and heuristic actions
  statistics.json        per-seed returns and lengths of Gymnasium's lander under uniform random actions
                         (seeds 0..299) and under its heuristic controller (seeds 0..199)

Trace format, one JSON object per line: a `meta` line, then per episode a `start` line and its `step` lines.
  start: env, case, seed, action_seed, n_actions, max_episode_steps, obs, and `state` (classic control only)
  step:  env, case, seed, t (from 1), action, obs, state?, reward, terminated, truncated
Observations are float32 values written as the exact JSON number of their float64 widening.
Cases: `seed` resets with reset(seed=s) and takes random actions from random.Random(action_seed);
`set` resets with seed 0 and then overwrites the internal float64 state (classic control only);
`heuristic` acts with Gymnasium's heuristic lander controller.
"""

import json
import platform
import random
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
from gymnasium.envs.box2d.lunar_lander import heuristic

CLASSIC = ["CartPole-v1", "Acrobot-v1", "MountainCar-v0"]
SEED_EPISODES = 5
SET_STATES = {
    "CartPole-v1": [[0.0, 0.0, 0.0, 0.0], [2.3, 0.5, 0.0, 0.0], [0.0, 0.0, 0.2, 0.0], [-1.0, -0.3, -0.1, 0.5]],
    "Acrobot-v1": [
        [0.0, 0.0, 0.0, 0.0],
        [np.pi / 2, 0.0, 0.0, 0.0],
        [3.0, -3.0, 12.0, 28.0],
        [-3.1, 3.1, -5.0, 5.0],
        [1.0, 0.5, 0.0, 0.0],
    ],
    "MountainCar-v0": [[-0.5, 0.0], [-1.2, -0.07], [0.49, 0.07], [0.0, 0.0], [-1.19, -0.05]],
}
RANDOM_STATISTICS_SEEDS = 300
HEURISTIC_STATISTICS_SEEDS = 200


def numbers(values):
    return [float(v) for v in values]


def versions():
    return {"gymnasium": gym.__version__, "numpy": np.__version__, "python": platform.python_version()}


def internal_state(env):
    return numbers(env.unwrapped.state)


def episode(out, env_id, case, seed, action_seed, env, obs, choose, with_state):
    """Writes one episode's start and step lines; `choose(obs)` gives each action."""
    spec = env.spec
    start = {
        "kind": "start",
        "env": env_id,
        "case": case,
        "seed": seed,
        "action_seed": action_seed,
        "n_actions": int(env.action_space.n),
        "max_episode_steps": spec.max_episode_steps,
        "obs": numbers(obs),
    }
    if with_state:
        start["state"] = internal_state(env)
    out.write(json.dumps(start, separators=(",", ":")) + "\n")
    t = 0
    while True:
        action = choose(obs)
        obs, reward, terminated, truncated, _ = env.step(action)
        t += 1
        step = {"kind": "step", "env": env_id, "case": case, "seed": seed, "t": t, "action": action, "obs": numbers(obs)}
        if with_state:
            step["state"] = internal_state(env)
        step.update({"reward": float(reward), "terminated": bool(terminated), "truncated": bool(truncated)})
        out.write(json.dumps(step, separators=(",", ":")) + "\n")
        if terminated or truncated:
            return


def random_actions(action_seed, n_actions):
    draw = random.Random(action_seed)
    return lambda _obs: draw.randrange(n_actions)


def record_classic(path):
    with open(path, "w") as out:
        meta = {"kind": "meta", **versions()}
        meta.update({
            "actions": "random.Random(action_seed).randrange(n_actions) per step",
            "seed_case": f"env.reset(seed=s), action_seed=s, s in 0..{SEED_EPISODES - 1}",
            "set_case": "env.reset(seed=0); env.unwrapped.state=np.array(state,float64); action_seed=1000+k",
        })
        out.write(json.dumps(meta, separators=(",", ":")) + "\n")
        for env_id in CLASSIC:
            env = gym.make(env_id)
            n = int(env.action_space.n)
            for seed in range(SEED_EPISODES):
                obs, _ = env.reset(seed=seed)
                episode(out, env_id, "seed", seed, seed, env, obs, random_actions(seed, n), True)
            for k, state in enumerate(SET_STATES[env_id]):
                env.reset(seed=0)
                env.unwrapped.state = np.array(state, dtype=np.float64)
                obs = env.unwrapped._get_ob() if env_id == "Acrobot-v1" else np.array(state, dtype=np.float32)
                episode(out, env_id, "set", k, 1000 + k, env, obs, random_actions(1000 + k, n), True)


def heuristic_policy(env):
    return lambda obs: int(heuristic(env.unwrapped, obs))


def record_lander(path):
    with open(path, "w") as out:
        meta = {"kind": "meta", **versions()}
        meta["actions"] = "case seed: random.Random(seed).randrange(4); case heuristic: gymnasium heuristic()"
        out.write(json.dumps(meta, separators=(",", ":")) + "\n")
        env = gym.make("LunarLander-v3")
        for seed in range(SEED_EPISODES):
            obs, _ = env.reset(seed=seed)
            episode(out, "LunarLander-v3", "seed", seed, seed, env, obs, random_actions(seed, 4), False)
        for seed in range(SEED_EPISODES):
            obs, _ = env.reset(seed=seed)
            episode(out, "LunarLander-v3", "heuristic", seed, seed, env, obs, heuristic_policy(env), False)


def play(env, seed, choose):
    obs, _ = env.reset(seed=seed)
    total, length = 0.0, 0
    while True:
        obs, reward, terminated, truncated, _ = env.step(choose(obs))
        total += float(reward)
        length += 1
        if terminated or truncated:
            return total, length


def record_statistics(path):
    env = gym.make("LunarLander-v3")
    samples = {}
    for name, seeds, policy in [
        ("random", RANDOM_STATISTICS_SEEDS, lambda seed: random_actions(seed, 4)),
        ("heuristic", HEURISTIC_STATISTICS_SEEDS, lambda _seed: heuristic_policy(env)),
    ]:
        runs = [play(env, seed, policy(seed)) for seed in range(seeds)]
        samples[name] = {
            "seeds": [0, seeds],
            "returns": [round(r, 6) for r, _ in runs],
            "lengths": [n for _, n in runs],
        }
    document = {
        "env": "LunarLander-v3",
        **versions(),
        "random": {"actions": "random.Random(seed).randrange(4)", **samples["random"]},
        "heuristic": {"actions": "gymnasium.envs.box2d.lunar_lander.heuristic", **samples["heuristic"]},
    }
    Path(path).write_text(json.dumps(document, indent=1) + "\n")


def main():
    if len(sys.argv) != 2:
        sys.exit("usage: record.py OUTPUT_DIR")
    out = Path(sys.argv[1])
    out.mkdir(parents=True, exist_ok=True)
    record_classic(out / "classic_control.jsonl")
    record_lander(out / "lunar_lander.jsonl")
    record_statistics(out / "statistics.json")


if __name__ == "__main__":
    main()
