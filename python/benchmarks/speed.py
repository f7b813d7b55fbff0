"""Steps per second from Python: arld (Gymnasium's CartPole stepped in Python, a Python expert) next to
Stable-Baselines3's DQN, one after the other in one process.

    .venv/bin/python python/benchmarks/speed.py [steps]

Both learn CartPole-v1 for the same number of environment steps with one gradient update per step after 500
steps, batch 32, one CPU thread. arld's numbers include evaluation (20 test episodes every 1000 steps), SB3 has none.
"""
import sys
import time

import gymnasium as gym
import torch

import arld

torch.set_num_threads(1)
steps = int(sys.argv[1]) if len(sys.argv) > 1 else 10_000


def expert(obs):
    return int(obs[2] + 0.5 * obs[3] > 0)


rows = []
for label, env in (("arld ADQN-B, Gymnasium env via Python", gym.make("CartPole-v1")),
                   ("arld ADQN-B, built-in env (arld.make)", arld.make("CartPole-v1"))):
    model = arld.Agent("adqn", env, net="bootstrap", expert=expert, seed=0, learning_starts=500, eval_period=1000)
    start = time.perf_counter()
    model.learn(total_timesteps=steps)
    rows.append((label, steps / (time.perf_counter() - start)))

for label, eval_every in (("arld DQN (plain), Gymnasium env via Python", 1000),):
    model = arld.Agent("dqn", gym.make("CartPole-v1"), net="plain", seed=0, learning_starts=500, eval_period=eval_every)
    start = time.perf_counter()
    model.learn(total_timesteps=steps)
    rows.append((label, steps / (time.perf_counter() - start)))

from stable_baselines3 import DQN

sb3 = DQN("MlpPolicy", "CartPole-v1", learning_starts=500, train_freq=1, gradient_steps=1, batch_size=32,
          policy_kwargs={"net_arch": [64, 64]}, seed=0, verbose=0)
start = time.perf_counter()
sb3.learn(total_timesteps=steps)
rows.append(("Stable-Baselines3 DQN (64-64 MLP)", steps / (time.perf_counter() - start)))

print(f"{steps} steps of CartPole-v1 each")
for label, rate in rows:
    print(f"{label:45s} {rate:9.0f} steps/s")
