"""The Python package against real Gymnasium and Stable-Baselines3: learning, the bridge's exactness, experts of
every kind, and every way an environment or expert can fail."""

import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import arld

REPO = Path(__file__).resolve().parents[2]
WEAK = REPO / "experts" / "CartPole-v0" / "weak.safetensors"


def weak_expert():
    """The shipped weak CartPole expert (the paper's kind: about 165 of 200) as a plain callable."""
    policy = arld.Agent.load(WEAK)
    return lambda obs: int(policy.predict(obs)[0])


def test_adqn_b_solves_gymnasium_cartpole_with_a_callable_expert():
    solved = 0
    for seed in range(5):
        model = arld.Agent("adqn", gym.make("CartPole-v0"), net="bootstrap", expert=weak_expert(), seed=seed)
        model.learn(total_timesteps=20_000)
        budget = model.config["budget"]
        assert model.summary["demos_queried"] <= budget
        expert_steps = sum(1 for _ in model.queries)  # each query is at least one expert step
        assert expert_steps <= budget
        assert [e["step"] for e in model.evaluations] == list(range(1000, 20_001, 1000))
        if max(e["mean"] for e in model.evaluations) >= 195:
            solved += 1
    assert solved >= 4, f"only {solved} of 5 seeds solved CartPole-v0 within 20k steps"


@pytest.mark.parametrize("method,net", [("adqn", "bootstrap"), ("bdqn", "noisy")])
def test_gymnasium_cartpole_through_python_equals_the_builtin(method, net):
    runs = []
    for env in (gym.make("CartPole-v0"), arld.make("CartPole-v0")):
        model = arld.Agent(method, env, net=net, expert=weak_expert(), seed=3)
        model.learn(total_timesteps=4000)
        runs.append(model)
    gym_run, builtin = runs
    assert len(gym_run.queries) > 0
    assert gym_run.evaluations == builtin.evaluations
    assert gym_run.queries == builtin.queries
    # And the same seed again gives the same again.
    again = arld.Agent(method, gym.make("CartPole-v0"), net=net, expert=weak_expert(), seed=3).learn(4000)
    assert again.evaluations == gym_run.evaluations and again.queries == gym_run.queries


def test_a_trained_stable_baselines3_model_is_an_expert():
    from stable_baselines3 import DQN

    sb3 = DQN("MlpPolicy", "CartPole-v1", learning_starts=200, train_freq=4, seed=0, verbose=0)
    sb3.learn(total_timesteps=1000)
    answers = []
    real_predict = sb3.predict

    def recording_predict(obs, state=None, episode_start=None, deterministic=False):
        assert deterministic, "arld must ask for the deterministic action"
        action, state = real_predict(obs, state, episode_start, deterministic)
        answers.append((np.array(obs), int(action)))
        return action, state

    sb3.predict = recording_predict
    model = arld.Agent("adqn", gym.make("CartPole-v1"), net="bootstrap", expert=sb3, seed=0)
    model.learn(total_timesteps=3000)
    assert model.summary["demos_queried"] == len(answers) > 0
    # Every query's expert action is what the SB3 policy answers for that observation.
    assert answers[0][1] == model.queries[0]["expert_action"]
    for obs, action in answers[:50]:
        assert int(real_predict(obs, deterministic=True)[0]) == action


def test_spaces_arld_cannot_use_are_value_errors():
    multi = gym.make("CartPole-v1")
    multi.action_space = gym.spaces.MultiDiscrete([2, 3])
    with pytest.raises(ValueError, match="Discrete action space starting at 0 or a Box.*CartPole-v1.*MultiDiscrete"):
        arld.Agent("adqn", multi, expert=lambda obs: 0)
    env = gym.make("CartPole-v1")
    env.observation_space = gym.spaces.Box(0, 255, (84, 84, 3), np.uint8)
    with pytest.raises(ValueError, match="are images .*FlattenObservation"):
        arld.Agent("dqn", env)


def test_unknown_hyperparameters_and_bad_values_are_clear():
    with pytest.raises(TypeError, match="'learning_rat'; did you mean 'learning_rate'"):
        arld.Agent("dqn", gym.make("CartPole-v1"), learning_rat=1e-3)
    assert arld.Agent("dqn", gym.make("CartPole-v1"), learning_rate=1e-3).config["lr"] == 1e-3
    with pytest.raises(ValueError, match="t_query"):
        arld.Agent("adqn", gym.make("CartPole-v1"), expert=lambda o: 0, t_query=1.5)
    with pytest.raises(ValueError, match="needs an expert"):
        arld.Agent("adqn", gym.make("CartPole-v1"))
    # The CLI's names and defaults.
    p = arld.preset("adqn", "LunarLander-v2", net="noisy")
    assert p["t_query"] == 0.1 and p["lr"] == 1e-3 and p["budget"] == 3000
    assert set(arld.config_keys()) <= set(p)
    assert arld.Agent("adqn", arld.make("CartPole-v0"), expert=lambda o: 0, lr=3e-4).config["lr"] == 3e-4


def test_a_misbehaving_python_expert_raises_with_context():
    def broken(obs):
        raise ZeroDivisionError("the expert broke")

    with pytest.raises(ZeroDivisionError, match="the expert broke") as info:
        arld.Agent("gdqn", gym.make("CartPole-v1"), expert=broken).learn(1000)
    if sys.version_info >= (3, 11):
        assert any("python:test_arld." in n and "broken" in n for n in info.value.__notes__)
    with pytest.raises(ValueError, match="answered action 7, but the environment has 2 actions"):
        arld.Agent("gdqn", gym.make("CartPole-v1"), expert=lambda obs: 7).learn(1000)
    with pytest.raises(TypeError, match="one integer action"):
        arld.Agent("gdqn", gym.make("CartPole-v1"), expert=lambda obs: "left").learn(1000)


class Exploding(gym.Wrapper):
    def step(self, action):
        raise RuntimeError("the environment exploded")


def test_an_environment_exception_propagates():
    env = Exploding(gym.make("CartPole-v1"))
    with pytest.raises(RuntimeError, match="the environment exploded"):
        arld.Agent("dqn", env, eval_env=gym.make("CartPole-v1")).learn(1000)
    # Without eval_env the test episodes run on copies of the environment as given, which explode too.
    with pytest.raises(RuntimeError, match="the environment exploded"):
        arld.Agent("dqn", env).learn(1000)


@pytest.mark.parametrize(
    "command,message",
    [
        ("sh -c 'read h; read q; echo dying >&2; exit 3'", "closed its output"),
        ("sleep 60", "did not answer within 1 s"),
        ("sh -c 'while read l; do echo garbage; done'", '"garbage"'),
    ],
)
def test_a_failing_expert_process_ends_learn_with_a_clear_error(command, message):
    model = arld.Agent("gdqn", gym.make("CartPole-v1"), expert="cmd:" + command, expert_timeout=1.0)
    with pytest.raises(RuntimeError, match=message) as info:
        model.learn(1000)
    assert "expert process" in str(info.value)


def test_the_example_expert_process_works_from_python():
    script = REPO / "examples" / "expert.py"
    model = arld.Agent("gdqn", gym.make("CartPole-v0"), expert=f"cmd:{sys.executable} {script}", seed=0)
    model.learn(2000)
    assert model.summary["demos_queried"] == model.config["budget"]


def test_predict_save_load_and_the_run_directory(tmp_path):
    env = gym.make("CartPole-v0")
    model = arld.Agent("adqn", env, expert=weak_expert(), seed=1)
    model.learn(total_timesteps=2000, log_dir=tmp_path / "run")
    run = tmp_path / "run"
    summary = json.loads((run / "summary.json").read_text())
    assert summary["env"] == "CartPole-v0" and summary["train_steps"] == 2000
    assert any(p.name.startswith("events.out.tfevents.") for p in run.iterdir())
    assert (run / "queries.csv").read_text().count("\n") == len(model.queries) + 1
    model.save(tmp_path / "agent.safetensors")
    loaded = arld.Agent.load(tmp_path / "agent.safetensors", env, expert=weak_expert())
    rng = np.random.default_rng(0)
    for obs in rng.normal(size=(100, 4)).astype(np.float32):
        assert loaded.predict(obs)[0] == model.predict(obs)[0]
    with pytest.raises(ValueError, match="4 inputs and 2 actions, the environment 2 and 3"):
        arld.Agent.load(run / "weights.safetensors", gym.make("MountainCar-v0"))
    plain = arld.Agent.load(run / "weights.safetensors")
    assert plain.net == "bootstrap" and plain.predict(np.zeros(4))[0] == model.predict(np.zeros(4))[0]


def test_builtin_environments_have_gymnasiums_api():
    env = arld.make("CartPole-v0")
    obs, info = env.reset(seed=5)
    ref = gym.make("CartPole-v0")
    ref_obs, _ = ref.reset(seed=5)
    assert np.array_equal(obs, ref_obs)
    for _ in range(20):
        a = env.action_space.sample()
        o1, r1, te1, tr1, _ = env.step(a)
        o2, r2, te2, tr2, _ = ref.step(a)
        assert np.array_equal(o1, o2) and (r1, te1, tr1) == (r2, te2, tr2)
        if te1:
            break
    with pytest.raises(ValueError, match="unknown environment id"):
        arld.make("Pong-v5")


def test_demonstrations_from_arrays_for_dqfd():
    env = gym.make("CartPole-v0")
    expert = weak_expert()
    cols = {k: [] for k in ("obs", "actions", "rewards", "next_obs", "terminated", "truncated")}
    obs, _ = env.reset(seed=0)
    while len(cols["actions"]) < 200:
        a = expert(obs)
        nxt, r, te, tr, _ = env.step(a)
        for k, v in zip(cols, (obs, a, r, nxt, te, tr)):
            cols[k].append(v)
        obs = env.reset()[0] if te or tr else nxt
    model = arld.Agent("dqfd", gym.make("CartPole-v0"), expert=expert, demos=cols, pretrain_steps=200, seed=0)
    model.learn(2000)
    assert model.summary["demos_pretrain"] == 200
    bad = dict(cols, actions=[5] * 200)
    with pytest.raises(RuntimeError, match="action 5 is out of range"):
        arld.Agent("dqfd", gym.make("CartPole-v0"), expert=expert, demos=bad, pretrain_steps=200).learn(1000)


def test_ctrl_c_interrupts_learn():
    # Python's own Ctrl-C handler, whatever this process inherited: a shell starts background jobs with SIGINT
    # ignored, and Python then installs no handler.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    # SIGINT from another process, as a terminal's Ctrl-C: a Python timer thread would first need the GIL, which
    # the training loop gives up only between steps, so the signal could come late or never.
    killer = subprocess.Popen(["sh", "-c", f"sleep 1; kill -INT {os.getpid()}"])
    try:
        with pytest.raises(KeyboardInterrupt):
            arld.Agent("dqn", gym.make("CartPole-v1")).learn(10_000_000)
    finally:
        killer.kill()
        killer.wait()
        signal.signal(signal.SIGINT, previous)


def test_help_of_agent_documents_every_keyword():
    import inspect

    doc = arld.Agent.__doc__ or ""
    names = [n for n, p in inspect.signature(arld.Agent.__init__).parameters.items()
             if n != "self" and p.kind is not inspect.Parameter.VAR_KEYWORD]
    # The hyperparameter keywords (typed, so that a type checker catches a misspelt one); arld's names of SB3's are
    # documented with them.
    aliases = set(arld.SB3_NAMES.values())
    names += [n for n in arld.agent.Hyperparameters.__annotations__ if n not in aliases]
    assert len(names) > 50 and aliases <= set(arld.agent.Hyperparameters.__annotations__)
    missing = [n for n in names if not re.search(rf"(^|[\s`(]){n}[:=`\s]", doc)]
    assert missing == []
    # Every configuration key is reachable by a documented keyword (arld's name or SB3's).
    documented = {arld.SB3_NAMES.get(n, n) for n in names}
    assert set(arld.config_keys()) - documented - {"env", "method", "net", "seed", "expert"} == set()
