"""Writes the small Minari datasets of tests/experts.rs with the real `minari` package (Arrow format), and what
`minari.load_dataset` reads back from them (expected.json), which the Rust reader must equal.

    .venv/bin/python tests/data/minari/make.py

CartPole-v1: three episodes of a scripted policy that loses the pole (time limit 30 steps); Pendulum-v1: two
episodes of 6 steps of a scripted torque. Minari's DataCollector needs jax for its step buffers, so the episodes are
gathered here and written with `minari.create_dataset_from_buffers`, the writer DataCollector ends in."""

import json
import os
import shutil
from pathlib import Path

import gymnasium as gym
import minari
import numpy as np
from minari.data_collector import EpisodeBuffer

HERE = Path(__file__).resolve().parent


def rollouts(env, policy, episodes):
    buffers = []
    for i in range(episodes):
        obs, _ = env.reset(seed=i)
        observations, actions, rewards, terminations, truncations = [obs], [], [], [], []
        done = False
        while not done:
            action = policy(obs)
            obs, reward, terminated, truncated, _ = env.step(action)
            observations.append(obs)
            actions.append(action)
            rewards.append(reward)
            terminations.append(terminated)
            truncations.append(truncated)
            done = terminated or truncated
        buffers.append(EpisodeBuffer(id=i, seed=i, observations=np.asarray(observations), actions=np.asarray(actions),
                                     rewards=rewards, terminations=terminations, truncations=truncations))
    return buffers


def main():
    os.environ["MINARI_DATASETS_PATH"] = str(HERE)
    expected = {}
    for dataset_id, env, policy, episodes in (
        ("arld-test/cartpole-v0", gym.make("CartPole-v1", max_episode_steps=30),
         lambda o: int(o[3] < 0), 3),
        ("arld-test/pendulum-v0", gym.make("Pendulum-v1", max_episode_steps=6),
         lambda o: np.clip([-1.5 * o[2]], -2, 2).astype(np.float32), 2),
    ):
        shutil.rmtree(HERE / dataset_id, ignore_errors=True)
        minari.create_dataset_from_buffers(dataset_id, rollouts(env, policy, episodes), env=env,
                                           algorithm_name="scripted", data_format="arrow")
        ds = minari.load_dataset(dataset_id)
        expected[dataset_id] = [
            {"observations": ep.observations.tolist(), "actions": ep.actions.tolist(),
             "rewards": ep.rewards.tolist(), "terminations": ep.terminations.tolist(),
             "truncations": ep.truncations.tolist()}
            for ep in ds.iterate_episodes()]
    (HERE / "expected.json").write_text(json.dumps(expected) + "\n")


if __name__ == "__main__":
    main()
