#!/usr/bin/env python3
"""An expert for arld in its own process: `arld train --env CartPole-v0 --method adqn --expert cmd:"python3 examples/expert.py"`.

It speaks arld's JSON-lines protocol on stdin/stdout (one JSON object per line):
  arld -> expert, once:       {"type": "hello", "protocol": 1, "env": "CartPole-v0",
                               "observation_space": {"type": "box", "shape": [4]},
                               "action_space": {"type": "discrete", "n": 2}}
  arld -> expert, per query:  {"type": "query", "obs": [x, x_dot, theta, theta_dot]}
  expert -> arld, per query:  {"action": 0 or 1}
When arld closes stdin, the expert exits. Print diagnostics to stderr, never to stdout.

This one balances CartPole by pushing the cart towards the side the pole falls to; replace `act` with your own
policy (a person, a trained model, a controller) and keep the loop.
"""
import json
import sys


def act(obs):
    theta, theta_dot = obs[2], obs[3]
    return 1 if theta + 0.5 * theta_dot > 0 else 0


def main():
    hello = json.loads(sys.stdin.readline())
    if hello.get("env", "").split("-")[0] != "CartPole":
        print(f"this example expert only plays CartPole, not {hello.get('env')}", file=sys.stderr)
        return 2
    for line in sys.stdin:
        message = json.loads(line)
        if message["type"] == "query":
            print(json.dumps({"action": act(message["obs"])}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
