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
    return json.loads([row for row in out.stdout.splitlines() if row.startswith("{")][-1])


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
    assert 0 < summary["demos_queried"] <= 30
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
    assert model.summary["demos_queried"] == 0
    # Nobody had the page open: none of it is a person's time.
    assert model.summary["person_s"] == 0.0
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


# FrozenLake under an id without a solve threshold, rendered; keys= (Space among them) and labels= given. The first
# learn runs to its end and the program goes on (it waits for a file the person creates), then trains on until it is
# stopped with a question open.
LAKE = r"""
import json, os, sys, time
import gymnasium as gym
import arld

gym.register("PersonLake-v0", entry_point="gymnasium.envs.toy_text.frozen_lake:FrozenLakeEnv",
             kwargs={"is_slippery": False}, max_episode_steps=40)
env = gym.make("PersonLake-v0", render_mode="rgb_array")
web = arld.WebExpert(keys={"a": 0, " ": 1, "d": 2, "w": 3}, labels=["west", "south", "east", "north"])
model = arld.Agent("adqn", env, net="bootstrap", expert=web, seed=0, budget=400, eval_period=200, eval_episodes=2)
started = time.monotonic()
model.learn(total_timesteps=400, log_dir=sys.argv[1])
wall = time.monotonic() - started
print(json.dumps({"learned": model.num_timesteps, "summary": model.summary, "wall_s": wall}), flush=True)
while not os.path.exists(sys.argv[2]):
    time.sleep(0.05)
try:
    model.learn(total_timesteps=4000, reset_num_timesteps=False)
    sys.exit("learn returned: the stop did not stop it")
except KeyboardInterrupt:
    print(json.dumps({"stopped": model.num_timesteps}), flush=True)
"""


def page_person(url, tmp_path, *extra):
    out = subprocess.run(["node", "python_page.mjs", "--url", url, "--shots", str(tmp_path / "shots"), *extra],
                         cwd=E2E, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, f"the person failed: {out.stderr}{out.stdout}"
    return json.loads([row for row in out.stdout.splitlines() if row.startswith("{")][-1])


def test_the_page_shows_where_a_python_run_stands_when_learn_returns_and_when_it_is_stopped(tmp_path):
    run, go = tmp_path / "run", tmp_path / "go"
    train, url = start_run_with(LAKE, run, go)
    try:
        report = page_person(url, tmp_path, "--key", "Space", "--pause", "3000", "--gamepad", "2", "--go", str(go),
                             "--pid", str(train.pid))
        out, err = train.communicate(timeout=120)
    finally:
        if train.poll() is None:
            train.kill()
    assert train.returncode == 0, f"the program failed: {err}"
    lines = [json.loads(row) for row in out.splitlines() if row.startswith("{")]
    learned, stopped = lines[0], lines[1]
    hello = report["hello"]
    # labels= and keys= (Space named as such); rendered frames cannot be copied, so undo is neither offered nor
    # promised.
    assert [a["label"] for a in hello["actions"]] == ["west", "south", "east", "north"]
    assert hello["buttons"][1] == "south [Space]", hello["buttons"]
    assert not hello["undo"] and hello["undoHidden"] and "Backspace" not in hello["help"]
    assert report["first"]["answers"] > 0
    # learn returned, the program runs on: the page says where the run stands, with nothing left to press.
    handed = report["handed"]
    assert handed["end"] is not None, handed
    assert handed["end"]["title"] == "Trained 400 steps", "no solve threshold: neither solved nor not solved"
    assert "Training returned at step 400" in handed["end"]["note"]
    assert handed["live"] == 0 and not handed["passLive"] and handed["prompt"] is None
    assert handed["badge"] == "the program has the run"
    with open(run / "queries.csv") as f:
        answered = [r for r in csv.DictReader(f) if r["answered"] == "true"]
    outcome = handed["outcome"]
    assert outcome["answered"] == len(answered) == report["first"]["questions"]
    assert outcome["keys"] == report["first"]["answers"]
    assert abs(outcome["person_s"] - learned["summary"]["person_s"]) < 1e-9
    # The first question was paused 3 s, its tab closed and opened again meanwhile: the pause held, and neither
    # its response time nor the person's time counts the pause.
    pause = report["pause"]
    assert pause["stillPaused"] and pause["banner"].startswith("Paused"), pause
    first_response = float(answered[0]["response_s"])
    assert abs(first_response - (pause["openS"] - pause["pausedS"])) < 0.5, (first_response, pause)
    assert first_response < pause["openS"] - 2.5
    assert learned["summary"]["person_s"] <= learned["wall_s"] - pause["pausedS"] + 0.2
    # A gamepad (scripted through the Gamepad API): its mapping shows on the page (south on A by default: its key is
    # Space, no arrow); east, moved from the d-pad's right to its down there, answered the second question with
    # that button (every key answered south).
    pad = report["pad"]
    assert pad["before"]["map"] == [14, 0, 15, 12], pad
    assert pad["before"]["rows"][1] == ["south", "A / Cross"] and pad["after"] == [14, 0, 13, 12]
    assert [int(r["expert_action"]) for r in answered[:2]] == [1, 2]
    # Training goes on: the note leaves; the stop with a question open is shown, the question closed.
    assert report["resumed"]["end"] is None and report["resumed"]["handed"] is None
    assert report["openWhenStopped"] is not None
    s = report["stopped"]
    assert s["handed"]["stopped"] and s["prompt"] is None and s["live"] == 0 and not s["passLive"]
    assert s["end"]["title"] == f"Stopped at step {stopped['stopped']}", s["end"]
    assert "stopped the run" in s["text"]
    # The program exits: the page says the run will not go on (no endless reconnecting).
    assert report["exited"]["ended"] and report["exited"]["badge"] == "run over"
    assert not report["exited"]["pauseLive"]


# MiniGrid's shape: a 2835-value observation and an `actions` enum, no rendering, no keys given.
BIG = r"""
import enum, sys
import numpy as np
import gymnasium as gym
import arld

class Actions(enum.IntEnum):
    left = 0
    right = 1
    forward = 2

class Big(gym.Env):
    observation_space = gym.spaces.Box(0.0, 1.0, (2835,), np.float32)
    action_space = gym.spaces.Discrete(3)

    def __init__(self):
        self.actions = Actions

    def reset(self, seed=None, options=None):
        super().reset(seed=seed)
        self.pos = 0
        return self._obs(), {}

    def _obs(self):
        o = np.zeros(2835, np.float32)
        o[self.pos] = 1.0
        return o

    def step(self, a):
        self.pos += int(a == Actions.forward)
        done = self.pos >= 5
        return self._obs(), float(done), done, False, {}

gym.register("PersonBig-v0", entry_point=Big, max_episode_steps=30, reward_threshold=0.9)
model = arld.Agent("adqn", gym.make("PersonBig-v0"), net="bootstrap", expert=arld.WebExpert(), seed=0, budget=20,
                   eval_period=100, eval_episodes=1)
model.learn(total_timesteps=200, log_dir=sys.argv[1])
"""


def test_a_large_observation_is_folded_and_an_actions_enum_names_the_buttons(tmp_path):
    train, url = start_run_with(BIG, tmp_path / "run")
    try:
        report = page_person(url, tmp_path, "--key", "3", "--handback", "2")
        _out, err = train.communicate(timeout=120)
    finally:
        if train.poll() is None:
            train.kill()
    assert train.returncode == 0, f"the program failed: {err}"
    assert [a["label"] for a in report["hello"]["actions"]] == ["left", "right", "forward"]
    assert report["hello"]["buttons"] == ["left [1]", "right [2]", "forward [3]"]
    asked = report["first"]["asked"]
    assert asked is not None and report["first"]["answers"] > 0
    # 16 values and a count, not 2835; the table's first 24 rows and a row that says how many more.
    assert asked["obsLine"].endswith("(2819 more of 2835 values)"), asked["obsLine"]
    assert asked["tableRows"] == 25
    assert report["first"]["tallest"] < 1400, report["first"]["tallest"]
    assert report["handed"]["end"]["title"].startswith(("Solved at step", "Not solved in 200 steps"))
    # The second question was handed back (Esc): the agent's questions in the next 100 steps of that episode went
    # back to it unasked (logged unanswered with no time), not shown to the person again.
    with open(tmp_path / "run" / "queries.csv") as f:
        rows = list(csv.DictReader(f))
    back = [i for i, r in enumerate(rows) if r["answered"] == "false" and float(r["response_s"]) > 0]
    assert len(back) == 1 and report["first"]["handedBack"] == 1, rows
    after = [r for r in rows[back[0] + 1:] if r["episode"] == rows[back[0]]["episode"]
             and int(r["step"]) < int(rows[back[0]]["step"]) + 100]
    assert after, "the agent did not ask again in that episode: nothing to check"
    assert all(r["answered"] == "false" and float(r["response_s"]) == 0.0 for r in after), after
    # Later episodes are asked again as before.
    assert all(r["answered"] == "true" for r in rows[back[0] + 1:] if r not in after), rows
    assert report["first"]["questions"] == sum(r["answered"] == "true" for r in rows)


def test_an_environment_refused_prints_no_url(capfd):
    import gymnasium as gym
    import pytest

    import arld

    class Endless(gym.Env):
        observation_space = gym.spaces.Box(-1.0, 1.0, (3,))
        action_space = gym.spaces.Discrete(2)

    web = arld.WebExpert(wait=False)
    with pytest.raises(ValueError, match="no time limit"):
        arld.Agent("adqn", Endless(), expert=web, seed=0)
    out, _ = capfd.readouterr()
    assert "http://" not in out, "the URL was printed for a run that was refused"
    assert web.url.startswith("http://127.0.0.1:")


def start_run_with(script, *argv):
    """Starts the Python program `script` with arguments `argv` after checking the prerequisites; returns the
    process and the URL it printed."""
    missing = missing_prerequisites()
    assert not missing, (
        f"the web expert's browser test cannot run; missing: {', '.join(missing)}; "
        "`scripts/test --setup` installs them"
    )
    train = subprocess.Popen([sys.executable, "-c", script, *map(str, argv)], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    for line in train.stdout:
        if "http://" in line:
            return train, line[line.index("http://"):].strip()
    train.kill()
    raise AssertionError(f"the program printed no URL: {train.stderr.read()}")


# Gymnasium's own Pendulum-v1 (actions in a box: one torque in [-2, 2]), rendered, in real time at 20 steps a
# second with a second of play per question; labels= names the torque's dimension. After learn the program waits
# for the file argv[2] (the page shows where the run stands meanwhile).
PENDULUM = r"""
import json, os, sys, time
import gymnasium as gym
import arld

env = gym.make("Pendulum-v1", render_mode="rgb_array")
web = arld.WebExpert(fps=20, segment_s=1.0, labels=["twist"])
model = arld.Agent("adqn", env, expert=web, seed=0, budget=100, eval_period=1500, eval_episodes=2)
model.learn(total_timesteps=3000, log_dir=sys.argv[1])
print(json.dumps({"summary": model.summary, "learned": model.num_timesteps,
                  "segment_len": model.config["segment_len"]}), flush=True)
while not os.path.exists(sys.argv[2]):
    time.sleep(0.05)
"""


def test_a_person_answers_a_gymnasium_box_task_with_a_pad_a_key_and_the_slider(tmp_path):
    """tests/e2e/continuous.mjs answers the page of a Python program's Pendulum: a pad's stick (scripted through the
    Gamepad API), the stick after the mapping is changed on the page, a held key and the slider, then it hands back.
    Every logged step of each segment must be the torque the control set, computed here from the control's position
    and the environment's own bounds; `learn` returns and the page shows the end screen."""
    import numpy as np

    missing = missing_prerequisites()
    assert not missing, f"missing: {', '.join(missing)}; `scripts/test --setup` installs them"
    # The screenshots (the end screen among them) where the Rust browser tests put theirs.
    run, shots = tmp_path / "run", REPO / "target" / "e2e-screenshots" / "python-box"
    go = tmp_path / "go"
    train, url = start_run_with(PENDULUM, run, go)
    try:
        out = subprocess.run(["node", "continuous.mjs", "--url", url, "--shots", str(shots), "--env", "Pendulum-v1"],
                             cwd=E2E, capture_output=True, text=True, timeout=300)
        go.touch()
        assert out.returncode == 0, f"the person failed: {out.stderr}{out.stdout}"
        report = json.loads([row for row in out.stdout.splitlines() if row.startswith("{")][-1])
        stdout, err = train.communicate(timeout=120)
    finally:
        if train.poll() is None:
            train.kill()
    assert train.returncode == 0, f"the program failed: {err}"
    import gymnasium as gym

    space = gym.make("Pendulum-v1").action_space
    low, high = float(space.low[0]), float(space.high[0])
    half, centre = (high - low) / 2, (high + low) / 2
    hello = report["hello"]
    assert hello["env"].startswith("Pendulum-v1") and hello["box"]["names"] == ["twist"], hello
    assert (hello["box"]["low"], hello["box"]["high"]) == ([low], [high])
    # The torque each control gave: the stick's x times the half-width, the held left arrow the lower bound (its
    # segment starts at once, the torque ramping down from the centre to it in 0.4 s), the slider its value.
    expected = [centre + 0.5 * half, centre - 0.25 * half, low, 0.8]
    lines = [json.loads(row) for row in (run / "answers.jsonl").read_text().splitlines()]
    questions = report["questions"]
    assert len(questions) >= 5, report
    # A second of play at 20 steps a second: 20 steps a question (fewer only where the episode's time limit cut
    # it), each lasting about its steps' time on the page.
    result = json.loads(stdout.strip().splitlines()[-1])
    assert result["segment_len"] == 20
    lengths = []
    for q, want in zip(questions, expected):
        first = next(row for row in lines if np.array_equal(np.float32(row["obs"]), np.float32(q["obs"])))
        segment = [row for row in lines if row["question_step"] == first["question_step"]]
        lengths.append(len(segment))
        # Paced at the real-time rate, never faster (a loaded machine may make it slower).
        assert 0.8 * (len(segment) - 1) / 20 <= q["segmentS"], (q, len(segment))
        assert segment and all(len(row["action"]) == 1 for row in segment), segment
        torques = [row["action"][0] for row in segment]
        if q["control"] == "keys":
            assert all(b <= a for a, b in zip(torques, torques[1:])), torques
            assert all(want <= t < centre for t in torques), torques
            assert len(torques) < 20 or torques[-1] == want, torques
        else:
            assert all(abs(t - want) < 1e-6 for t in torques), (q["control"], want, segment)
        assert all(row["expert"] == "web" and row["started_by"] == "rule" for row in segment)
    # learn returned: the page shows the end screen of the run the program has back; the budget spent is the
    # logged steps.
    assert max(lengths) == 20 and all(n <= 20 for n in lengths), lengths
    summary = json.loads((run / "summary.json").read_text())
    assert result["learned"] == 3000 and summary["train_steps"] == 3000
    assert summary["demos_queried"] == len(lines) <= 100
    end = report["endScreen"]
    solved = f"Solved at step {summary['steps_to_solve']} of 3000" if summary["solved"] else None
    assert end["title"] == (solved or "Not solved in 3000 steps"), end
    assert end["badge"] == "the program has the run" and end["handed"] is not None, end
    # (The questions the person did not hand back; the budget of 100 lets the person answer more than the four
    # above, with continuous.mjs' later gestures.)
    given = sum(1 for q in questions if not q["control"].startswith("handed back"))
    assert given >= 4 and end["outcome"]["answered"] == given, end
    assert end["rows"]["Questions answered"].startswith(str(given)), end
    assert (shots / "end-screen.png").is_file()
