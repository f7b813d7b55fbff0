"""What a Stable-Baselines3 user relies on, checked against the real Stable-Baselines3 (its callbacks, its logger
from `configure`, Monitor and `evaluate_policy`): a second learn keeps the network, load applies its keywords,
callbacks see the step, SB3's logger gets the run's values, SB3's attributes, set_parameters, copies and pickles,
a Box expert's answer outside the box, and the built-in continuous tasks."""

import copy
import csv
import pickle
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest

import arld

sb3 = pytest.importorskip("stable_baselines3")
from stable_baselines3 import DQN  # noqa: E402
from stable_baselines3.common.callbacks import BaseCallback, CheckpointCallback  # noqa: E402
from stable_baselines3.common.evaluation import evaluate_policy  # noqa: E402
from stable_baselines3.common.logger import configure  # noqa: E402
from stable_baselines3.common.monitor import Monitor  # noqa: E402
from stable_baselines3.common.vec_env import DummyVecEnv  # noqa: E402

OBS = np.random.default_rng(1).normal(size=(32, 4)).astype(np.float32)


def expert(obs):
    """A CartPole controller written here (module level, so that it pickles)."""
    return int(obs[2] + 0.5 * obs[3] > 0)


def cartpole(method="dqn", env=None, **kw):
    env = gym.make("CartPole-v1") if env is None else env
    kw = {"learning_starts": 100, "eval_period": 100_000, "eval_episodes": 2, **kw}
    return arld.Agent(method, env, net="plain", expert=None if method == "dqn" else expert, seed=0, **kw)


def weights(model):
    return model.get_parameters()["policy"]


def same(a, b):
    return a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)


def evaluate(model, episodes=10):
    """SB3's evaluate_policy on Monitor-wrapped CartPole episodes from seed 0 (the same episodes every time)."""
    venv = DummyVecEnv([lambda: Monitor(gym.make("CartPole-v1"))])
    venv.seed(0)
    return evaluate_policy(model, venv, n_eval_episodes=episodes)[0]


def sb3_weights(model):
    return {k: v.detach().numpy().copy() for k, v in model.policy.state_dict().items()}


# --- 1. a second learn keeps the network


def test_sb3_keeps_the_weights_over_a_second_learn_and_arld_does_too(tmp_path):
    # SB3 itself: a second learn with reset_num_timesteps=True restarts the counters, not the network (one step
    # before learning_starts trains nothing, so the weights are exactly those the first learn left).
    ref = DQN("MlpPolicy", "CartPole-v1", learning_starts=100, train_freq=1, seed=0)
    ref.learn(300)
    before = sb3_weights(ref)
    ref.learn(1)
    assert ref.num_timesteps == 1 and same(sb3_weights(ref), before)

    model = cartpole(learning_rate=1e-3, train_steps=4000, exploration_fraction=0.5).learn(4000)
    trained = evaluate(model)
    before = weights(model)
    model.learn(1)
    assert model.num_timesteps == 1 and same(weights(model), before)
    assert model.exploration_rate == pytest.approx(model.config["eps_start"], abs=1e-3)  # the schedule restarts
    again = evaluate(model)
    assert again == trained and trained > 100
    # The new run trains on from those weights: a fresh agent learning the same 300 steps ends elsewhere.
    model.learn(300)
    assert not same(weights(model), before)
    assert not same(weights(model), weights(cartpole(learning_rate=1e-3).learn(300)))
    # So does an agent from Agent.load: learn(n) keeps the saved network.
    model.save(tmp_path / "m.zip")
    loaded = arld.Agent.load(tmp_path / "m.zip", gym.make("CartPole-v1"))
    loaded.learn(1)
    assert loaded.num_timesteps == 1 and same(weights(loaded), weights(model))


def test_learn_in_stretches_still_equals_one_learn():
    one = cartpole(train_steps=1200).learn(1200)
    two = cartpole(train_steps=1200).learn(500)
    two.learn(700, reset_num_timesteps=False)
    assert two.num_timesteps == 1200 and same(weights(two), weights(one))


# --- 2. Agent.load applies its keywords


def test_load_applies_keywords_and_custom_objects_as_sb3_does(tmp_path):
    # SB3 sets load's keywords on the loaded model.
    DQN("MlpPolicy", "CartPole-v1", learning_rate=1e-4).save(tmp_path / "sb3.zip")
    assert DQN.load(tmp_path / "sb3.zip", learning_rate=0.5).learning_rate == 0.5
    assert DQN.load(tmp_path / "sb3.zip", custom_objects={"learning_rate": 0.25}).learning_rate == 0.25

    cartpole(learning_rate=1e-4).learn(300).save(tmp_path / "run.zip")
    loaded = arld.Agent.load(tmp_path / "run.zip", gym.make("CartPole-v1"), learning_rate=0.5, gamma=0.9)
    assert (loaded.learning_rate, loaded.gamma) == (0.5, 0.9)
    loaded.learn(200, log_dir=tmp_path / "new")
    assert "lr = 0.5" in (tmp_path / "new" / "config.toml").read_text()
    custom = arld.Agent.load(tmp_path / "run.zip", gym.make("CartPole-v1"),
                             custom_objects={"learning_rate": 0.25, "lr_schedule": lambda _: 0.0})
    assert custom.learning_rate == 0.25
    # Without keywords the saved values stand.
    assert arld.Agent.load(tmp_path / "run.zip", gym.make("CartPole-v1")).learning_rate == 1e-4
    # What cannot change is refused, naming it.
    with pytest.raises(ValueError, match="reset_num_timesteps"):
        arld.Agent.load(tmp_path / "run.zip", gym.make("CartPole-v1"), learning_rate=0.5).learn(
            10, reset_num_timesteps=False)
    with pytest.raises(ValueError, match="hidden cannot change"):
        arld.Agent.load(tmp_path / "run.zip", gym.make("CartPole-v1"), policy_kwargs=dict(net_arch=[32]))
    with pytest.raises(TypeError, match="did you mean 'learning_rate'"):
        arld.Agent.load(tmp_path / "run.zip", gym.make("CartPole-v1"), learning_rat=0.5)  # type: ignore[call-arg]
    with pytest.raises(ValueError, match="CPU"):
        arld.Agent.load(tmp_path / "run.zip", gym.make("CartPole-v1"), device="cuda")


def test_a_loaded_dqfd_run_given_its_demos_again_starts_a_new_run(tmp_path):
    demos = arld.collect_demos(gym.make("CartPole-v1"), expert, 200, seed=0)
    arld.Agent("dqfd", gym.make("CartPole-v1"), demos=demos, seed=0, pretrain_steps=20, learning_starts=50,
               eval_period=100_000, eval_episodes=1).learn(100).save(tmp_path / "dqfd.zip")
    with pytest.raises(RuntimeError, match="same demos="):
        arld.Agent.load(tmp_path / "dqfd.zip", gym.make("CartPole-v1")).learn(20)
    loaded = arld.Agent.load(tmp_path / "dqfd.zip", gym.make("CartPole-v1"), demos=demos)
    assert loaded.learn(20).num_timesteps == 20


# --- 3. callbacks see the step


class MonitorEpisodes(BaseCallback):
    """Counts Monitor's episodes in the locals, as an SB3 user's callback does, and checks the locals' shapes."""

    def __init__(self):
        super().__init__()
        self.returns, self.rewards, self.shapes = [], 0.0, set()

    def _on_step(self):
        loc = self.locals
        self.shapes.add((loc["actions"].shape, loc["rewards"].shape, loc["dones"].shape, loc["new_obs"].shape))
        self.rewards += float(loc["rewards"][0])
        for info in loc["infos"]:
            if "episode" in info:
                assert loc["dones"][0] and "terminal_observation" in info
                self.returns.append(info["episode"]["r"])
        return True


def test_callbacks_see_monitors_episodes_rewards_actions_and_observations():
    env = Monitor(gym.make("CartPole-v1"))
    counter = MonitorEpisodes()
    cartpole(env=env).learn(1000, callback=counter)
    # Monitor's own record of the training episodes (its copies ran the test episodes).
    assert len(counter.returns) == len(env.get_episode_rewards()) > 10
    assert counter.returns == pytest.approx(env.get_episode_rewards())
    # Every step's reward: the finished episodes' and the one in progress (CartPole pays 1 a step).
    assert counter.rewards == pytest.approx(sum(env.get_episode_rewards()) + len(env.rewards))
    assert counter.shapes == {((1,), (1,), (1,), (1, 4))}


def test_the_built_in_task_trained_in_rust_gives_the_locals_too():
    counter = MonitorEpisodes()
    seen = []

    def probe(loc, _globals):
        seen.append((int(loc["actions"][0]), float(loc["rewards"][0]), bool(loc["dones"][0])))
        return True

    cartpole(env=arld.make("CartPole-v1")).learn(300, callback=[counter, probe])
    assert counter.shapes == {((1,), (1,), (1,), (1, 4))} and counter.returns == []  # no Monitor: no "episode"
    assert {a for a, _, _ in seen} == {0, 1} and all(r == 1.0 for _, r, _ in seen) and any(d for _, _, d in seen)


# --- 4. SB3's logger


def test_sb3_logger_gets_callbacks_records_and_the_runs_values(tmp_path):
    env = Monitor(gym.make("CartPole-v1"))
    model = cartpole(env=env)
    model.set_logger(configure(str(tmp_path), ["csv"]))

    class Record(BaseCallback):
        def _on_step(self):
            self.logger.record("custom/steps", self.num_timesteps)
            return True

    model.learn(1200, callback=Record(), log_interval=3)
    with open(tmp_path / "progress.csv") as f:
        rows = list(csv.DictReader(f))
    episodes = env.get_episode_rewards()
    assert len(rows) == len(episodes) // 3 > 3
    for i, row in enumerate(rows, start=1):
        done = episodes[:3 * i]
        assert int(row["time/episodes"]) == 3 * i
        # SB3's ep_rew_mean: the mean of the last 100 episodes Monitor saw, computed here from Monitor's record.
        assert float(row["rollout/ep_rew_mean"]) == pytest.approx(np.mean(done[-100:]))
        assert int(row["time/total_timesteps"]) == sum(env.get_episode_lengths()[:3 * i])
        assert int(row["custom/steps"]) == int(row["time/total_timesteps"])
        assert 0 < float(row["rollout/exploration_rate"]) <= 1
    assert model.logger.name_to_value == {} or "custom/steps" in model.logger.name_to_value


# --- 5. SB3's attributes


def test_sb3_attributes_policy_hyperparameters_device_replay_and_seed(tmp_path):
    model = cartpole(learning_rate=3e-4, gamma=0.95, batch_size=16, buffer_size=5000).learn(300)
    assert (model.learning_rate, model.gamma, model.batch_size, model.buffer_size) == (3e-4, 0.95, 16, 5000)
    assert model.device == "cpu"
    assert np.array_equal(model.policy.predict(OBS)[0], model.predict(OBS)[0])
    assert same(model.policy.state_dict(), weights(model))
    assert evaluate(model.policy, 3) == evaluate(model, 3)
    with pytest.raises(AttributeError, match="save"):
        _ = model.replay_buffer
    # SB3's CheckpointCallback with save_replay_buffer=True writes the run (which holds the replay) and goes on.
    model.learn(200, callback=CheckpointCallback(100, str(tmp_path), save_replay_buffer=True))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rl_model_100_steps.zip", "rl_model_200_steps.zip"]
    # A hyperparameter set now applies to the next new run.
    model.learning_rate = 1e-2
    with pytest.raises(ValueError, match="learning_rate=0.01"):
        model.learn(10, reset_num_timesteps=False)
    model.learn(10, log_dir=tmp_path / "next")
    assert "lr = 0.01" in (tmp_path / "next" / "config.toml").read_text()
    # set_random_seed: the next run draws from that seed.
    seeded = cartpole()
    seeded.set_random_seed(5)
    other = arld.Agent("dqn", gym.make("CartPole-v1"), net="plain", seed=5, learning_starts=100,
                       eval_period=100_000, eval_episodes=2)
    assert same(weights(seeded.learn(300)), weights(other.learn(300)))


# --- 6. set_parameters


def test_set_parameters_from_a_saved_agent_a_partial_dict_and_on_a_fresh_agent(tmp_path):
    trained = cartpole().learn(400)
    trained.save(tmp_path / "full.zip")
    other = cartpole()
    other.set_parameters(str(tmp_path / "full.zip"))
    assert same(weights(other), weights(trained))
    # A fresh agent takes another's parameters before learning; its first run trains from them.
    fresh = cartpole()
    fresh.set_parameters(trained.get_parameters())
    assert np.array_equal(fresh.predict(OBS)[0], trained.predict(OBS)[0])
    fresh.learn(1)
    assert same(weights(fresh), weights(trained))
    # exact_match=False: the weights given, the others kept; exact_match=True names what is missing.
    target = cartpole().learn(200)
    kept = weights(target)
    part = {"policy": {k: v for k, v in weights(trained).items() if k.startswith("fc2")}}
    assert part["policy"] and len(part["policy"]) < len(kept)
    with pytest.raises(ValueError, match="missing: .*fc1"):
        target.set_parameters(part)
    target.set_parameters(part, exact_match=False)
    now = weights(target)
    assert all(np.array_equal(now[k], weights(trained)[k] if k.startswith("fc2") else kept[k]) for k in now)
    with pytest.raises(ValueError, match="shape"):
        target.set_parameters({"policy": {k: v[:1] for k, v in part["policy"].items()}}, exact_match=False)


# --- 7. copies and pickles


def test_deepcopy_and_pickle_of_a_trained_agent_stand_where_it_stood():
    model = arld.Agent("adqn", gym.make("CartPole-v1"), net="bootstrap", expert=expert, seed=0, learning_starts=100,
                       eval_period=300, eval_episodes=2, budget=50, train_steps=900).learn(500)
    copied = copy.deepcopy(model)
    pickled = pickle.loads(pickle.dumps(model))
    for twin in (copied, pickled):
        assert twin.num_timesteps == 500 and twin.evaluations == model.evaluations
        assert twin.queries == model.queries and np.array_equal(twin.predict(OBS)[0], model.predict(OBS)[0])
    model.learn(400, reset_num_timesteps=False)
    for twin in (copied, pickled):
        twin.learn(400, reset_num_timesteps=False)
        assert same(weights(twin), weights(model)) and twin.queries == model.queries
    # An expert that does not pickle (a lambda): the error points to save and load.
    with pytest.raises(TypeError, match="Agent.load"):
        pickle.dumps(arld.Agent("gdqn", gym.make("CartPole-v1"), expert=lambda o: 0).learn(50))
    # An untrained agent copies too.
    assert copy.deepcopy(cartpole()).learn(200).num_timesteps == 200


# --- 8. a Box expert's answer outside the box


def test_a_box_experts_answer_outside_the_bounds_is_refused():
    model = arld.Agent("gdqn", gym.make("Pendulum-v1"), expert=lambda o: np.array([5.0], np.float32), seed=0,
                       n_step=1, heads=2, eval_episodes=1, learning_starts=50, budget=20)
    with pytest.raises(ValueError, match=r"answered \[5\.0\]: dimension 0 of Pendulum-v1's actions lies in \[-2, 2\]"):
        model.learn(300)


# --- 9. the built-in continuous tasks, and typed keywords


def test_arld_make_knows_the_continuous_tasks():
    for env_id, dim in (("Pendulum-v1", 1), ("MountainCarContinuous-v0", 1), ("LunarLanderContinuous-v3", 2)):
        env = arld.make(env_id)
        assert isinstance(env.action_space, gym.spaces.Box) and env.action_space.shape == (dim,)
    ours, theirs = arld.make("Pendulum-v1"), gym.make("Pendulum-v1")
    assert ours.action_space == theirs.action_space
    o, _ = ours.reset(seed=3)
    t, _ = theirs.reset(seed=3)
    for _ in range(50):
        assert np.allclose(o, t, atol=1e-5)
        o, r1, *_ = ours.step(np.array([0.7], np.float32))
        t, r2, *_ = theirs.step(np.array([0.7], np.float32))
        assert r1 == pytest.approx(r2, abs=1e-4)
    model = arld.Agent("dqn", arld.make("Pendulum-v1"), seed=0, n_step=1, heads=2, eval_episodes=1,
                       learning_starts=100, eval_period=300).learn(300)
    assert model.predict(o)[0].shape == (1,) and len(model.evaluations) == 1


def test_mypy_catches_misspelt_keywords(tmp_path):
    wrong = tmp_path / "wrong.py"
    wrong.write_text(
        "import arld\n"
        "arld.Agent('dqn', 'CartPole-v1', learning_rat=1e-3)\n"
        "arld.Agent.load('x.zip', learning_rat=1e-3)\n"
        "arld.Agent('dqn', 'CartPole-v1', learning_rate=1e-3, replay_size=500, lambda_margin=1.0)\n"
    )
    out = subprocess.run([sys.executable, "-m", "mypy", "--strict", str(wrong)], capture_output=True, text=True)
    lines = [line for line in out.stdout.splitlines() if ": error:" in line]
    assert [line.split(":")[1] for line in lines] == ["2", "3"], out.stdout
    assert all("learning_rat" in line for line in lines), out.stdout
