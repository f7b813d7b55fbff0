"""Gymnasium environments with a `Box` action space: TD3 learns them through `arld.Agent` with the habits of the
discrete tasks (`predict` in the space's shape, SB3 models and callables as experts, learn in stretches, save and
load of the whole run), Gymnasium's own Pendulum-v1 learns from a Stable-Baselines3 TD3 model as the expert, and a
MuJoCo task (InvertedPendulum-v5) runs with a scripted expert."""

import json
import math

import gymnasium as gym
import numpy as np
import pytest

import arld

# TD3's settings that learn Pendulum-v1 (one-step returns, two critic heads), small enough for a test.
TD3 = dict(n_step=1, heads=2, eval_episodes=3)


def swing_up(obs):
    """An energy-based swing-up with a PD balance near the top (written here, independently of arld's)."""
    cos, sin, thdot = (float(v) for v in obs)
    theta = math.atan2(sin, cos)
    if cos > 0.8:
        u = -10.0 * theta - 2.0 * thdot
    else:
        energy = 0.5 * thdot**2 + 10.0 * (cos - 1.0)
        u = -2.0 * energy * (1.0 if thdot * cos >= 0 else -1.0)
    return np.array([min(2.0, max(-2.0, u))], dtype=np.float32)


def returns(policy, seeds, env_id="Pendulum-v1"):
    """Returns of `policy` (obs -> action) on Gymnasium's own environment, one episode per seed."""
    env = gym.make(env_id)
    out = []
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        total, done = 0.0, False
        while not done:
            obs, r, te, tr, _ = env.step(policy(obs))
            total += float(r)
            done = te or tr
        out.append(total)
    return out


def answers(run_dir):
    with open(run_dir / "answers.jsonl") as f:
        return [json.loads(line) for line in f]


@pytest.fixture(scope="module")
def sb3_td3():
    """A Stable-Baselines3 TD3 model trained briefly on Pendulum-v1 (8,000 steps: about three minutes on one
    busy core)."""
    import torch
    from stable_baselines3 import TD3 as SB3TD3
    from stable_baselines3.common.noise import NormalActionNoise

    torch.set_num_threads(1)
    model = SB3TD3("MlpPolicy", gym.make("Pendulum-v1"), learning_rate=1e-3, learning_starts=1000, batch_size=128,
                   policy_kwargs=dict(net_arch=[64, 64]), action_noise=NormalActionNoise(np.zeros(1), 0.1 * np.ones(1)),
                   seed=0)
    model.learn(8000)
    return model


def test_pendulum_with_an_sb3_td3_model_as_the_expert_learns(tmp_path, sb3_td3):
    seeds = range(100, 110)
    expert_score = np.mean(returns(lambda o: sb3_td3.predict(o, deterministic=True)[0], seeds))
    assert expert_score > -400, f"the SB3 expert itself did not learn Pendulum-v1: {expert_score:.0f}"

    untrained = arld.Agent("dqn", gym.make("Pendulum-v1"), seed=5, **TD3).learn(1)
    trained = arld.Agent("adqn", gym.make("Pendulum-v1"), expert=sb3_td3, seed=5, train_steps=12000, budget=1500,
                         eval_period=2000, batch_size=128, **TD3)
    trained.learn(12000, log_dir=tmp_path / "run")

    # predict: the space's shape and dtype, one observation or a batch.
    action, state = trained.predict(np.zeros(3, dtype=np.float32))
    assert state is None and action.shape == (1,) and action.dtype == np.float32
    assert -2.0 <= float(action[0]) <= 2.0
    batch, _ = trained.predict(np.zeros((4, 3), dtype=np.float32))
    assert batch.shape == (4, 1) and np.array_equal(batch[0], action)

    before = np.mean(returns(lambda o: untrained.predict(o)[0], seeds))
    after = np.mean(returns(lambda o: trained.predict(o)[0], seeds))
    print(f"Pendulum-v1 from Gymnasium: untrained {before:.0f}, trained with the SB3 TD3 expert {after:.0f} "
          f"(expert {expert_score:.0f}), {trained.summary['demos_queried']} expert steps")
    assert after > before + 500 and after > -400, (before, after)
    # The run's own last evaluation agrees that it learned.
    assert trained.evaluations[-1]["step"] == 12000 and trained.evaluations[-1]["mean"] > -400

    # The expert was asked, within the budget, and answered what the SB3 model answers at each observation.
    asked = answers(tmp_path / "run")
    assert 0 < len(asked) == trained.summary["demos_queried"] <= 1500
    for step in asked[:50]:
        expected, _ = sb3_td3.predict(np.asarray(step["obs"], dtype=np.float32), deterministic=True)
        assert np.allclose(step["action"], expected, atol=1e-6), step
    queries = trained.queries
    assert queries and all(len(q["agent_action"]) == 1 for q in queries)
    assert all(q["expert_action"] is None or -2.0 <= q["expert_action"][0] <= 2.0 for q in queries)


def test_callables_sb3_models_and_agents_answer_in_the_space(tmp_path):
    from stable_baselines3 import SAC

    sac = SAC("MlpPolicy", gym.make("Pendulum-v1"), seed=1, policy_kwargs=dict(net_arch=[16, 16]))
    for name, expert in (("callable", swing_up), ("sac", sac)):
        model = arld.Agent("gdqn", gym.make("Pendulum-v1"), expert=expert, seed=3, train_steps=1200, budget=40,
                           eval_period=600, learning_starts=200, **TD3)
        model.learn(1200, log_dir=tmp_path / name)
        asked = answers(tmp_path / name)
        assert len(asked) == model.summary["demos_queried"] > 0
        for step in asked:
            obs = np.asarray(step["obs"], dtype=np.float32)
            expected = swing_up(obs) if name == "callable" else sac.predict(obs, deterministic=True)[0]
            assert np.allclose(step["action"], expected, atol=1e-6), (name, step)
        assert model.summary["expert"].startswith("python:")
    # An answer of the wrong shape is refused, naming the shape.
    bad = arld.Agent("gdqn", gym.make("Pendulum-v1"), expert=lambda obs: np.zeros(2), seed=3, learning_starts=10,
                     **TD3)
    with pytest.raises(TypeError, match=r"shape \(1,\)"):
        bad.learn(200)


def test_box_runs_learn_in_stretches_and_save_and_load_whole(tmp_path):
    def agent():
        return arld.Agent("adqn", gym.make("Pendulum-v1"), expert=swing_up, seed=7, train_steps=1600, budget=100,
                          eval_period=400, learning_starts=300, **TD3)

    one = agent().learn(1600)
    two = agent().learn(700)
    two.save(tmp_path / "half.arld")
    loaded = arld.Agent.load(tmp_path / "half.arld", env=gym.make("Pendulum-v1"), expert=swing_up)
    two.learn(900, reset_num_timesteps=False)
    loaded.learn(900, reset_num_timesteps=False)
    obs = np.random.default_rng(0).uniform(-1, 1, (20, 3)).astype(np.float32)
    for other in (two, loaded):
        assert other.evaluations == one.evaluations
        assert other.queries == one.queries
        assert other.summary["demos_queried"] == one.summary["demos_queried"]
        assert np.array_equal(other.predict(obs)[0], one.predict(obs)[0])
    assert len(one.evaluations) == 4 and one.queries


def test_box_spaces_of_more_dimensions_and_refusals():
    class Plane(gym.Env):
        """A point pushed in the plane by a (2, 1) Box action, back to the origin."""

        observation_space = gym.spaces.Box(-10, 10, (2,), np.float32)
        action_space = gym.spaces.Box(np.array([[-1.0], [-0.5]], np.float32), np.array([[1.0], [0.5]], np.float32))

        def reset(self, *, seed=None, options=None):
            super().reset(seed=seed)
            self.p = self.np_random.uniform(-1, 1, 2).astype(np.float32)
            return self.p.copy(), {}

        def step(self, action):
            assert action.shape == (2, 1) and action.dtype == np.float32
            self.p = np.clip(self.p + 0.1 * action.reshape(2), -10, 10).astype(np.float32)
            return self.p.copy(), -float(np.abs(self.p).sum()), False, False, {}

    def towards_origin(obs):
        return np.clip(-np.asarray(obs).reshape(2, 1), [[-1.0], [-0.5]], [[1.0], [0.5]]).astype(np.float32)

    model = arld.Agent("gdqn", Plane(), expert=towards_origin, max_episode_steps=50, seed=0, learning_starts=50,
                       eval_period=100, **TD3)
    model.learn(200)
    assert model.env_id.startswith("Plane")
    action, _ = model.predict(np.zeros(2, dtype=np.float32))
    assert action.shape == (2, 1) and -1.0 <= action[0, 0] <= 1.0 and -0.5 <= action[1, 0] <= 0.5
    assert all(len(q["agent_action"]) == 2 for q in model.queries)

    with pytest.raises(ValueError, match="finite bounds"):
        unbounded = gym.make("Pendulum-v1")
        unbounded.action_space = gym.spaces.Box(-np.inf, np.inf, (1,), np.float32)
        arld.Agent("dqn", unbounded)


def test_box_weights_travel_like_sb3_parameters(tmp_path):
    """get_parameters/set_parameters and weights files for a TD3 actor: another agent given the weights acts as
    the trained one, a run's weights.safetensors loads as an acting agent (and as a checkpoint expert of the
    same numbers), and weights for another box are refused."""
    trained = arld.Agent("dqn", gym.make("Pendulum-v1"), seed=4, learning_starts=200, eval_period=500, **TD3)
    trained.learn(600, log_dir=tmp_path / "run")
    obs = np.random.default_rng(1).uniform(-1, 1, (16, 3)).astype(np.float32)
    acted = trained.predict(obs)[0]
    params = trained.get_parameters()
    assert set(params["policy"]) == {"actor.params"}
    # 3 -> 64 -> 64 -> 1 with biases.
    assert params["policy"]["actor.params"].shape == (3 * 64 + 64 + 64 * 64 + 64 + 64 + 1,)

    other = arld.Agent("dqn", gym.make("Pendulum-v1"), seed=99, learning_starts=50, **TD3).learn(60)
    assert not np.array_equal(other.predict(obs)[0], acted)
    other.set_parameters(params)
    assert np.array_equal(other.predict(obs)[0], acted)

    # The run's weights file: an agent that acts, and the actor computed here from the flat parameters.
    loaded = arld.Agent.load(tmp_path / "run" / "weights.safetensors", env=gym.make("Pendulum-v1"))
    assert np.array_equal(loaded.predict(obs)[0], acted)
    flat, layers, at = params["policy"]["actor.params"], [(3, 64), (64, 64), (64, 1)], 0
    h = obs.astype(np.float64)
    for i, (n_in, n_out) in enumerate(layers):
        w = flat[at:at + n_in * n_out].reshape(n_in, n_out)
        b = flat[at + n_in * n_out:at + n_in * n_out + n_out]
        at += n_in * n_out + n_out
        h = h @ w + b
        h = np.maximum(h, 0.0) if i < len(layers) - 1 else np.tanh(h)
    assert np.allclose(-2.0 + (h + 1.0) * 2.0, acted, atol=1e-5)
    loaded.save(tmp_path / "again.safetensors")
    assert np.array_equal(arld.Agent.load(tmp_path / "again.safetensors").predict(obs)[0], acted)

    with pytest.raises(ValueError, match="Box of 1 dimensions"):
        arld.Agent.load(tmp_path / "run" / "weights.safetensors", env=gym.make("CartPole-v1"))
    arld.Agent("dqn", gym.make("CartPole-v1"), seed=0, learning_starts=50).learn(60, log_dir=tmp_path / "cartpole")
    with pytest.raises(ValueError, match="another observation size"):
        other.set_parameters(tmp_path / "cartpole" / "weights.safetensors")


def test_a_mujoco_task_runs_with_a_scripted_expert(tmp_path):
    try:
        import mujoco  # noqa: F401
    except ImportError as e:
        pytest.fail(f"gymnasium[mujoco] is not installed ({e}); scripts/test installs it with pip install "
                    "'gymnasium[mujoco]' (it needs the mujoco wheel for this platform)")

    def balance(obs):
        """PD on the pole's angle and angular velocity, with a little pull of the cart to the centre."""
        x, angle, x_dot, angle_dot = (float(v) for v in obs)
        return np.array([np.clip(x + 10.0 * angle + 0.5 * x_dot + angle_dot, -3.0, 3.0)], dtype=np.float32)

    assert returns(balance, range(3), "InvertedPendulum-v5") == [1000.0] * 3, "the scripted expert balances"
    model = arld.Agent("adqn", gym.make("InvertedPendulum-v5"), expert=balance, seed=0, train_steps=1500,
                       budget=300, eval_period=500, learning_starts=300, eval_episodes=2, n_step=1, heads=2)
    model.learn(1500, log_dir=tmp_path / "run")
    assert model.env_id == "InvertedPendulum-v5" and model.summary["train_steps"] == 1500
    assert [e["step"] for e in model.evaluations] == [500, 1000, 1500]
    asked = answers(tmp_path / "run")
    assert 0 < len(asked) == model.summary["demos_queried"] <= 300
    for step in asked:
        assert np.allclose(step["action"], balance(step["obs"]), atol=1e-6), step
    action, _ = model.predict(np.zeros(4))
    assert action.shape == (1,) and -3.0 <= float(action[0]) <= 3.0


def imitation_error(model, states):
    """Mean |pi(s) - a_E| of the model's test actions against the swing-up's on `states`."""
    actions, _ = model.predict(np.asarray(states, dtype=np.float32))
    return float(np.mean([abs(float(a[0]) - float(swing_up(s)[0])) for a, s in zip(actions, states)]))


def test_pendulum_dqfd_pre_trains_from_a_callable_an_sb3_style_expert_and_demos(tmp_path):
    """dqfd on Gymnasium's Pendulum-v1 collects its demonstrations from a callable or from a model with SB3's
    predict, or takes them as arrays (demos=): the pre-trained actor follows the swing-up, closer than the best
    constant action and than the same agent untrained."""

    class Predicting:
        """A model with Stable-Baselines3's predict, answering the swing-up in the space's shape."""

        def predict(self, obs, deterministic=False):
            return swing_up(obs), None

    def episodes(seeds):
        """Whole episodes of the swing-up, each reset with its seed, as one dict of columns."""
        parts = [arld.collect_demos(gym.make("Pendulum-v1"), swing_up, 200, seed=s) for s in seeds]
        return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}

    def constant_error(states):
        targets = np.array([swing_up(s)[0] for s in states])
        return float(np.mean(np.abs(targets - np.median(targets))))

    # One-step returns: this is a test of cloning the demonstrations, as measured with docs/algorithm.md §17's settings.
    short = dict(pretrain_steps=2000, learning_starts=1000, eval_period=1, eval_episodes=1, seed=3, n_step=1)
    # Held-out states: the swing-up's own episodes on seeds no run uses.
    held_out = episodes(range(1000, 1003))["obs"]
    untrained = imitation_error(arld.Agent("dqn", gym.make("Pendulum-v1"), seed=3).learn(1), held_out)
    errors = {}
    for name, expert in (("callable", swing_up), ("sb3-style", Predicting())):
        model = arld.Agent("dqfd", gym.make("Pendulum-v1"), expert=expert, **short)
        model.learn(1, log_dir=tmp_path / name)
        assert model.summary["demos_pretrain"] == 1000
        errors[name] = imitation_error(model, held_out)
    print(f"Pendulum-v1 dqfd, mean |pi(s) - a_E| on held-out states: {errors}; untrained {untrained:.3f}, the "
          f"best constant {constant_error(held_out):.3f}")
    assert errors["callable"] == errors["sb3-style"], "the same expert in two forms gives the same run"
    bound = 0.8 * min(untrained, constant_error(held_out))
    assert errors["callable"] < bound, (errors, bound)

    # Demonstrations given as arrays (the actions as rows of the space's shape): the actor clones them.
    demos = episodes(range(5))
    assert demos["actions"].shape == (1000, 1) and demos["actions"].dtype == np.float32
    model = arld.Agent("dqfd", gym.make("Pendulum-v1"), demos=demos, **short)
    model.learn(1)
    assert model.summary["demos_pretrain"] == 1000 and model.config["demo_file"] == "python:demos"
    seen, constant = imitation_error(model, demos["obs"]), constant_error(demos["obs"])
    print(f"demos=: {seen:.3f} on the demonstrated states, the best constant {constant:.3f}")
    assert seen < 0.25 * constant, (seen, constant)

    # Demonstrations outside the box or of the wrong width are refused, naming the problem.
    for actions, says in ((np.full((1000, 1), 2.5, np.float32), "out of range"),
                          (np.zeros((1000, 2), np.float32), "2 values")):
        bad = dict(demos, actions=actions)
        with pytest.raises(RuntimeError, match=says):
            arld.Agent("dqfd", gym.make("Pendulum-v1"), demos=bad, **short).learn(1)


def test_pendulum_adqnp_pre_trains_then_asks_within_its_budget(tmp_path):
    model = arld.Agent("adqnp", gym.make("Pendulum-v1"), expert=swing_up, seed=2, n_demo=200, budget=100,
                       pretrain_steps=200, learning_starts=300, train_steps=1500, eval_period=500, eval_episodes=2,
                       hidden=[32, 32], batch_size=32)
    model.learn(1500, log_dir=tmp_path / "run")
    assert model.summary["demos_pretrain"] == 200 and model.summary["demos_queried"] == 100
    asked = answers(tmp_path / "run")
    assert len(asked) == 100
    for step in asked:
        assert np.allclose(step["action"], swing_up(step["obs"]), atol=1e-6), step


def test_the_uncertainty_a_box_rule_reads_is_chosen_recorded_and_refused_where_it_has_no_meaning(tmp_path):
    """`uncertainty=` chooses what ADQN's rule reads on a Box task: the critic heads' spread at the agent's action
    (the default) or their disagreement about the best action, a probe spread in half-widths (in [0, 1]). Each run
    records its choice in config.toml, and the two ask differently; a discrete task, a method that does not ask and
    an unknown name are refused, naming the key."""
    asked = {}
    for measure in ("critic_variance", "action_disagreement"):
        model = arld.Agent("adqn", gym.make("Pendulum-v1"), expert=swing_up, seed=4, uncertainty=measure, budget=150,
                           learning_starts=300, train_steps=1500, eval_period=500, hidden=[32, 32], batch_size=32,
                           **TD3)
        model.learn(1500, log_dir=tmp_path / measure)
        config = (tmp_path / measure / "config.toml").read_text()
        assert f'uncertainty = "{measure}"' in config, config
        asked[measure] = [(q["step"], q["uncertainty"]) for q in model.queries]
        assert asked[measure], f"no query with {measure}"
    assert all(0.0 <= u <= 1.0 for _, u in asked["action_disagreement"]), asked["action_disagreement"]
    assert asked["action_disagreement"] != asked["critic_variance"]
    with pytest.raises(ValueError, match="uncertainty"):
        arld.Agent("adqn", gym.make("CartPole-v1"), expert=lambda obs: 0, uncertainty="action_disagreement")
    with pytest.raises(ValueError, match="uncertainty"):
        arld.Agent("dqfd", gym.make("Pendulum-v1"), expert=swing_up, uncertainty="action_disagreement")
    with pytest.raises(ValueError, match="critic_variance"):
        arld.Agent("adqn", gym.make("Pendulum-v1"), expert=swing_up, uncertainty="entropy")
