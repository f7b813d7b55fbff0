"""A run's answers kept as a Minari dataset, with the real `minari` package: a run's answers exported, read back
with `minari.load_dataset` and compared with what the run's other logs say, and later runs seeded from the dataset
(`demos=` by id and by directory, and the command line's `demo_file` through `arld.answers to-demos`)."""

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


def test_bad_answers_and_datasets_are_clear_errors(tmp_path, monkeypatch):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "datasets"))
    with pytest.raises(FileNotFoundError, match="no answer log"):
        answers.export_minari(tmp_path, DATASET)
    out = subprocess.run([sys.executable, "-m", "arld.answers", "export", str(tmp_path), "--dataset-id", DATASET],
                         capture_output=True, text=True)
    assert out.returncode == 1 and "no answer log" in out.stderr
    with pytest.raises(FileNotFoundError, match="not found locally"):
        arld.Agent("dqfd", gym.make("CartPole-v0"), demos="arld-test/nothing-v0")
