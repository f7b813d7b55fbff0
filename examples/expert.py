#!/usr/bin/env python3
"""An expert for arld in its own process: `arld train --env CartPole-v0 --method adqn --expert cmd:"python3 examples/expert.py"`
(or `--env Pendulum-v1`, whose actions are in a box).

It speaks arld's JSON-lines protocol on stdin/stdout (one JSON object per line):
  arld -> expert, once:       {"type": "hello", "protocol": 1, "env": "CartPole-v0",
                               "observation_space": {"type": "box", "shape": [4]},
                               "action_space": {"type": "discrete", "n": 2}}
  arld -> expert, per query:  {"type": "query", "obs": [x, x_dot, theta, theta_dot]}
  expert -> arld, per query:  {"action": 0 or 1}
In a task whose actions are in a box, the hello's action space is
  {"type": "box", "shape": [1], "low": [-2.0], "high": [2.0]}
and an answer is a list of numbers within those bounds, e.g. {"action": [0.5]}.
When arld closes stdin, the expert exits. Print diagnostics to stderr, never to stdout.

CartPole: it pushes the cart towards the side the pole falls to. Pendulum-v1: it pumps energy into the swing until
the pendulum nears the top, then holds it there with a proportional-derivative law. Replace `act` with your own
policy (a person, a trained model, a controller) and keep the loop.
"""
import json
import math
import sys


def cartpole(obs):
    theta, theta_dot = obs[2], obs[3]
    return 1 if theta + 0.5 * theta_dot > 0 else 0


def pendulum(obs):
    """Pendulum-v1 (g = 10, m = l = 1, torque in [-2, 2]); the angle is 0 upright."""
    cos, sin, speed = obs
    angle = math.atan2(sin, cos)
    if cos > 0.85:
        torque = -(10.0 * angle + 2.0 * speed)
    else:
        energy = 0.5 * speed * speed + 10.0 * cos  # 10 upright at rest
        torque = 2.0 if speed * (10.0 - energy) >= 0 else -2.0
    return [max(-2.0, min(2.0, torque))]


EXPERTS = {"CartPole": cartpole, "Pendulum": pendulum}


def main():
    hello = json.loads(sys.stdin.readline())
    act = EXPERTS.get(hello.get("env", "").split("-")[0])
    if act is None:
        print(f"this example expert plays {', '.join(EXPERTS)}, not {hello.get('env')}", file=sys.stderr)
        return 2
    for line in sys.stdin:
        message = json.loads(line)
        if message["type"] == "query":
            print(json.dumps({"action": act(message["obs"])}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
