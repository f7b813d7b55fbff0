"""What a Stable-Baselines3 user's fingers do, against real Gymnasium and SB3: predict and evaluate_policy,
learn in stretches (byte-identical to one stretch), callbacks, save/load of the full run, environments as users
have them (re-limited, wrapped, one eval_env, vector envs refused), demonstrations through wrappers, the
README's example, and mypy --strict on a user script."""

import json
import re
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import arld

REPO = Path(__file__).resolve().parents[2]


def expert(obs):
    return int(obs[2] + 0.5 * obs[3] > 0)


def cartpole_agent(method="adqn", env=None, **kw):
    env = gym.make("CartPole-v1") if env is None else env
    return arld.Agent(method, env, expert=None if method == "dqn" else expert, seed=2, eval_period=500, **kw)


def test_evaluate_policy_of_stable_baselines3_runs_an_arld_model():
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.monitor import Monitor

    model = cartpole_agent().learn(1500)
    mean, std = evaluate_policy(model, Monitor(gym.make("CartPole-v1")), n_eval_episodes=3)
    assert mean > 0 and std >= 0
    action, state = model.predict(np.zeros(4, dtype=np.float32))
    assert state is None and action.shape == () and int(action) in (0, 1)
    actions, _ = model.predict(np.zeros((5, 4), dtype=np.float32))
    assert actions.shape == (5,)
    # deterministic=False explores as training does: ε is still high early in a run.
    early = cartpole_agent(exploration_initial_eps=1.0, exploration_final_eps=1.0).learn(10)
    explored = {int(early.predict(np.zeros(4), deterministic=False)[0]) for _ in range(50)}
    assert explored == {0, 1}


@pytest.mark.parametrize("method,net", [("adqn", "bootstrap"), ("bdqn", "noisy"), ("dqfd", "plain")])
def test_learn_in_two_stretches_equals_one_byte_for_byte(tmp_path, method, net):
    kw = dict(net=net, pretrain_steps=100) if method == "dqfd" else dict(net=net)
    runs = []
    for stretches, name in (((700, 1300), "two"), ((2000,), "one")):
        model = cartpole_agent(method, **kw)
        for i, n in enumerate(stretches):
            model.learn(n, reset_num_timesteps=i == 0, log_dir=tmp_path / name)
        model.save(tmp_path / f"{name}.arld")
        runs.append(model)
    two, one = runs
    assert two.evaluations == one.evaluations and two.queries == one.queries
    assert two.summary["train_steps"] == one.summary["train_steps"] == 2000
    a, b = two.get_parameters()["policy"], one.get_parameters()["policy"]
    assert a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)
    for f in ("eval.csv", "queries.csv", "episodes.csv"):
        if (tmp_path / "one" / f).exists():
            assert (tmp_path / "two" / f).read_bytes() == (tmp_path / "one" / f).read_bytes(), f


def test_load_continues_the_saved_run(tmp_path):
    model = cartpole_agent().learn(1000)
    model.save(tmp_path / "run.arld")
    loaded = arld.Agent.load(tmp_path / "run.arld", gym.make("CartPole-v1"), expert=expert)
    assert loaded.num_timesteps == 1000 and loaded.net == "bootstrap"
    loaded.learn(1000)
    whole = cartpole_agent().learn(2000)
    assert loaded.evaluations == [e for e in whole.evaluations if e["step"] > 1000]
    assert loaded.summary["queries_used"] == whole.summary["queries_used"]
    # A Python expert is not in the file: loading without it says so.
    with pytest.raises(ValueError, match="pass it as expert="):
        arld.Agent.load(tmp_path / "run.arld", gym.make("CartPole-v1"))
    # Plain weights of a plain network say so, and act.
    dqn = cartpole_agent("dqn", net="plain").learn(600, log_dir=tmp_path / "dqn")
    weights = arld.Agent.load(tmp_path / "dqn" / "weights.safetensors")
    assert weights.net == "plain"
    assert weights.predict(np.ones(4))[0] == dqn.predict(np.ones(4))[0]
    with pytest.raises(RuntimeError, match="trained or loaded"):
        arld.Agent("dqn", gym.make("CartPole-v1")).predict(np.zeros(4))


class Scaled(gym.ObservationWrapper):
    """A user's wrapper: observations scaled by 2."""

    outputs = []

    def observation(self, obs):
        out = (2 * obs).astype(np.float32)
        Scaled.outputs.append(out.tobytes())
        return out


def test_relimited_and_wrapped_environments_train_as_given():
    limited = cartpole_agent(env=gym.make("CartPole-v1", max_episode_steps=200), eval_env=gym.make(
        "CartPole-v1", max_episode_steps=200)).learn(1000)
    assert limited.env_id.startswith("CartPole-v1[max_episode_steps=200")
    assert all(e["max"] <= 200 for e in limited.evaluations)
    assert limited.config["lr"] == arld.preset("adqn", "CartPole-v1")["lr"]  # still CartPole's preset
    seen = []

    def watching(obs):
        seen.append(np.array(obs))
        return expert(obs / 2)

    wrapped = arld.Agent("adqn", Scaled(gym.make("CartPole-v1")), expert=watching, seed=0,
                         eval_env=Scaled(gym.make("CartPole-v1")), eval_period=500).learn(1000)
    assert len(wrapped.evaluations) == 2 and seen
    made = set(Scaled.outputs)
    assert all(o.astype(np.float32).tobytes() in made for o in seen)  # the expert sees the wrapper's output
    # The built-in environment's fast path equals Gymnasium's unchanged environment.
    fast = cartpole_agent(env=arld.make("CartPole-v1")).learn(1000)
    slow = cartpole_agent().learn(1000)
    assert fast.evaluations == slow.evaluations and fast.queries == slow.queries
    # An id string, as SB3 takes it.
    assert cartpole_agent(env="CartPole-v1").learn(500).evaluations == slow.evaluations[:1]


def test_vector_environments_are_refused_with_what_to_pass():
    from stable_baselines3.common.vec_env import DummyVecEnv

    for venv in (gym.make_vec("CartPole-v1", num_envs=2), DummyVecEnv([lambda: gym.make("CartPole-v1")])):
        with pytest.raises(TypeError, match="pass a single environment"):
            arld.Agent("dqn", venv)


def test_dqfd_demonstrations_come_through_the_wrapper():
    seen = []

    def watching(obs):
        seen.append(np.array(obs))
        return expert(obs / 2)

    env = Scaled(gym.make("CartPole-v1"))
    model = arld.Agent("dqfd", env, expert=watching, seed=0, n_demo=100, pretrain_steps=50)
    model.learn(600)
    assert model.summary["demos_pretrain"] == 100 and len(seen) >= 100
    # Every observation the expert saw is one the wrapper made.
    made = set(Scaled.outputs)
    assert all(o.astype(np.float32).tobytes() in made for o in seen)
    demos = arld.collect_demos(Scaled(gym.make("CartPole-v1")), watching, 100, seed=0)
    first, _ = gym.make("CartPole-v1").reset(seed=0)
    assert np.array_equal(demos["obs"][0], 2 * first) and len(demos["actions"]) == 100

    class Transitions:  # imitation's TransitionsWithRew, duck-typed
        obs, acts, next_obs, rews = demos["obs"], demos["actions"], demos["next_obs"], demos["rewards"]
        dones = demos["terminated"] | demos["truncated"]
        infos = [{} for _ in demos["actions"]]

    arld.Agent("dqfd", Scaled(gym.make("CartPole-v1")), expert=watching, demos=Transitions(),
               pretrain_steps=50).learn(500)
    with pytest.raises(ValueError, match="does not pre-train"):
        arld.Agent("adqn", gym.make("CartPole-v1"), expert=expert, demos=demos)


def test_callbacks_see_the_run_and_stop_it():
    from stable_baselines3.common.callbacks import BaseCallback

    class StopAt(BaseCallback):
        def __init__(self):
            super().__init__()
            self.events = []

        def _on_training_start(self):
            self.events.append("start")

        def _on_step(self):
            return self.num_timesteps < 777

        def _on_training_end(self):
            self.events.append(("end", self.locals["step"], self.locals["queries"]))

    cb = StopAt()
    model = cartpole_agent()
    model.learn(5000, callback=cb)
    assert model.num_timesteps == 777 and cb.n_calls == 777
    assert cb.events[0] == "start" and cb.events[-1][:2] == ("end", 777)
    # The run goes on from there as if it had never stopped.
    model.learn(1223, reset_num_timesteps=False)
    assert model.evaluations == cartpole_agent().learn(2000).evaluations
    calls = []

    def plain(locals_, globals_):
        calls.append(locals_["step"])
        return locals_["step"] < 10

    cartpole_agent().learn(100, callback=plain)
    assert calls == list(range(1, 11))


def test_tensorboard_runs_are_numbered_and_records_name_the_expert(tmp_path):
    for _ in range(2):
        cartpole_agent(tensorboard_log=tmp_path).learn(500)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ADQN_1", "ADQN_2"]
    text = (tmp_path / "ADQN_1" / "config.toml").read_text()
    assert 'expert = "python:test_sb3.expert"' in text
    assert arld.__version__


def test_the_readme_python_example_runs(tmp_path, monkeypatch):
    readme = (REPO / "README.md").read_text()
    code = re.search(r"## From Python.*?```python\n(.*?)```", readme, re.S).group(1)
    monkeypatch.chdir(tmp_path)
    code = code.replace("total_timesteps=20_000", "total_timesteps=1_000")
    exec(compile(code, "README.md", "exec"), {})


def test_mypy_strict_accepts_a_user_script():
    script = Path(__file__).with_name("typing_user.py")
    out = subprocess.run([sys.executable, "-m", "mypy", "--strict", str(script)], capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr
