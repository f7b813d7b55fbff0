"""A Stable-Baselines3 user's first hour, against the real SB3 and Gymnasium: SB3's callbacks on the live model,
exceptions that keep the run, wrapped and re-limited tasks, any observation space, and arld.make as a
gymnasium.Env. Live values are compared with a second run of the same seed stopped at that step."""

import json
import os
import pickle
import shutil
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.callbacks import (BaseCallback, CallbackList, CheckpointCallback, EvalCallback,
                                                StopTrainingOnMaxEpisodes, StopTrainingOnNoModelImprovement,
                                                StopTrainingOnRewardThreshold)

import arld


def expert(obs):
    return int(obs[2] + 0.5 * obs[3] > 0)


def agent(method="adqn", env=None, **kw):
    env = gym.make("CartPole-v1") if env is None else env
    kw.setdefault("eval_period", 500)
    kw.setdefault("eval_episodes", 5)
    return arld.Agent(method, env, expert=None if method == "dqn" else expert, seed=3, **kw)


def params(model):
    return model.get_parameters()["policy"]


def same_params(a, b):
    return a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)


OBS = np.random.default_rng(0).normal(size=(64, 4)).astype(np.float32)


class Probe(BaseCallback):
    """Records, at the given steps, what the model says inside the callback."""

    def __init__(self, at):
        super().__init__()
        self.at, self.seen, self.events = set(at), {}, []

    def _on_training_start(self):
        self.events.append("training_start")

    def _on_rollout_start(self):
        self.events.append("rollout_start")

    def _on_step(self):
        assert self.num_timesteps == self.model.num_timesteps
        if self.num_timesteps in self.at:
            self.seen[self.num_timesteps] = dict(
                params=params(self.model), actions=self.model.predict(OBS)[0],
                evaluations=list(self.model.evaluations), queries=list(self.model.queries))
        return True

    def _on_rollout_end(self):
        self.events.append("rollout_end")

    def _on_training_end(self):
        self.events.append("training_end")


def test_predict_and_get_parameters_in_a_callback_use_the_live_weights_in_every_learn():
    probe = Probe(at=(300, 700))
    model = agent()
    model.learn(500, callback=probe)
    model.learn(500, callback=probe, reset_num_timesteps=False)
    for step in (300, 700):
        ref = agent().learn(step)
        live = probe.seen[step]
        assert same_params(live["params"], params(ref)), step
        assert np.array_equal(live["actions"], ref.predict(OBS)[0])
        assert live["evaluations"] == ref.evaluations and live["queries"] == ref.queries
    assert not same_params(probe.seen[700]["params"], probe.seen[300]["params"])
    # One learn is one rollout: its start and end around the steps, once per learn.
    assert probe.events == ["training_start", "rollout_start", "rollout_end", "training_end"] * 2


def test_eval_callback_with_a_reward_threshold_stops_the_run_and_saves_the_best_model(tmp_path):
    stop = StopTrainingOnRewardThreshold(reward_threshold=5, verbose=0)  # met at the first evaluation
    evaluate = EvalCallback(gym.make("CartPole-v1"), eval_freq=400, n_eval_episodes=3, callback_on_new_best=stop,
                            best_model_save_path=str(tmp_path / "best"), log_path=str(tmp_path / "log"))
    checkpoints = CheckpointCallback(save_freq=200, save_path=str(tmp_path / "cp"), name_prefix="cp")
    model = agent()
    model.learn(3000, callback=CallbackList([checkpoints, evaluate]))
    assert model.num_timesteps == 400 and evaluate.n_calls == 400
    assert evaluate.best_mean_reward >= 5 and (tmp_path / "log" / "evaluations.npz").exists()
    assert sorted(p.name for p in (tmp_path / "cp").iterdir()) == ["cp_200_steps.zip", "cp_400_steps.zip"]
    ref = agent().learn(400)
    best = arld.Agent.load(tmp_path / "best" / "best_model", gym.make("CartPole-v1"), expert=expert)
    assert best.num_timesteps == 400 and same_params(params(best), params(ref))
    assert np.array_equal(best.predict(OBS)[0], ref.predict(OBS)[0])


def test_stop_training_on_no_model_improvement_stops_at_the_first_evaluation_without_a_new_best(tmp_path):
    stop = StopTrainingOnNoModelImprovement(max_no_improvement_evals=1, min_evals=1)
    evaluate = EvalCallback(gym.make("CartPole-v1"), eval_freq=300, n_eval_episodes=3, callback_after_eval=stop,
                            log_path=str(tmp_path))
    model = agent().learn(4500, callback=evaluate)
    # Independently, from the evaluations EvalCallback recorded and SB3's documented rule: stop after more than
    # max_no_improvement_evals evaluations in a row without a new best, counted after min_evals of them.
    log = np.load(tmp_path / "evaluations.npz")
    means = log["results"].mean(axis=1)
    best, last_best, without, stop_at = -np.inf, -np.inf, 0, None
    for i, mean in enumerate(means):
        best = max(best, mean)
        if i + 1 > 1:
            without = 0 if best > last_best else without + 1
            if without > 1:
                stop_at = i
                break
        last_best = best
    expected = 4500 if stop_at is None else int(log["timesteps"][stop_at])
    assert model.num_timesteps == expected and len(means) == (15 if stop_at is None else stop_at + 1)


def test_a_checkpoint_written_in_a_callback_is_the_whole_run_at_that_step(tmp_path):
    model = agent()
    model.learn(1000, callback=CheckpointCallback(save_freq=400, save_path=str(tmp_path), name_prefix="cp"))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cp_400_steps.zip", "cp_800_steps.zip"]
    resumed = arld.Agent.load(tmp_path / "cp_400_steps.zip", gym.make("CartPole-v1"), expert=expert)
    resumed.learn(1100, reset_num_timesteps=False)
    whole = agent().learn(1500)
    assert resumed.num_timesteps == 1500 and same_params(params(resumed), params(whole))
    assert resumed.evaluations == [e for e in whole.evaluations if e["step"] > 400]
    assert resumed.summary["demos_queried"] == whole.summary["demos_queried"]


def test_stop_training_on_max_episodes_counts_the_runs_episodes():
    model = agent("dqn", net="plain")
    assert model.get_env().num_envs == 1 and model.get_vec_normalize_env() is None
    model.learn(5000, callback=StopTrainingOnMaxEpisodes(max_episodes=7))
    # Independently: the step at which the same run finishes its seventh episode.
    ends = []

    def watch(local_vars, global_vars):
        if local_vars["episode"] > len(ends):
            ends.append(local_vars["step"])
        return True

    agent("dqn", net="plain").learn(5000, callback=watch)
    assert model.summary["episodes"] == 7 and model.num_timesteps == ends[6]


class Raising(BaseCallback):
    def __init__(self, at):
        super().__init__()
        self.at = at

    def _on_step(self):
        if self.num_timesteps == self.at:
            raise KeyError("the callback broke")
        return True


def test_an_exception_from_a_callback_pauses_the_run_whole_and_it_goes_on_as_if_not():
    model = agent()
    with pytest.raises(KeyError, match="the callback broke") as info:
        model.learn(1500, callback=Raising(at=600))
    if sys.version_info >= (3, 11):
        notes = " ".join(info.value.__notes__)
        assert "raised by a callback after step 600" in notes and "paused whole after step 600" in notes
    ref = agent().learn(600)
    assert model.num_timesteps == 600 and same_params(params(model), params(ref))
    assert model.queries == ref.queries and model.queries
    model.learn(900, reset_num_timesteps=False)
    whole = agent().learn(1500)
    assert model.evaluations == whole.evaluations and model.queries == whole.queries
    assert same_params(params(model), params(whole))


def test_an_exception_from_an_expert_pauses_the_run_and_the_question_is_asked_again():
    calls = []

    def flaky(obs):
        calls.append(1)
        if len(calls) == 5:
            raise ConnectionError("the expert went away")
        return expert(obs)

    model = arld.Agent("gdqn", gym.make("CartPole-v1"), expert=flaky, seed=3, eval_period=500, eval_episodes=5)
    with pytest.raises(ConnectionError, match="went away") as info:
        model.learn(1000)
    if sys.version_info >= (3, 11):
        assert any("paused whole" in n for n in info.value.__notes__)
    paused_at = model.num_timesteps
    assert 0 < paused_at < 1000 and len(model.queries) >= 1
    model.learn(1000 - paused_at, reset_num_timesteps=False)
    whole = arld.Agent("gdqn", gym.make("CartPole-v1"), expert=expert, seed=3, eval_period=500,
                       eval_episodes=5).learn(1000)
    assert model.queries == whole.queries and model.evaluations == whole.evaluations
    assert same_params(params(model), params(whole))


@pytest.mark.parametrize("method", arld.METHODS)
def test_wrapped_and_relimited_builtin_tasks_train_with_every_method(method):
    small = dict(n_demo=50, pretrain_steps=20) if method in ("dqfd", "adqnp") else {}
    envs = [gym.make("CartPole-v1", max_episode_steps=200),
            gym.wrappers.TimeLimit(gym.make("CartPole-v1"), max_episode_steps=100),
            gym.wrappers.TransformObservation(gym.make("CartPole-v1"), lambda o: o * 2,
                                              gym.make("CartPole-v1").observation_space)]
    for env in envs:
        model = agent(method, env, eval_period=200, **small).learn(200)
        assert model.config["lr"] == arld.preset(method, "CartPole-v1")["lr"]  # the task's preset
    model.set_env(gym.make("CartPole-v1", max_episode_steps=150))
    model.learn(200)
    assert all(e["max"] <= 150 for e in model.evaluations)


class Extra(gym.ObservationWrapper):
    """CartPole with `n` more observation values."""

    def __init__(self, env, n):
        super().__init__(env)
        self.n = n
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (4 + n,), np.float32)

    def observation(self, obs):
        return np.concatenate([obs, np.zeros(self.n, np.float32)])


def test_two_wrappers_of_one_id_with_other_observation_sizes_in_one_process():
    a = agent("dqn", Extra(gym.make("CartPole-v1"), 1)).learn(300)
    b = agent("dqn", Extra(gym.make("CartPole-v1"), 2)).learn(300)
    assert a.env_id != b.env_id
    assert params(a)["fc1.weight"].shape == (64, 5) and params(b)["fc1.weight"].shape == (64, 6)
    assert a.predict(np.zeros(5))[0] in (0, 1) and b.predict(np.zeros(6))[0] in (0, 1)


class Walk(gym.Env):
    """An unregistered environment that never ends by itself: reward 1 per step. With `max_steps` it truncates
    itself there (as MiniGrid's environments do)."""

    def __init__(self, max_steps=None):
        self.observation_space = gym.spaces.Box(-1, 1, (2,), np.float32)
        self.action_space = gym.spaces.Discrete(2)
        if max_steps is not None:
            self.max_steps = max_steps
        self.t = 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return np.zeros(2, np.float32), {}

    def step(self, action):
        self.t += 1
        truncated = getattr(self, "max_steps", None) is not None and self.t >= self.max_steps
        return np.zeros(2, np.float32), 1.0, False, truncated, {}


def test_time_limits_of_unregistered_environments_are_honoured():
    with pytest.raises(ValueError, match="no time limit.*max_episode_steps"):
        arld.Agent("dqn", Walk())
    for env, kw, limit in ((gym.wrappers.TimeLimit(Walk(), 30), {}, 30), (Walk(max_steps=20), {}, 20),
                           (Walk(), dict(max_episode_steps=40), 40)):
        model = arld.Agent("dqn", env, seed=0, eval_period=100, eval_episodes=2, **kw).learn(100)
        assert [e["max"] for e in model.evaluations] == [limit], (env, kw)


def test_discrete_observations_are_one_hot_as_sb3_encodes_them():
    import torch as th
    from stable_baselines3.common.preprocessing import preprocess_obs

    seen = []

    def walker(obs):
        seen.append(obs)
        return 2

    env = gym.make("FrozenLake-v1", is_slippery=False)
    model = arld.Agent("gdqn", env, expert=walker, seed=0, eval_period=200, eval_episodes=2).learn(200)
    assert seen and all(np.ndim(o) == 0 and 0 <= int(o) < 16 for o in seen)  # the expert sees states as given
    codec = arld.envs.ObsCodec(env.observation_space, "FrozenLake-v1")
    for s in range(16):
        sb3 = preprocess_obs(th.tensor([s]), env.observation_space).numpy()[0]
        assert np.array_equal(np.asarray(codec.flat(s), np.float32), sb3)
    assert model.predict(5)[0].shape == () and model.predict(np.array([0, 5, 7]))[0].shape == (3,)
    with pytest.raises(ValueError, match="shape"):
        model.predict(np.zeros((2, 2)))


class Composite(gym.Env):
    """A Dict observation of a Box, a Discrete, a MultiDiscrete and a MultiBinary."""

    def __init__(self):
        self.observation_space = gym.spaces.Dict({
            "pos": gym.spaces.Box(-1, 1, (2,), np.float32), "mode": gym.spaces.Discrete(3),
            "grid": gym.spaces.MultiDiscrete([2, 3]), "flags": gym.spaces.MultiBinary(2)})
        self.action_space = gym.spaces.Discrete(2)
        self.spec = None

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return self.observation_space.sample(), {}

    def step(self, action):
        return self.observation_space.sample(), float(action), False, False, {}


def test_dict_and_multi_observations_are_flattened_as_sb3s_multi_input_policy_sees_them():
    import torch as th
    from stable_baselines3.common.preprocessing import preprocess_obs

    env = gym.wrappers.TimeLimit(Composite(), 25)
    codec = arld.envs.ObsCodec(env.observation_space, "Composite")
    space = env.observation_space
    space.seed(1)
    for _ in range(20):
        obs = space.sample()
        tensors = {k: th.as_tensor(np.asarray(v))[None] for k, v in obs.items()}
        sb3 = th.cat([preprocess_obs(tensors[k], s).float().flatten(1) for k, s in space.spaces.items()], 1)
        assert np.array_equal(np.asarray(codec.flat(obs), np.float32), sb3.numpy()[0])
    seen = []
    model = arld.Agent("gdqn", env, expert=lambda o: seen.append(o) or 1, seed=0, eval_period=100,
                       eval_episodes=2).learn(100)
    assert seen and all(isinstance(o, dict) and set(o) == set(space.spaces) for o in seen)
    assert model.predict(space.sample())[0] in (0, 1)
    tup = gym.wrappers.TimeLimit(Composite(), 25)
    tup.observation_space = gym.spaces.Tuple((gym.spaces.Discrete(4), gym.spaces.MultiBinary(3)))
    assert arld.envs.ObsCodec(tup.observation_space, "t").flat((2, np.array([1, 0, 1], np.int8))) == [
        0, 0, 1, 0, 1, 0, 1]
    images = gym.wrappers.TimeLimit(Composite(), 25)
    images.observation_space = gym.spaces.Dict({"camera": gym.spaces.Box(0, 255, (32, 32, 3), np.uint8)})
    with pytest.raises(ValueError, match=r"\['camera'\] are images.*FlattenObservation"):
        arld.Agent("dqn", images)


def test_arld_make_is_a_gymnasium_env_that_sb3_and_wrappers_accept():
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3 import DQN
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = arld.make("CartPole-v1")
    assert isinstance(env, gym.Env) and env.unwrapped is env and env.spec.id == "CartPole-v1"
    assert env.spec.max_episode_steps == 500 and env.render() is None
    check_env(env, skip_render_check=True)
    sb3_check_env(arld.make("CartPole-v1"))
    copy = pickle.loads(pickle.dumps(env))
    assert copy.id == "CartPole-v1" and np.array_equal(copy.reset(seed=4)[0], gym.make("CartPole-v1").reset(
        seed=4)[0])
    DQN("MlpPolicy", arld.make("CartPole-v1"), learning_starts=50, seed=0).learn(100)
    limited = gym.wrappers.TimeLimit(arld.make("CartPole-v1"), 50)
    model = arld.Agent("dqn", limited, seed=0, eval_period=200, eval_episodes=2).learn(200)
    assert all(e["max"] <= 50 for e in model.evaluations)


def test_continuing_a_loaded_run_in_its_log_dir_keeps_its_records(tmp_path):
    first = agent()
    first.learn(800, log_dir=tmp_path / "run")
    first.save(tmp_path / "snap.arld")
    first.close()  # its run holds the directory until then
    loaded = arld.Agent.load(tmp_path / "snap.arld", gym.make("CartPole-v1"), expert=expert)
    loaded.learn(700, log_dir=tmp_path / "run", reset_num_timesteps=False)
    agent().learn(1500, log_dir=tmp_path / "whole")
    for f in ("queries.csv", "eval.csv", "episodes.csv"):
        assert (tmp_path / "run" / f).read_bytes() == (tmp_path / "whole" / f).read_bytes(), f


def test_seed_none_draws_a_seed_and_parameters_set_back_are_the_same_network():
    drawn = arld.Agent("dqn", gym.make("CartPole-v1"), seed=None)
    assert isinstance(drawn.seed, int) and drawn.config["seed"] == drawn.seed
    model = agent().learn(600)
    other = agent().learn(300)
    other.set_parameters(model.get_parameters())
    assert same_params(params(other), params(model))
    assert np.array_equal(other.predict(OBS)[0], model.predict(OBS)[0])


def test_verbose_with_no_evaluation_yet_and_bad_observations_for_predict(capsys):
    agent(verbose=1).learn(100)
    assert "last evaluation none yet" in capsys.readouterr().out
    model = agent().learn(100)
    for bad in (np.zeros((2, 2)), np.zeros((1, 1, 4)), np.array([0.0, np.nan, 0.0, 0.0])):
        with pytest.raises(ValueError, match="shape|NaN"):
            model.predict(bad)


def test_a_loaded_agent_has_the_queries_of_the_agent_that_saved_it(tmp_path):
    first = agent().learn(200)
    assert len(first.queries) > 5
    first.save(tmp_path / "snap.arld")
    loaded = arld.Agent.load(tmp_path / "snap.arld", gym.make("CartPole-v1"), expert=expert)
    assert loaded.queries == first.queries and loaded.evaluations == first.evaluations
    loaded.learn(1300, reset_num_timesteps=False)
    whole = agent().learn(1500)
    assert loaded.queries == whole.queries and len(whole.queries) > len(first.queries)


ARLD = Path(__file__).resolve().parents[2] / "target" / "release" / "arld"


def test_a_run_directory_holds_one_run_at_a_time(tmp_path):
    run = tmp_path / "run"
    first = agent().learn(600, log_dir=run)
    holder = json.loads((run / ".arld.lock").read_text())
    assert holder["pid"] == os.getpid()
    second = agent()
    with pytest.raises(RuntimeError, match=rf"close\(\).*process {os.getpid()} on host"):
        second.learn(300, log_dir=run)
    assert not (tmp_path / "run" / "snapshot.safetensors").exists()
    if ARLD.is_file():  # the command line is refused too, naming this process
        out = subprocess.run([str(ARLD), "train", "--env", "CartPole-v1", "--method", "dqn", "--quiet",
                              "--overwrite", "-o", str(run)], capture_output=True, text=True)
        assert out.returncode != 0 and f"process {os.getpid()} on host" in out.stderr, out.stderr
    queries = list(first.queries)
    first.close()
    assert not (run / ".arld.lock").exists()
    # Closed, the agent keeps its run: it predicts, and continues as if it had not been closed.
    assert first.queries == queries and first.predict(OBS[0])[0] in (0, 1)
    first.learn(900, reset_num_timesteps=False)
    whole = agent().learn(1500)
    assert first.queries == whole.queries and first.evaluations == whole.evaluations
    assert same_params(params(first), params(whole))
    # The directory is free: the second agent's run takes it.
    second.learn(300, log_dir=run)
    assert json.loads((run / ".arld.lock").read_text())["pid"] == os.getpid()
    second.close()
    if ARLD.is_file():
        out = subprocess.run([str(ARLD), "train", "--env", "CartPole-v0", "--method", "dqn", "--quiet",
                              "--set", "train_steps=200", "--overwrite", "-o", str(run)],
                             capture_output=True, text=True)
        assert out.returncode == 0, out.stderr


class Flaky(gym.Wrapper):
    """Raises once: at its `fail_step`-th step (before stepping), or at its `fail_reset`-th reset."""

    def __init__(self, env, fail_step=None, fail_reset=None):
        super().__init__(env)
        self.steps, self.resets, self.fail_step, self.fail_reset = 0, 0, fail_step, fail_reset

    def step(self, action):
        self.steps += 1
        if self.steps == self.fail_step:
            raise OSError("the simulator dropped the connection")
        return self.env.step(action)

    def reset(self, **kwargs):
        self.resets += 1
        if self.resets == self.fail_reset:
            raise OSError("the simulator could not restart")
        return self.env.reset(**kwargs)


@pytest.mark.parametrize("where", ["step", "reset"])
def test_an_exception_from_the_environment_pauses_the_run_whole_and_it_goes_on_as_if_not(tmp_path, where):
    fail = {"fail_step": 450} if where == "step" else {"fail_reset": 20}
    model = agent(env=Flaky(gym.make("CartPole-v1"), **fail), eval_env=gym.make("CartPole-v1"))
    run = tmp_path / "run"
    with pytest.raises(OSError, match="the simulator") as info:
        model.learn(1500, log_dir=run)
    if sys.version_info >= (3, 11):
        notes = " ".join(info.value.__notes__)
        assert "paused whole" in notes and "snapshot.safetensors" in notes
    paused_at = model.num_timesteps
    assert 0 < paused_at < 1500
    # The logs are whole (every line ended) and the snapshot is there.
    for f in ("queries.csv", "episodes.csv"):
        assert (run / f).read_bytes().endswith(b"\n"), f
    shutil.copy(run / "snapshot.safetensors", tmp_path / "at-exception.arld")
    queries_then = list(model.queries)
    model.learn(1500 - paused_at, reset_num_timesteps=False)
    whole = agent(eval_env=gym.make("CartPole-v1")).learn(1500, log_dir=tmp_path / "whole")
    assert model.queries == whole.queries and model.evaluations == whole.evaluations
    assert same_params(params(model), params(whole))
    for f in ("queries.csv", "eval.csv", "episodes.csv"):
        assert (run / f).read_bytes() == (tmp_path / "whole" / f).read_bytes(), f
    # Another process continues from the snapshot written at the exception: the same run again.
    loaded = arld.Agent.load(tmp_path / "at-exception.arld", gym.make("CartPole-v1"), expert=expert,
                             eval_env=gym.make("CartPole-v1"))
    assert loaded.queries == queries_then
    loaded.learn(1500 - paused_at, reset_num_timesteps=False)
    assert loaded.queries == whole.queries and same_params(params(loaded), params(whole))
