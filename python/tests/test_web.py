"""A person as the expert of a Gymnasium environment arld does not build in, in a real headless Chromium:
`arld.WebExpert` serves the page, the scripted person (tests/e2e/person.mjs, Playwright) answers from what the
page shows, and the run's files must hold the person's answers and time.

Needs Debian's chromium, node, playwright-core in tests/e2e/node_modules and pygame (Gymnasium's
classic-control rendering); without them the test fails, naming `scripts/test --setup`."""

import csv
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
E2E = REPO / "tests" / "e2e"

# The run: Gymnasium's own CartPole under an id arld does not know, rendered as RGB frames.
RUN = r"""
import json, sys
import gymnasium as gym
import arld

gym.register("PersonCartPole-v0", entry_point="gymnasium.envs.classic_control.cartpole:CartPoleEnv",
             max_episode_steps=200, reward_threshold=195.0)
env = gym.make("PersonCartPole-v0", render_mode="rgb_array")
web = arld.WebExpert(listen="127.0.0.1:0")
assert web.url.startswith("http://127.0.0.1:") and "token=" in web.url, web.url
model = arld.Agent("adqn", env, net="bootstrap", expert=web, seed=0, budget=30, eval_period=500, eval_episodes=3)
model.learn(total_timesteps=1500, log_dir=sys.argv[1])
print(json.dumps({"summary": model.summary}), flush=True)
"""


def missing_prerequisites():
    missing = []
    chromium = os.environ.get("CHROMIUM", "/usr/bin/chromium")
    if not Path(chromium).is_file():
        missing.append(f"Chromium at {chromium} (Debian's chromium)")
    if shutil.which("node") is None:
        missing.append("node (Debian's nodejs)")
    if not (E2E / "node_modules" / "playwright-core").is_dir():
        missing.append("playwright-core (in tests/e2e/node_modules)")
    try:
        import pygame  # noqa: F401
    except ImportError:
        missing.append("pygame (gymnasium[classic-control])")
    return missing


def start_run(script, run):
    """Starts the Python program `script` (its run directory `run`) after checking the prerequisites; returns
    the process and the URL it printed."""
    missing = missing_prerequisites()
    assert not missing, (
        f"the web expert's browser test cannot run; missing: {', '.join(missing)}; "
        "`scripts/test --setup` installs them"
    )
    train = subprocess.Popen(
        [sys.executable, "-c", script, str(run)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    for line in train.stdout:
        if "http://" in line:
            return train, line[line.index("http://") :].strip()
    train.kill()
    raise AssertionError(f"the run printed no URL: {train.stderr.read()}")


def scripted_person(url, tmp_path, *extra):
    """The scripted person answering at `url` from the rendered frames; returns its report."""
    out = subprocess.run(
        ["node", "person.mjs", "--url", url, "--shots", str(tmp_path / "shots"), "--policy", "CartPole-v0",
         "--expect-image", *extra],
        cwd=E2E, capture_output=True, text=True, timeout=300,
    )
    assert out.returncode == 0, f"the scripted person failed: {out.stderr}{out.stdout}"
    return json.loads([l for l in out.stdout.splitlines() if l.startswith("{")][-1])


def test_a_person_answers_a_gymnasium_environment_from_its_rendered_frames(tmp_path):
    run = tmp_path / "run"
    train, url = start_run(RUN, run)
    try:
        report = scripted_person(url, tmp_path)
        out, err = train.communicate(timeout=120)
    finally:
        if train.poll() is None:
            train.kill()
    assert train.returncode == 0, f"the run failed: {err}"
    assert report["env"] == "PersonCartPole-v0"
    # The page showed the environment's own frames, not blank (the person checked the canvas at each shot).
    for name in ("training", "asking", "mid-segment"):
        drawn = report["drawn"][name]
        assert drawn["share"] > 0.005 and drawn["colours"] >= 3, (name, drawn)
        assert (tmp_path / "shots" / f"{name}.png").is_file()

    with open(run / "queries.csv") as f:
        rows = list(csv.DictReader(f))
    answered = [r for r in rows if r["answered"] == "true"]
    assert [int(r["expert_action"]) for r in answered] == report["answers"], "queries.csv lacks the answers"
    assert all(r["expert"] == "web" and float(r["response_s"]) > 0 for r in answered)
    summary = json.loads((run / "summary.json").read_text())
    assert summary["train_steps"] == 1500 and summary["env"] == "PersonCartPole-v0"
    assert 0 < summary["queries_used"] <= 30
    # The person's time: at least the sum of their response times to opening questions, and what the end
    # screen showed.
    assert summary["person_s"] >= sum(float(r["response_s"]) for r in answered) - 1e-6
    outcome = report["endScreen"]["outcome"]
    assert outcome["answered"] == len(answered) and outcome["keys"] == report["steps"]
    assert abs(outcome["person_s"] - summary["person_s"]) < 1e-6
    assert json.loads(out.strip().splitlines()[-1])["summary"]["person_s"] == summary["person_s"]


def test_web_expert_arguments_are_checked_and_a_run_nobody_answers_completes(tmp_path):
    import gymnasium as gym
    import pytest

    import arld

    with pytest.raises(ValueError, match="listen"):
        arld.WebExpert(listen="not-an-address")
    with pytest.raises(ValueError, match="fps"):
        arld.WebExpert(fps=-1)
    with pytest.raises(ValueError, match="Escape"):
        arld.WebExpert(keys={"Escape": 0})
    # Without rendering, the observation is shown as a table; nobody opens the page (wait=False) and every
    # question times out: the run completes on the agent's own, each question logged unanswered at no cost.
    web = arld.WebExpert(timeout=0.05, wait=False, keys={"ArrowLeft": 0, "ArrowRight": 1})
    assert web.url.startswith("http://127.0.0.1:") and repr(web).startswith("arld.WebExpert(")
    model = arld.Agent("adqn", gym.make("CartPole-v1"), net="bootstrap", expert=web, seed=1, eval_period=300)
    model.learn(total_timesteps=600, log_dir=tmp_path / "run")
    with open(tmp_path / "run" / "queries.csv") as f:
        rows = list(csv.DictReader(f))
    assert rows and all(r["answered"] == "false" and r["expert_action"] == "" for r in rows)
    assert all(float(r["response_s"]) >= 0.05 for r in rows)
    assert model.summary["queries_used"] == 0
    assert model.summary["person_s"] >= 0.05 * len(rows)
    # One run per WebExpert.
    with pytest.raises(RuntimeError, match="create a new one"):
        arld.Agent("adqn", gym.make("CartPole-v1"), expert=web, seed=1).learn(total_timesteps=100)


# The same run, stopped by SIGTERM while a question is open, then continued in the same process.
STOPPED = r"""
import csv, json, os, sys
import gymnasium as gym
import arld

gym.register("PersonCartPole-v0", entry_point="gymnasium.envs.classic_control.cartpole:CartPoleEnv",
             max_episode_steps=200, reward_threshold=195.0)
env = gym.make("PersonCartPole-v0", render_mode="rgb_array")
model = arld.Agent("adqn", env, net="bootstrap", expert=arld.WebExpert(listen="127.0.0.1:0"), seed=0, budget=30,
                   eval_period=500, eval_episodes=3)
try:
    model.learn(total_timesteps=1500, log_dir=sys.argv[1])
    sys.exit("learn returned: the stop did not stop it")
except KeyboardInterrupt:
    pass
with open(os.path.join(sys.argv[1], "queries.csv")) as f:
    rows = list(csv.DictReader(f))
print(json.dumps({"stopped_at": model.num_timesteps, "answers": [int(r["expert_action"]) for r in rows
                  if r["answered"] == "true"], "snapshot": os.path.isfile(os.path.join(sys.argv[1],
                  "snapshot.safetensors"))}), flush=True)
model.learn(total_timesteps=1500 - model.num_timesteps, reset_num_timesteps=False)
print(json.dumps({"summary": model.summary}), flush=True)
"""


def test_a_stop_while_a_question_is_open_pauses_the_run_whole_and_learn_asks_it_again(tmp_path):
    import signal

    run = tmp_path / "run"
    train, url = start_run(STOPPED, run)
    try:
        # Two questions answered; the person leaves with the third open, and the program gets SIGTERM.
        first = scripted_person(url, tmp_path, "--answer", "2")
        assert first["open"] is not None and len(first["answers"]) == 2
        train.send_signal(signal.SIGTERM)
        stopped = json.loads(train.stdout.readline())
        # Nothing given before the stop is lost: the answers are in queries.csv, the snapshot is in the run
        # directory, and the process lives on.
        assert stopped["answers"] == first["answers"] and stopped["snapshot"], stopped
        assert train.poll() is None
        # learn goes on: the open question is asked again, the person answers to the end.
        second = scripted_person(url, tmp_path)
        assert second["first"]["obs"] == first["open"]["obs"], (second["first"], first["open"])
        out, err = train.communicate(timeout=120)
    finally:
        if train.poll() is None:
            train.kill()
    assert train.returncode == 0, f"the run failed: {err}"
    assert "stopped; the run's snapshot is in" in err
    with open(run / "queries.csv") as f:
        rows = list(csv.DictReader(f))
    answered = [int(r["expert_action"]) for r in rows if r["answered"] == "true"]
    assert answered == first["answers"] + second["answers"], "queries.csv lost answers across the stop"
    summary = json.loads(out.strip().splitlines()[-1])["summary"]
    assert summary["train_steps"] == 1500
