"""A run's answers kept as a Minari dataset, with the real `minari` package: a run's answers exported, read back
with `minari.load_dataset` and compared with what the run's other logs say, and later runs seeded from the dataset
(`demos=` by id and by directory, and the command line's `demo_file` through `arld.answers to-demos`); the command
line reads the dataset itself (`demo_file` = its id or directory, `arld demo convert`), a box dataset written by
minari from Gymnasium's Pendulum-v1 too, and a dataset of other spaces is refused."""

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import minari
import numpy as np
import pytest

import arld
from arld import answers

REPO = Path(__file__).resolve().parents[2]
WEAK = REPO / "experts" / "CartPole-v0" / "weak.safetensors"
ARLD = Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target")) / "release" / "arld"
DATASET = "arld-test/cartpole-answers-v0"


def weak_expert():
    policy = arld.Agent.load(WEAK)
    return lambda obs: int(policy.predict(obs)[0])


@pytest.fixture
def answered_run(tmp_path, monkeypatch):
    """A short ADQN run on CartPole-v0 answered by a program, its directory, and Minari's dataset directory."""
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "datasets"))
    run = tmp_path / "run"
    model = arld.Agent("adqn", gym.make("CartPole-v0"), net="bootstrap", expert=weak_expert(), seed=2)
    model.learn(total_timesteps=3000, log_dir=run)
    assert model.summary["demos_queried"] > 0
    return run, tmp_path / "datasets"


def test_a_runs_answers_are_a_minari_dataset_that_minari_loads(answered_run):
    run, _ = answered_run
    answers.export_minari(run, DATASET)
    ds = minari.load_dataset(DATASET)
    # Independently of the answer log: the questions answered (queries.csv) and the expert's steps per episode
    # (episodes.csv, finished episodes).
    with open(run / "queries.csv") as f:
        asked = [r for r in csv.DictReader(f) if r["answered"] == "true"]
    with open(run / "episodes.csv") as f:
        demo_steps = {int(r["episode"]): int(r["demo_steps"]) for r in csv.DictReader(f)}
    episodes = list(ds.iterate_episodes())
    assert ds.total_episodes == len(episodes) >= len(asked) > 0
    assert ds.total_steps == sum(len(ep.actions) for ep in episodes)
    taken = {e: 0 for e in demo_steps}
    questions = []
    for ep in episodes:
        n = len(ep.actions)
        assert ep.observations.shape == (n + 1, 4) and ep.observations.dtype == np.float32
        assert np.all(ep.rewards == 1.0)  # CartPole pays 1 a step
        assert ep.terminations[:-1].sum() == 0 and ep.truncations[:-1].sum() == 0
        assert ep.terminations[-1] or ep.truncations[-1]
        info = ep.infos
        assert list(info["step"]) == list(range(int(info["step"][0]), int(info["step"][0]) + n + 1))
        for key in ("episode", "question_step", "agent_action", "expert", "started_by"):
            assert len(set(info[key].tolist())) == 1, key  # the segment's question, in every row
        episode = int(info["episode"][0])
        if episode in taken:
            taken[episode] += n
        if int(info["question_step"][0]) == int(info["step"][0]):
            questions.append((ep, info))
    assert taken == demo_steps
    # Each answered question opens one segment, which starts with the answer.
    assert len(questions) == len(asked)
    for (ep, info), row in zip(questions, asked):
        assert int(info["step"][0]) == int(row["step"])
        assert int(ep.actions[0]) == int(row["expert_action"])
        assert int(info["agent_action"][0]) == int(row["agent_action"])
        assert np.float32(info["uncertainty"][0]) == np.float32(row["uncertainty"])
        assert str(info["expert"][0]) == row["expert"] and str(info["started_by"][0]) == "rule"
    # The environment confirms the observations: CartPole's dynamics from each state and action give the next.
    env = gym.make("CartPole-v0").unwrapped
    env.reset(seed=0)
    for ep in episodes[:10]:
        for i, a in enumerate(ep.actions):
            env.state = ep.observations[i].astype(np.float64)
            nxt, _, terminated, _, _ = env.step(int(a))
            assert np.allclose(nxt, ep.observations[i + 1], atol=1e-5)
            assert terminated == bool(ep.terminations[i])


def columns_from_the_answer_log(run):
    """The run's answers as demonstration columns, read from answers.jsonl directly, cut where minari's episodes
    are: another question, a gap, or the episode's end."""
    rows = [json.loads(line) for line in (run / "answers.jsonl").read_text().splitlines()]
    cols = {k: [] for k in ("obs", "actions", "rewards", "next_obs", "terminated", "truncated")}
    for i, r in enumerate(rows):
        nxt = rows[i + 1] if i + 1 < len(rows) else None
        cut = nxt is None or nxt["question_step"] != r["question_step"] or nxt["step"] != r["step"] + 1
        for k, v in zip(cols, (r["obs"], r["action"], r["reward"], r["next_obs"], r["terminated"],
                                r["truncated"] or (cut and not r["terminated"]))):
            cols[k].append(v)
    return cols


def test_a_run_seeded_from_an_earlier_runs_answers(answered_run, tmp_path):
    run, datasets = answered_run
    answers.export_minari(run, DATASET)
    cols = columns_from_the_answer_log(run)
    n = len(cols["actions"])
    assert answers.minari_columns(DATASET)["actions"].tolist() == cols["actions"]

    def seeded(**given):
        model = arld.Agent("dqfd", gym.make("CartPole-v0"), pretrain_steps=300, seed=5, **given)
        model.learn(2000)
        return model

    by_columns = seeded(demos=cols)
    assert by_columns.summary["demos_pretrain"] == n
    # The dataset by id and by directory: the same transitions, so the same run to the last number.
    for given in (DATASET, datasets / DATASET):
        model = seeded(demos=given)
        assert model.summary["demos_pretrain"] == n
        assert model.evaluations == by_columns.evaluations
    # The command line's demo_file: the dataset written as a demonstration file holds the same transitions, and
    # a DQfD run of the command line pre-trains on all of them.
    demo_file = tmp_path / "answers.demos.jsonl"
    out = subprocess.run([sys.executable, "-m", "arld.answers", "to-demos", DATASET, str(demo_file)],
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert f"{n} transitions" in out.stdout
    header, *lines = [json.loads(line) for line in demo_file.read_text().splitlines()]
    assert header["env"] == "CartPole-v0" and header["transitions"] == n
    for key, col in (("obs", "obs"), ("action", "actions"), ("reward", "rewards"), ("next_obs", "next_obs"),
                     ("terminated", "terminated"), ("truncated", "truncated")):
        assert np.array_equal(np.asarray([t[key] for t in lines], dtype=np.float32),
                              np.asarray(cols[col], dtype=np.float32)), key
    assert ARLD.is_file(), "the command line is not built (cargo build --release)"
    out = subprocess.run([str(ARLD), "train", "--env", "CartPole-v0", "--method", "dqfd", "--quiet", "--demos",
                          str(demo_file), "--set", "pretrain_steps=300", "--set", "train_steps=1000",
                          "-o", str(tmp_path / "cli")], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert json.loads((tmp_path / "cli" / "summary.json").read_text())["demos_pretrain"] == n
    # The command line reads the dataset itself, by id (MINARI_DATASETS_PATH) and by directory: it pre-trains on
    # the same transitions, so the run is the one above to the last byte of its evaluations.
    for name, given in (("by_id", DATASET), ("by_dir", str(datasets / DATASET))):
        out = subprocess.run([str(ARLD), "train", "--env", "CartPole-v0", "--method", "dqfd", "--quiet", "--set",
                              f"demo_file={given}", "--set", "pretrain_steps=300", "--set", "train_steps=1000",
                              "-o", str(tmp_path / name)], capture_output=True, text=True)
        assert out.returncode == 0, out.stderr
        assert json.loads((tmp_path / name / "summary.json").read_text())["demos_pretrain"] == n
        assert (tmp_path / name / "eval.csv").read_bytes() == (tmp_path / "cli" / "eval.csv").read_bytes()
    # What the command line reads is what minari reads.
    assert_cli_reads_as_minari(DATASET, "CartPole-v0", tmp_path / "converted.jsonl")


def assert_cli_reads_as_minari(dataset, env, out):
    """`arld demo convert` (the command line's reader of `demo_file`) writes the dataset's transitions as
    `minari.load_dataset` reads them: as many, in order, each episode's last step truncated unless it ended."""
    res = subprocess.run([str(ARLD), "demo", "convert", str(dataset), "--env", env, "-o", str(out)],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    header, *lines = [json.loads(line) for line in out.read_text().splitlines()]
    ds = answers.load_dataset(dataset)
    assert header["env"] == env and header["transitions"] == len(lines) == ds.total_steps
    expected = []
    for ep in ds.iterate_episodes():
        n = len(ep.actions)
        for i in range(n):
            ended = bool(ep.terminations[i])
            truncated = bool(ep.truncations[i]) or (i == n - 1 and not ended)
            expected.append((ep.observations[i], ep.actions[i], ep.rewards[i], ep.observations[i + 1], ended,
                             truncated))
    assert len(expected) == len(lines)
    for (obs, action, reward, next_obs, terminated, truncated), t in zip(expected, lines):
        assert np.array_equal(np.asarray(t["obs"], dtype=np.float32), np.asarray(obs, dtype=np.float32))
        assert np.array_equal(np.asarray(t["next_obs"], dtype=np.float32), np.asarray(next_obs, dtype=np.float32))
        assert np.array_equal(np.asarray(t["action"], dtype=np.float32), np.asarray(action, dtype=np.float32))
        assert np.float32(t["reward"]) == np.float32(reward)
        assert (t["terminated"], t["truncated"]) == (terminated, truncated)
    return len(lines)


def pendulum_dataset(dataset_id, episodes=3, steps=40):
    """A box dataset written by minari from Gymnasium's Pendulum-v1 under a scripted torque. (Minari's
    DataCollector needs jax for its step buffers; the episodes go through `create_dataset_from_buffers`, the
    writer DataCollector ends in.)"""
    from minari.data_collector import EpisodeBuffer
    env = gym.make("Pendulum-v1", max_episode_steps=steps)
    buffers = []
    for i in range(episodes):
        obs, _ = env.reset(seed=10 + i)
        observations, actions, rewards, terminations, truncations = [obs], [], [], [], []
        done = False
        while not done:
            action = np.clip([-2.0 * obs[1] - 0.5 * obs[2]], -2.0, 2.0).astype(np.float32)
            obs, reward, terminated, truncated, _ = env.step(action)
            for col, value in zip((observations, actions, rewards, terminations, truncations),
                                  (obs, action, reward, terminated, truncated)):
                col.append(value)
            done = terminated or truncated
        buffers.append(EpisodeBuffer(id=i, observations=np.asarray(observations), actions=np.asarray(actions),
                                     rewards=rewards, terminations=terminations, truncations=truncations))
    return minari.create_dataset_from_buffers(dataset_id, buffers, env=env, algorithm_name="scripted torque",
                                              data_format="arrow")


def test_the_command_line_reads_a_box_dataset_and_refuses_other_spaces(tmp_path, monkeypatch):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "datasets"))
    assert ARLD.is_file(), "the command line is not built (cargo build --release)"
    ds = pendulum_dataset("arld-test/pendulum-torque-v0")
    assert ds.total_steps == 120
    assert assert_cli_reads_as_minari("arld-test/pendulum-torque-v0", "Pendulum-v1", tmp_path / "pendulum.jsonl") == 120
    out = subprocess.run([str(ARLD), "train", "--env", "Pendulum-v1", "--method", "dqfd", "--quiet", "--set",
                          "demo_file=arld-test/pendulum-torque-v0", "--set", "pretrain_steps=50", "--set",
                          "train_steps=400", "--set", "learning_starts=200", "-o", str(tmp_path / "run")],
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert json.loads((tmp_path / "run" / "summary.json").read_text())["demos_pretrain"] == 120
    # Of other spaces: refused before training, naming what differs.
    for env, says in (("MountainCarContinuous-v0", "observes 2 numbers"),
                      ("CartPole-v0", "CartPole-v0 observes 4 numbers")):
        out = subprocess.run([str(ARLD), "train", "--env", env, "--method", "dqfd", "--quiet", "--set",
                              "demo_file=arld-test/pendulum-torque-v0", "-o", str(tmp_path / env)],
                             capture_output=True, text=True)
        assert out.returncode != 0 and says in out.stderr, out.stderr
        assert not (tmp_path / env / "summary.json").exists()
    # The same torques in a narrower box than Pendulum's: refused, naming both boxes.
    narrow = minari.load_dataset("arld-test/pendulum-torque-v0")
    meta_path = Path(narrow.storage.data_path) / "metadata.json"
    meta = json.loads(meta_path.read_text())
    meta["action_space"] = json.dumps({"type": "Box", "dtype": "float32", "shape": [1], "low": [-1.0], "high": [1.0]})
    meta_path.write_text(json.dumps(meta))
    out = subprocess.run([str(ARLD), "demo", "convert", "arld-test/pendulum-torque-v0", "--env", "Pendulum-v1", "-o",
                          str(tmp_path / "narrow.jsonl")], capture_output=True, text=True)
    assert out.returncode != 0, out.stdout
    for box in ("Box([-1.0] to [1.0], shape [1])", "Box([-2.0] to [2.0], shape [1])"):
        assert box in out.stderr, out.stderr
    assert not (tmp_path / "narrow.jsonl").exists()


def test_bad_answers_and_datasets_are_clear_errors(tmp_path, monkeypatch):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "datasets"))
    with pytest.raises(FileNotFoundError, match="no answer log"):
        answers.export_minari(tmp_path, DATASET)
    out = subprocess.run([sys.executable, "-m", "arld.answers", "export", str(tmp_path), "--dataset-id", DATASET],
                         capture_output=True, text=True)
    assert out.returncode == 1 and "no answer log" in out.stderr
    with pytest.raises(FileNotFoundError, match="not found locally"):
        arld.Agent("dqfd", gym.make("CartPole-v0"), demos="arld-test/nothing-v0")


def test_a_box_runs_answers_are_a_minari_dataset_that_runs_train_on(tmp_path, monkeypatch):
    """Answers in a box, from the command line's run and from Python's: exported (`python -m arld.answers export`),
    loaded by minari with the very actions answers.jsonl holds and the task's box, and pre-trained on by the
    command line (`demo_file` = the dataset) and by Python (`demos=` the dataset)."""
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "datasets"))
    assert ARLD.is_file(), "the command line is not built (cargo build --release)"
    cli_run = tmp_path / "cli-run"
    out = subprocess.run([str(ARLD), "train", "--env", "Pendulum-v1", "--method", "adqn", "--expert", "scripted",
                          "--quiet", "--set", "train_steps=600", "--set", "budget=80", "-o", str(cli_run)],
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    py_run = tmp_path / "py-run"

    def torque(obs):
        return [float(np.clip(-2.0 * obs[1] - 0.5 * obs[2], -2.0, 2.0))]

    model = arld.Agent("adqn", gym.make("Pendulum-v1"), expert=torque, seed=3)
    model.learn(total_timesteps=600, log_dir=py_run)
    for run, dataset in ((cli_run, "arld-test/pendulum-cli-answers-v0"), (py_run, "arld-test/pendulum-py-answers-v0")):
        logged = [json.loads(line) for line in (run / "answers.jsonl").read_text().splitlines()]
        assert logged and all(isinstance(s["action"], list) for s in logged)
        out = subprocess.run([sys.executable, "-m", "arld.answers", "export", str(run), "--dataset-id", dataset],
                             capture_output=True, text=True)
        assert out.returncode == 0, out.stderr
        ds = minari.load_dataset(dataset)
        assert isinstance(ds.action_space, gym.spaces.Box)
        assert ds.action_space.low.tolist() == [-2.0] and ds.action_space.high.tolist() == [2.0]
        actions = np.concatenate([np.asarray(ep.actions, dtype=np.float32).reshape(-1, 1)
                                  for ep in ds.iterate_episodes()])
        assert np.array_equal(actions, np.asarray([s["action"] for s in logged], dtype=np.float32))
        assert ds.total_steps == len(logged)
        # The agent's proposal is kept in the infos, as a JSON list.
        first = next(iter(ds.iterate_episodes()))
        assert json.loads(first.infos["agent_action"][0]) == pytest.approx(logged[0]["agent_action"])
        # The command line pre-trains on the dataset, every transition.
        out = subprocess.run([str(ARLD), "train", "--env", "Pendulum-v1", "--method", "dqfd", "--quiet", "--set",
                              f"demo_file={dataset}", "--set", "pretrain_steps=50", "--set", "train_steps=400",
                              "--set", "learning_starts=200", "-o", str(tmp_path / f"{run.name}-dqfd")],
                             capture_output=True, text=True)
        assert out.returncode == 0, out.stderr
        summary = json.loads((tmp_path / f"{run.name}-dqfd" / "summary.json").read_text())
        assert summary["demos_pretrain"] == len(logged)
        # What the command line reads is what minari reads; the demonstration file of it says the box.
        assert assert_cli_reads_as_minari(dataset, "Pendulum-v1", tmp_path / f"{run.name}.jsonl") == len(logged)
        demo_file = tmp_path / f"{run.name}.demos.jsonl"
        out = subprocess.run([sys.executable, "-m", "arld.answers", "to-demos", dataset, str(demo_file), "--env",
                              "Pendulum-v1"], capture_output=True, text=True)
        assert out.returncode == 0, out.stderr
        header = json.loads(demo_file.read_text().splitlines()[0])
        assert (header["action_dim"], header["low"], header["high"]) == (1, [-2.0], [2.0]) and "n_actions" not in header
    # Python pre-trains on the dataset too.
    seeded = arld.Agent("dqfd", gym.make("Pendulum-v1"), demos="arld-test/pendulum-py-answers-v0", pretrain_steps=50,
                        seed=5)
    seeded.learn(400)
    assert seeded.summary["demos_pretrain"] == len((py_run / "answers.jsonl").read_text().splitlines())
