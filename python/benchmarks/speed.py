"""Steps per second from Python: arld next to Stable-Baselines3's DQN, one after the other in one process.

    .venv/bin/python python/benchmarks/speed.py [steps]

Every row learns CartPole-v1 for the same number of environment steps with one gradient update per step after 500
steps, batch 32, one CPU thread. arld's rows with evaluations run 20 test episodes every 1000 steps (their cost is
in the rate); "one evaluation" rows evaluate only at the end; SB3 evaluates never. The last column is the rate over
SB3's.
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


def timed(model):
    start = time.perf_counter()
    model.learn(total_timesteps=steps)
    return steps / (time.perf_counter() - start)


rows = []
for label, env in (("arld ADQN-B, Gymnasium env via Python", gym.make("CartPole-v1")),
                   ("arld ADQN-B, built-in env (arld.make)", arld.make("CartPole-v1"))):
    rows.append((label, timed(arld.Agent("adqn", env, net="bootstrap", expert=expert, seed=0, learning_starts=500,
                                         eval_period=1000))))
for label, env, eval_period, hidden in (
        ("arld DQN 64-64, Gymnasium env via Python", gym.make("CartPole-v1"), 1000, [64, 64]),
        ("arld DQN 64-64, built-in env", arld.make("CartPole-v1"), 1000, [64, 64]),
        ("arld DQN 64-64, built-in env, one evaluation", arld.make("CartPole-v1"), steps, [64, 64]),
        ("arld DQN 256-256, built-in env, one evaluation", arld.make("CartPole-v1"), steps, [256, 256])):
    rows.append((label, timed(arld.Agent("dqn", env, net="plain", seed=0, learning_starts=500, eval_period=eval_period,
                                         policy_kwargs=dict(net_arch=hidden)))))

from stable_baselines3 import DQN  # noqa: E402 (imported where SB3's rows begin)

for hidden in ([64, 64], [256, 256]):
    sb3 = DQN("MlpPolicy", "CartPole-v1", learning_starts=500, train_freq=1, gradient_steps=1, batch_size=32,
              policy_kwargs={"net_arch": hidden}, seed=0, verbose=0)
    rows.append((f"Stable-Baselines3 DQN {hidden[0]}-{hidden[1]}", timed(sb3)))

sb3_rate = rows[-2][1]
print(f"{steps} steps of CartPole-v1 each (arld {arld.__version__})")
for label, rate in rows:
    print(f"{label:48s} {rate:9.0f} steps/s {rate / sb3_rate:7.1f}x")
