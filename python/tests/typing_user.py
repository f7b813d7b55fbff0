"""A user's script over the package's whole surface; tests/test_sb3.py runs `mypy --strict` on it."""

from typing import Any, Dict

import gymnasium as gym
import numpy as np

import arld


def my_expert(obs: np.ndarray) -> int:
    return int(obs[2] + 0.5 * obs[3] > 0)


def stop_early(locals_: Dict[str, Any], globals_: Dict[str, Any]) -> bool:
    return bool(locals_["step"] < 100)


def main() -> None:
    env = gym.make("CartPole-v1", max_episode_steps=200)
    model = arld.Agent("adqn", env, net="bootstrap", expert=my_expert, seed=0, learning_rate=1e-3, budget=100,
                       policy_kwargs=dict(net_arch=[64, 64]), eval_env=gym.make("CartPole-v1", max_episode_steps=200))
    model.learn(total_timesteps=200, callback=stop_early, progress_bar=False)
    model.learn(100, reset_num_timesteps=False, log_interval=None)
    wide = arld.Agent("dqn", env, net="plain", hidden=[128, 32], verbose=1)
    wide.learn(100, log_interval=2)
    action, state = model.predict(np.zeros(4, dtype=np.float32), deterministic=True)
    assert state is None
    print(int(action), model.num_timesteps, model.evaluations, model.queries, model.summary)
    params = model.get_parameters()
    model.set_parameters(params)
    model.set_env(gym.make("CartPole-v1", max_episode_steps=200))
    print(model.get_env(), arld.__version__, arld.config_keys()[:3], arld.preset("adqn", "CartPole-v1")["lr"])
    demos = arld.collect_demos(gym.make("CartPole-v1"), my_expert, 50, seed=0)
    print(len(demos["actions"]), arld.make("CartPole-v1"), arld.METHODS, arld.NETS)
    model.save("/tmp/arld_typing_user.arld")
    again = arld.Agent.load("/tmp/arld_typing_user.arld", env, expert=my_expert, learning_rate=1e-3,
                            custom_objects={"gamma": 0.98})
    again.learning_rate = 5e-4
    again.set_random_seed(3)
    print(again.num_timesteps, again.policy.predict(np.zeros(4, dtype=np.float32))[0], again.device, again.gamma)
    sb3_like = arld.Agent("dqn", "CartPole-v1", defaults="sb3").learn(200)
    student = arld.Agent("gdqn", arld.make("CartPole-v1"), expert=sb3_like, eval_env=[env, env])
    print(student.method, student.net, arld.SB3_DEFAULTS["lr"])


if __name__ == "__main__":
    main()
