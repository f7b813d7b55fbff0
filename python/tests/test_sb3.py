"""What a Stable-Baselines3 user's fingers do, against real Gymnasium and SB3: predict and evaluate_policy,
learn in stretches (byte-identical to one stretch), callbacks, save/load of the full run, environments as users
have them (re-limited, wrapped, one eval_env, vector envs refused), demonstrations through wrappers, the
README's example, and mypy --strict on a user script."""

import json
import re
import subprocess
import sys
import warnings
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
    # The evaluations travel in the file (the query events do not).
    assert len(model.evaluations) == 2 and loaded.evaluations == model.evaluations
    loaded.learn(1000, reset_num_timesteps=False)
    whole = cartpole_agent().learn(2000)
    assert len(whole.evaluations) == 4 and loaded.evaluations == whole.evaluations
    assert loaded.summary["demos_queried"] == whole.summary["demos_queried"]
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


def test_dqfd_on_given_demonstrations_runs_no_expert_and_records_none(tmp_path):
    demos = arld.collect_demos(gym.make("CartPole-v1"), expert, 200, seed=0)
    calls = []

    def never(obs):
        calls.append(obs)
        return 0

    # Without expert=: the demonstrations are all DQfD needs.
    model = arld.Agent("dqfd", gym.make("CartPole-v1"), demos=demos, seed=0, pretrain_steps=20)
    model.learn(600, log_dir=tmp_path / "a")
    summary = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert summary["demos_pretrain"] == 200 and "expert" not in summary
    config = (tmp_path / "a" / "config.toml").read_text()
    assert 'demo_file = "python:demos"' in config
    # With an expert= beside demos=, the expert is never asked and not named.
    arld.Agent("dqfd", gym.make("CartPole-v1"), expert=never, demos=demos, seed=0,
               pretrain_steps=20).learn(600, log_dir=tmp_path / "b")
    assert calls == []
    assert "expert" not in json.loads((tmp_path / "b" / "summary.json").read_text())
    with pytest.raises(ValueError, match="needs an expert"):
        arld.Agent("adqnp", gym.make("CartPole-v1"), demos=demos)


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
    summary = json.loads((tmp_path / "ADQN_1" / "summary.json").read_text())
    assert summary["expert"] == "python:test_sb3.expert"


def test_the_readme_python_example_runs(tmp_path, monkeypatch):
    readme = (REPO / "README.md").read_text()
    code = re.search(r"## From Python.*?```python\n(.*?)```", readme, re.S).group(1)
    monkeypatch.chdir(tmp_path)
    code = code.replace("total_timesteps=20_000", "total_timesteps=1_000")
    exec(compile(code, "README.md", "exec"), {})


def test_mypy_strict_accepts_a_user_script(tmp_path):
    script = Path(__file__).with_name("typing_user.py")
    out = subprocess.run([sys.executable, "-m", "mypy", "--strict", str(script)], capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr
    # The package itself, with the compiled part's stubs, by name (a path inside site-packages would make mypy
    # take site-packages for the package's root).
    out = subprocess.run([sys.executable, "-m", "mypy", "--strict", "-p", "arld"], capture_output=True, text=True)
    assert "Success" in out.stdout, out.stdout + out.stderr
    assert out.returncode == 0, out.stdout + out.stderr
    # A misspelt method or network, an expert or environment of the wrong kind: mypy says so before any run.
    wrong = tmp_path / "wrong.py"
    wrong.write_text(
        "import arld\n"
        "arld.Agent('dqm', 'CartPole-v1')\n"
        "arld.Agent('dqn', 'CartPole-v1', net='boot')\n"
        "arld.Agent('adqn', 3, expert='shipped:weak')\n"
        "arld.Agent('adqn', 'CartPole-v1', expert=3)\n"
    )
    out = subprocess.run([sys.executable, "-m", "mypy", "--strict", str(wrong)], capture_output=True, text=True)
    lines = [line for line in out.stdout.splitlines() if ": error:" in line]
    assert [line.split(":")[1] for line in lines] == ["2", "3", "4", "5"], out.stdout
    assert "'dqm'" in lines[0] and "Literal" in lines[0] and "'boot'" in lines[1], out.stdout


def _safetensors_shapes(path):
    """Tensor shapes from a safetensors file's header (8-byte length, then JSON), read without arld."""
    data = Path(path).read_bytes()
    n = int.from_bytes(data[:8], "little")
    header = json.loads(data[8:8 + n])
    return {k: v["shape"] for k, v in header.items() if k != "__metadata__"}


def _numpy_greedy(weights, obs):
    """The plain network's greedy action computed with NumPy from PyTorch-layout weights."""
    h = np.maximum(weights["fc1.weight"] @ obs + weights["fc1.bias"], 0)
    h = np.maximum(weights["fc2.weight"] @ h + weights["fc2.bias"], 0)
    return int(np.argmax(weights["out.weight"] @ h + weights["out.bias"]))


def test_net_arch_sets_the_hidden_widths_and_the_saved_weights_have_them(tmp_path):
    cartpole_agent("dqn", net="plain", policy_kwargs=dict(net_arch=[256, 256])).learn(
        600, log_dir=tmp_path / "wide")
    shapes = _safetensors_shapes(tmp_path / "wide" / "weights.safetensors")
    assert shapes["fc1.weight"] == [256, 4] and shapes["fc2.weight"] == [256, 256]
    assert shapes["out.weight"] == [2, 256]
    assert "hidden = [\n    256,\n    256,\n]" in (tmp_path / "wide" / "config.toml").read_text()
    # Uneven widths, given by arld's own name: predict is the network the file holds.
    uneven = cartpole_agent("dqn", net="plain", hidden=[48, 24]).learn(600, log_dir=tmp_path / "uneven")
    assert _safetensors_shapes(tmp_path / "uneven" / "weights.safetensors")["fc2.weight"] == [24, 48]
    weights = uneven.get_parameters()["policy"]
    rng = np.random.default_rng(0)
    for obs in rng.normal(size=(20, 4)).astype(np.float32):
        assert int(uneven.predict(obs)[0]) == _numpy_greedy(weights, obs.astype(np.float64))
    # A saved run keeps its widths.
    uneven.save(tmp_path / "uneven.arld")
    loaded = arld.Agent.load(tmp_path / "uneven.arld", gym.make("CartPole-v1"))
    assert loaded.policy_kwargs == {"net_arch": [48, 24]}
    # The paper's network is 64-64 when nothing is said.
    paper = cartpole_agent("dqn", net="plain").learn(500).get_parameters()["policy"]
    assert paper["fc1.weight"].shape == (64, 4) and paper["fc2.weight"].shape == (64, 64)
    for bad in ([], [64] * 9, [0, 64]):
        with pytest.raises(ValueError, match=r"net_arch .*1 to 8 layers"):
            cartpole_agent("dqn", policy_kwargs=dict(net_arch=bad))
    with pytest.raises(TypeError, match="net_arch is the list"):
        cartpole_agent("dqn", policy_kwargs=dict(net_arch=dict(pi=[64], qf=[64])))


def test_log_interval_prints_a_line_every_n_episodes_when_verbose(capsys):
    episodes = []

    def count(locals_, globals_):
        episodes.append(locals_["episode"])
        return True

    model = cartpole_agent("dqn", verbose=1).learn(700, log_interval=3, callback=count)
    lines = [line for line in capsys.readouterr().out.splitlines() if "| episodes " in line]
    finished = model.summary["episodes"]
    assert finished == episodes[-1] > 6
    assert [int(line.split("| episodes ")[1].split()[0]) for line in lines] == list(range(3, finished + 1, 3))
    cartpole_agent("dqn").learn(700, log_interval=3)  # verbose=0: SB3 prints nothing either
    assert "| episodes " not in capsys.readouterr().out
    with pytest.raises(ValueError, match="log_interval"):
        cartpole_agent("dqn").learn(10, log_interval=0)


def test_records_name_the_expert_that_ran(tmp_path):
    from stable_baselines3 import DQN

    sb3 = DQN("MlpPolicy", gym.make("CartPole-v1"), seed=0)
    model = arld.Agent("adqn", gym.make("CartPole-v1"), expert=sb3, seed=0, eval_period=300).learn(
        300, log_dir=tmp_path / "sb3")
    summary = json.loads((tmp_path / "sb3" / "summary.json").read_text())
    assert summary["expert"] == "python:stable_baselines3.dqn.dqn.DQN" == model.summary["expert"]
    assert 'expert = "python:stable_baselines3.dqn.dqn.DQN"' in (tmp_path / "sb3" / "config.toml").read_text()
    cartpole_agent("dqn").learn(300, log_dir=tmp_path / "dqn")
    assert "expert" not in json.loads((tmp_path / "dqn" / "summary.json").read_text())


def test_errors_speak_python_not_rust():
    for kw, words in ((dict(batch_size=-1), "whole number"), (dict(batch_size=1.5), "whole number"),
                      (dict(learning_rate="fast"), "expected a number"), (dict(hidden=64), "expected a list")):
        with pytest.raises(ValueError, match=words) as err:
            cartpole_agent("dqn", **kw)
        assert not re.search(r"\b(usize|u64|i64|f64|f32)\b|floating point|\d\.\.\d", str(err.value)), err.value
    with pytest.raises(ValueError, match="`learning_rate` \\(arld's `lr`\\)"):
        cartpole_agent("dqn", learning_rate="fast")
    with pytest.raises(ValueError, match=r"2 actions \(0 to 1\)"):
        arld.Agent("dqfd", gym.make("CartPole-v1"), expert=lambda obs: 7, n_demo=10, pretrain_steps=1).learn(10)
    with pytest.raises(TypeError, match="did you mean 'exploration_fraction'"):
        cartpole_agent("dqn", exploration_fractoin=0.2)


def test_a_builtin_env_evaluates_on_the_eval_env_given():
    short = gym.wrappers.TimeLimit(gym.make("CartPole-v1"), max_episode_steps=5)
    model = cartpole_agent("dqn", env=arld.make("CartPole-v1"), eval_env=short).learn(1000)
    assert model.evaluations and all(e["max"] <= 5 for e in model.evaluations)
    plain = cartpole_agent("dqn", env=arld.make("CartPole-v1")).learn(1000)
    assert any(e["max"] > 5 for e in plain.evaluations)


def test_defaults_sb3_are_those_of_stable_baselines3_dqn():
    import inspect

    import torch
    from stable_baselines3 import DQN
    from stable_baselines3.common.buffers import ReplayBuffer
    from stable_baselines3.common.utils import get_linear_fn

    sb3 = DQN("MlpPolicy", gym.make("CartPole-v1"), device="cpu")
    agent = arld.Agent("dqn", gym.make("CartPole-v1"), defaults="sb3", seed=3, eval_period=100, eval_episodes=2)
    cfg = agent.config
    assert agent.net == "plain" and cfg["net"] == "plain"
    assert cfg["lr"] == sb3.learning_rate and cfg["replay_size"] == sb3.buffer_size
    assert cfg["batch_size"] == sb3.batch_size and cfg["gamma"] == sb3.gamma
    assert cfg["train_freq"] == sb3.train_freq.frequency and sb3.gradient_steps == 1 and sb3.tau == 1.0
    assert cfg["target_period"] == sb3.target_update_interval and cfg["target_period_in_steps"] is True
    assert cfg["random_before_learning"] is True
    assert cfg["grad_clip"] == sb3.max_grad_norm
    assert (cfg["eps_start"], cfg["eps_end"], cfg["eps_fraction"]) == (
        sb3.exploration_initial_eps, sb3.exploration_final_eps, sb3.exploration_fraction)
    # SB3 trains after a rollout of train_freq steps once num_timesteps > learning_starts; arld at the steps
    # (multiples of train_freq) >= its learning_starts: the first update falls on the same step.
    first_sb3 = next(t for t in range(1, 10_000) if t % sb3.train_freq.frequency == 0 and t > sb3.learning_starts)
    first_arld = next(t for t in range(1, 10_000) if t % cfg["train_freq"] == 0 and t >= cfg["learning_starts"])
    assert first_sb3 == first_arld
    assert list(cfg["hidden"]) == list(sb3.policy.net_arch) and isinstance(sb3.policy.q_net.q_net[1], torch.nn.ReLU)
    assert cfg["loss"] == "huber" and "smooth_l1_loss" in inspect.getsource(DQN.train)
    assert cfg["double_q"] is False and "q_net_target(replay_data.next_observations)" in inspect.getsource(DQN.train)
    assert "q_net(replay_data.next_observations)" not in inspect.getsource(DQN.train)  # no double Q in SB3
    assert cfg["prioritized"] is False and type(sb3.replay_buffer) is ReplayBuffer
    # A keyword given wins over the SB3 defaults; net= too.
    assert arld.Agent("dqn", "CartPole-v1", defaults="sb3", learning_rate=5e-4).config["lr"] == 5e-4
    with pytest.raises(ValueError, match="unknown defaults 'sb4'"):
        arld.Agent("dqn", "CartPole-v1", defaults="sb4")

    # ε over the first learn's total_timesteps, as SB3's schedule over its learn.
    total = 400
    with warnings.catch_warnings():  # deprecated in favour of LinearSchedule, the same line
        warnings.simplefilter("ignore")
        schedule = get_linear_fn(sb3.exploration_initial_eps, sb3.exploration_final_eps, sb3.exploration_fraction)
    seen = []

    def record(local_vars, global_vars):
        model = local_vars["self"]
        seen.append((model.num_timesteps, model.exploration_rate))
        return True

    agent.learn(total, callback=record)
    assert agent.config["train_steps"] == total and len(seen) == total
    for step, eps in seen:
        assert eps == pytest.approx(schedule(1.0 - step / total), abs=1e-12), step
    # SB3's own model after learning the same number of steps has the same ε as the arld run's last step.
    sb3.learn(total)
    assert agent.exploration_rate == pytest.approx(sb3.exploration_rate, abs=1e-12)
    # A new run takes its own learn's horizon; train_steps= fixes it.
    agent.learn(200)
    assert agent.config["train_steps"] == 200
    fixed = arld.Agent("dqn", "CartPole-v1", defaults="sb3", train_steps=1000, eval_period=100, eval_episodes=2)
    assert fixed.learn(100).config["train_steps"] == 1000


class _Actions(gym.Wrapper):
    """Records each step's observation and action."""

    def __init__(self, env):
        super().__init__(env)
        self.seen, self.last = [], None

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        self.last = obs
        return obs, info

    def step(self, action):
        self.seen.append((self.last, int(action)))
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.last = obs
        return obs, reward, terminated, truncated, info


def test_defaults_sb3_take_random_actions_copy_the_target_and_anneal_as_sb3_step_by_step(tmp_path):
    """Against SB3's own attributes, read after each of its steps: its target copies (`_n_calls %
    target_update_interval == 0`) and ε, and its uniformly random actions while num_timesteps < learning_starts."""
    from stable_baselines3 import DQN

    interval, starts, total = 50, 100, 400

    class Recording(DQN):
        def _on_step(self):
            super()._on_step()
            self.record.append((self.num_timesteps, self._n_calls % max(self.target_update_interval, 1) == 0,
                                self.exploration_rate))

    sb3 = Recording("MlpPolicy", gym.make("CartPole-v1"), learning_starts=starts, target_update_interval=interval,
                    seed=0, device="cpu")
    sb3.record = []
    sb3.learn(total)
    assert [t for t, _, _ in sb3.record] == list(range(1, total + 1))
    sb3_copies = [t for t, copied, _ in sb3.record if copied]
    first_update = next(t for t in range(1, total) if t % sb3.train_freq.frequency == 0 and t > starts)

    # arld, the same settings in its units (its learning_starts is SB3's + 1).
    model = arld.Agent("dqn", gym.make("CartPole-v1"), defaults="sb3", learning_starts=starts + 1,
                       target_update_interval=interval, seed=0, eval_period=total, eval_episodes=2)
    targets, eps = [], []

    def record(local_vars, global_vars):
        run = local_vars["self"]._run
        path = str(tmp_path / "target.safetensors")
        run.live_target_policy().save(path, {})
        targets.append(Path(path).read_bytes())
        eps.append((local_vars["self"].num_timesteps, local_vars["self"].exploration_rate))
        return True

    model.learn(total, callback=record)
    assert [t for t, _ in eps] == list(range(1, total + 1))
    # ε after every step, as SB3's exploration_rate after the same step.
    for (t, mine), (t_sb3, _, theirs) in zip(eps, sb3.record):
        assert t == t_sb3 and mine == pytest.approx(theirs, abs=1e-12), t
    # The target changes exactly at SB3's copies once the network has learned (copies before the first update
    # copy an unchanged network).
    changed = [t for t in range(2, total + 1) if targets[t - 1] != targets[t - 2]]
    assert changed == [t for t in sb3_copies if t > first_update] and len(changed) >= 5
    assert sb3_copies == list(range(interval, total + 1, interval))

    # Random actions before learning_starts: with ε 0, arld acts greedily from step learning_starts on, and
    # uniformly before; without random_before_learning it is greedy from the first step.
    def acted(random_before_learning):
        env = _Actions(gym.make("CartPole-v1"))
        arld.Agent("dqn", env, defaults="sb3", learning_starts=starts + 1, exploration_initial_eps=0.0,
                   exploration_final_eps=0.0, random_before_learning=random_before_learning, seed=0,
                   eval_period=total, eval_episodes=2).learn(first_update)
        return env.seen

    # The network before its first update (a run of one step learns nothing).
    untrained = arld.Agent("dqn", gym.make("CartPole-v1"), defaults="sb3", learning_starts=starts + 1, seed=0,
                           eval_period=total, eval_episodes=2).learn(1)

    def greedy(obs):
        return int(untrained.predict(np.asarray(obs, dtype=np.float32), deterministic=True)[0])

    random_first = acted(True)
    assert all(a == greedy(o) for o, a in random_first[starts:first_update])
    off_greedy = sum(a != greedy(o) for o, a in random_first[:starts])
    assert 25 <= off_greedy <= 75  # uniform over 2 actions: about half differ from the greedy one
    assert all(a == greedy(o) for o, a in acted(False)[:first_update])
    # SB3 too: with ε 0 its actions before learning_starts are uniform (SB3 samples the action space there).
    recorder = _Actions(gym.make("CartPole-v1"))
    sb3_zero = DQN("MlpPolicy", recorder, learning_starts=starts, exploration_initial_eps=0.0,
                   exploration_final_eps=0.0, seed=0, device="cpu")
    sb3_zero.learn(starts)
    actions = [a for _, a in recorder.seen]
    assert len(actions) == starts and 25 <= sum(actions) <= 75
