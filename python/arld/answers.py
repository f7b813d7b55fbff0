"""A run's answers kept as a dataset: the steps the expert took in a run (`answers.jsonl` in its run directory)
written as a Minari dataset, and Minari datasets read back as demonstrations (`demos=`, or a demonstration file
for the command line's `demo_file`; the command line also reads a dataset in the Arrow format itself, by id or
directory, and `arld demo convert` writes one as a demonstration file for either kind of action).

    python -m arld.answers export RUN_DIR --dataset-id arld/cartpole-answers-v0
    python -m arld.answers to-demos arld/cartpole-answers-v0 answers.demos.jsonl [--env CartPole-v1]

Needs the `minari` package with its Arrow storage (`pip install "minari[arrow]"`); datasets are written in Minari's
Arrow format under Minari's dataset directory (`MINARI_DATASETS_PATH`, by default ~/.minari/datasets).

An episode of the dataset is one segment of the expert's control: the consecutive steps it took after one question
(or until the environment's episode ended there). `observations` holds the segment's states and the state after its
last step; `actions`, `rewards`, `terminations` and `truncations` are the steps' own; a segment that ends before
the environment's episode does (the expert handed back) ends with `truncations` true, so that learning
bootstraps there. `infos` has one row per observation: `step` (the run's step that acts from that observation;
after the last step, one more) and the segment's question, the same in every row: `episode` (the run's episode),
`question_step`, `agent_action` (what the agent proposed: its index, -1 when not known; for actions in a box its
numbers as a JSON list in a string, empty when not known), `uncertainty` and `threshold`
(NaN when the rule computed none), `response_s` (seconds the answer took; NaN for a program), `expert` (who
answered) and `started_by` (`rule`: the query rule asked; `person`: a person took over unasked on the web page).
Observations are arld's flat float32 vectors (a Box); actions are the task's: discrete (a `Discrete` space) or, for a
task with actions in a box, float32 vectors (a `Box` with the task's bounds), exactly as the run took them. The
dataset's metadata also holds `arld_env` (the run's environment) and `arld_run`.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import shutil
import sys
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple

import numpy as np

ANSWERS_FILE = "answers.jsonl"
CONFIG_FILE = "config.toml"

# The per-observation fields of a dataset's `infos`, in order.
INFO_FIELDS = ("step", "episode", "question_step", "agent_action", "uncertainty", "threshold", "response_s", "expert",
               "started_by")


def read_answers(run_dir: "str | os.PathLike[str]") -> List[Dict[str, Any]]:
    """The steps the expert took in the run in `run_dir` (its `answers.jsonl`), in order."""
    path = Path(run_dir) / ANSWERS_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no answer log; is {run_dir} a run directory of arld 0.1 or later?")
    steps = []
    with open(path, encoding="utf-8") as f:
        for lineno, line in enumerate(f, 1):
            if not line.strip():
                continue
            try:
                steps.append(json.loads(line))
            except json.JSONDecodeError as e:
                raise ValueError(f"{path}:{lineno}: malformed line ({e})") from None
    return steps


def segments(steps: List[Dict[str, Any]]) -> List[List[Dict[str, Any]]]:
    """The steps cut into the expert's segments: a new segment starts at another question, at a step that does not
    follow the previous one, or after the environment's episode ended."""
    out: List[List[Dict[str, Any]]] = []
    for s in steps:
        prev = out[-1][-1] if out else None
        if (prev is None or s["question_step"] != prev["question_step"] or s["step"] != prev["step"] + 1
                or prev["terminated"] or prev["truncated"] or s["episode"] != prev["episode"]):
            out.append([s])
        else:
            out[-1].append(s)
    return out


def _run_env(run_dir: Path) -> str:
    """The environment id of the run's configuration (the top-level `env = "..."` of config.toml)."""
    try:
        text = (run_dir / CONFIG_FILE).read_text(encoding="utf-8")
    except OSError as e:
        raise ValueError(f"{run_dir / CONFIG_FILE}: cannot read the run's environment ({e})") from None
    for line in text.splitlines():
        if line.startswith("["):
            break  # the top-level keys come before the first table
        match = re.fullmatch(r'env\s*=\s*"((?:[^"\\]|\\.)*)"\s*', line)
        if match:
            return str(json.loads(f'"{match.group(1)}"'))
    raise ValueError(f"{run_dir / CONFIG_FILE}: no `env = ...` line; is {run_dir} a run directory?")


def _number(x: Optional[float]) -> float:
    return math.nan if x is None else float(x)


def _buffer(index: int, seg: List[Dict[str, Any]], box: bool) -> Any:
    from minari.data_collector import EpisodeBuffer  # type: ignore[import-untyped, import-not-found, unused-ignore]
    first = seg[0]
    n = len(seg)
    observations = [s["obs"] for s in seg] + [seg[-1]["next_obs"]]
    truncations = [bool(s["truncated"]) for s in seg]
    if not seg[-1]["terminated"]:
        truncations[-1] = True  # handed back (or the episode was cut): learning bootstraps here
    question = {
        "episode": int(first["episode"]),
        "question_step": -1 if first.get("question_step") is None else int(first["question_step"]),
        "agent_action": _agent_action(first.get("agent_action"), box),
        "uncertainty": _number(first.get("uncertainty")),
        "threshold": _number(first.get("threshold")),
        "response_s": _number(first.get("response_s")),
        "expert": str(first.get("expert", "")),
        "started_by": str(first.get("started_by", "")),
    }
    # Plain lists: Minari stores a list of scalars as a column, while a one-dimensional array gets a shape its
    # reader cannot parse back (minari 0.5).
    infos: Dict[str, Any] = {"step": list(range(int(first["step"]), int(first["step"]) + n + 1))}
    for key, value in question.items():
        infos[key] = [value] * (n + 1)
    return EpisodeBuffer(
        id=index,
        observations=np.asarray(observations, dtype=np.float32),
        actions=np.asarray([s["action"] for s in seg], dtype=np.float32 if box else np.int64),
        rewards=np.asarray([s["reward"] for s in seg], dtype=np.float32),
        terminations=np.asarray([bool(s["terminated"]) for s in seg]),
        truncations=np.asarray(truncations),
        infos=infos,
    )


def _agent_action(proposal: Any, box: bool) -> Any:
    """The agent's proposal as the dataset's `infos` keep it: an index (-1 unknown), or for actions in a box its
    numbers as a JSON list in a string (empty unknown; Minari stores strings and scalars per row)."""
    if box:
        return "" if proposal is None else json.dumps([float(x) for x in proposal])
    return -1 if proposal is None else int(proposal)


def _box_bounds(env_id: str) -> Optional[Tuple[List[float], List[float]]]:
    """The bounds `(low, high)` of the actions of `env_id` when they are in a box, else None: a built-in task's
    own (and a registered one's, in this process), the bounds a Python environment's id states among its facts
    (`Id[...,action_low=[...],action_high=[...]]`), else Gymnasium's."""
    from . import _arld
    bounds = _arld.box_bounds(env_id)
    if bounds is not None:
        return bounds
    facts = re.search(r"action_low=\[([^\]]*)\],action_high=\[([^\]]*)\]", env_id)
    if facts:
        low, high = ([float(x) for x in part.split(",")] for part in facts.groups())
        return (low, high)
    if re.search(r"n_actions=\d+", env_id):
        return None
    base = env_id.split("[", 1)[0]
    bounds = _arld.box_bounds(base)
    if bounds is not None or base in _arld.builtin_env_ids():
        return bounds
    import gymnasium as gym
    space = gym.make(base).action_space
    if isinstance(space, gym.spaces.Box):
        return ([float(x) for x in space.low.reshape(-1)], [float(x) for x in space.high.reshape(-1)])
    return None


def _n_actions(env_id: str) -> int:
    """How many actions `env_id` has: a built-in environment's own count; for a Python environment arld tells
    apart by its facts (`Id[...,n_actions=N]`), that N; else Gymnasium's."""
    from . import _arld
    facts = re.search(r"n_actions=(\d+)", env_id)
    if facts:
        return int(facts.group(1))
    base = env_id.split("[", 1)[0]
    if base in _arld.builtin_env_ids():
        from .envs import make
        space = make(base).action_space
    else:
        import gymnasium as gym
        space = gym.make(base).action_space
    n = getattr(space, "n", None)
    if n is None:
        raise ValueError(f"{env_id} has no discrete actions ({space}); arld's answers are discrete actions")
    return int(n)


def export_minari(run_dir: "str | os.PathLike[str]", dataset_id: str, *, n_actions: Optional[int] = None,
                  description: Optional[str] = None, author: Optional[str] = None) -> Any:
    """Writes the answers of the run in `run_dir` as the Minari dataset `dataset_id` (`namespace/name-vN`, in
    Minari's Arrow format) and returns it (a `minari.MinariDataset`). `n_actions` defaults to the run's
    environment's. A run with no answers is an error (a dataset needs an episode)."""
    import gymnasium as gym
    import minari  # type: ignore[import-untyped, import-not-found, unused-ignore]
    from minari.dataset.minari_dataset import parse_dataset_id  # type: ignore[import-untyped, import-not-found, unused-ignore]
    from minari.storage import get_dataset_path  # type: ignore[import-untyped, import-not-found, unused-ignore]

    run_dir = Path(run_dir)
    steps = read_answers(run_dir)
    if not steps:
        raise ValueError(f"{run_dir / ANSWERS_FILE}: the run has no answers to export (the expert took no step)")
    env_id = _run_env(run_dir)
    obs_dim = len(steps[0]["obs"])
    bounds = _box_bounds(env_id)
    box = bounds is not None
    if box != isinstance(steps[0]["action"], list):
        raise ValueError(f"{run_dir / ANSWERS_FILE}: its actions ({steps[0]['action']!r}) are not {env_id}'s kind")
    if bounds is not None:
        if n_actions is not None:
            raise ValueError(f"n_actions is for discrete actions; {env_id}'s actions are in a box")
        low, high = (np.asarray(b, dtype=np.float32) for b in bounds)
        action_space: Any = gym.spaces.Box(low, high, low.shape, np.float32)
    else:
        action_space = gym.spaces.Discrete(_n_actions(env_id) if n_actions is None else int(n_actions))
    buffers = [_buffer(i, seg, box) for i, seg in enumerate(segments(steps))]
    parse_dataset_id(dataset_id)  # a malformed id is refused before anything is written
    path = get_dataset_path(dataset_id)
    if path.exists():
        raise ValueError(f"a Minari dataset {dataset_id} exists already ({path}); give another name or version")
    try:
        dataset = minari.create_dataset_from_buffers(
            dataset_id=dataset_id,
            buffer=buffers,
            observation_space=gym.spaces.Box(-np.inf, np.inf, (obs_dim,), np.float32),
            action_space=action_space,
            algorithm_name="arld answers",
            author=author,
            description=description or f"The expert's answers in the arld run {run_dir.resolve()} on {env_id}: one "
                                       "episode per segment of the expert's control.",
            data_format="arrow",
        )
        dataset.storage.update_metadata({"arld_env": env_id, "arld_run": str(run_dir.resolve())})
    except BaseException:
        shutil.rmtree(path, ignore_errors=True)  # no half-written dataset
        raise
    return dataset


def load_dataset(dataset: Any) -> Any:
    """A Minari dataset from a `MinariDataset`, a dataset id (`namespace/name-vN`, under Minari's dataset
    directory) or the path of a dataset's directory (the one holding `data/`)."""
    import minari  # type: ignore[import-untyped, import-not-found, unused-ignore]
    if isinstance(dataset, minari.MinariDataset):
        return dataset
    path = Path(dataset)
    if (path / "data" / "metadata.json").is_file():
        return minari.MinariDataset(path / "data")
    if path.name == "data" and (path / "metadata.json").is_file():
        return minari.MinariDataset(path)
    return minari.load_dataset(str(dataset))


def is_dataset(demos: Any) -> bool:
    """Whether `demos=` names a Minari dataset: a `MinariDataset`, or a string or path (an id or a directory)."""
    if isinstance(demos, (str, os.PathLike)):
        return True
    minari = sys.modules.get("minari")
    return minari is not None and isinstance(demos, minari.MinariDataset)


def minari_columns(dataset: Any) -> Dict[str, np.ndarray]:
    """The transitions of a Minari dataset (see `load_dataset`) as demonstration columns (`demos=`): each episode's
    steps in order, its last step marked truncated when it neither terminated nor was truncated, so that the
    episodes stay apart. Observations are flattened to float32 vectors; actions are discrete (an index each), or in a
    box (a `Box` action space: float32 vectors)."""
    import gymnasium as gym
    ds = load_dataset(dataset)
    box = isinstance(ds.action_space, gym.spaces.Box)
    cols: Dict[str, List[Any]] = {k: [] for k in ("obs", "actions", "rewards", "next_obs", "terminated", "truncated")}
    for ep in ds.iterate_episodes():
        n = len(ep.actions)
        if n == 0:
            continue
        obs = np.asarray(ep.observations, dtype=np.float32).reshape(n + 1, -1)
        actions = np.asarray(ep.actions)
        if box:
            actions = actions.astype(np.float32).reshape(n, -1)
        elif not np.issubdtype(actions.dtype, np.integer) or actions.reshape(n, -1).shape[1] != 1:
            raise ValueError(f"episode {ep.id} of {ds.spec.dataset_id} has actions of type {actions.dtype} and shape "
                             f"{actions.shape}: arld's demonstrations are discrete actions or vectors in a Box")
        else:
            actions = actions.reshape(n).astype(np.int64)
        terminated = np.asarray(ep.terminations, dtype=bool).reshape(n)
        truncated = np.asarray(ep.truncations, dtype=bool).reshape(n).copy()
        if not (terminated[-1] or truncated[-1]):
            truncated[-1] = True
        cols["obs"].append(obs[:-1])
        cols["next_obs"].append(obs[1:])
        cols["actions"].append(actions)
        cols["rewards"].append(np.asarray(ep.rewards, dtype=np.float32).reshape(n))
        cols["terminated"].append(terminated)
        cols["truncated"].append(truncated)
    if not cols["actions"]:
        raise ValueError(f"the Minari dataset {ds.spec.dataset_id} holds no transitions")
    return {k: np.concatenate(v) for k, v in cols.items()}


def write_demo_file(dataset: Any, path: "str | os.PathLike[str]", env_id: Optional[str] = None) -> int:
    """Writes a Minari dataset as an arld demonstration file (the command line's `demo_file`); `env_id` defaults
    to the run's environment kept in the dataset's metadata (`arld_env`). Returns the number of transitions."""
    ds = load_dataset(dataset)
    env_id = env_id or ds.storage.metadata.get("arld_env")
    if not env_id:
        raise ValueError(f"the Minari dataset {ds.spec.dataset_id} does not say its arld environment: give env_id")
    cols = minari_columns(ds)
    n = len(cols["actions"])
    ends = cols["terminated"] | cols["truncated"]
    episode = np.concatenate([[0], np.cumsum(ends)[:-1]]).astype(int)
    header: Dict[str, Any] = {"format": "arld-demos", "version": 1, "env": env_id,
                              "expert": f"minari:{ds.spec.dataset_id}", "seed": 0, "obs_dim": int(cols["obs"].shape[1])}
    box = cols["actions"].ndim == 2
    if box:
        low, high = (np.asarray(b, dtype=np.float32).reshape(-1) for b in (ds.action_space.low, ds.action_space.high))
        header.update({"action_dim": int(low.size), "low": [float(x) for x in low], "high": [float(x) for x in high]})
    else:
        header["n_actions"] = _n_actions(env_id)
    header.update({"transitions": n, "episodes": int(episode[-1]) + 1})
    tmp = Path(f"{path}.tmp")
    with open(tmp, "w", encoding="utf-8") as f:
        f.write(json.dumps(header) + "\n")
        for i in range(n):
            f.write(json.dumps({
                "episode": int(episode[i]), "obs": [float(x) for x in cols["obs"][i]],
                "action": [float(x) for x in cols["actions"][i]] if box else int(cols["actions"][i]),
                "reward": float(cols["rewards"][i]), "next_obs": [float(x) for x in cols["next_obs"][i]],
                "terminated": bool(cols["terminated"][i]), "truncated": bool(cols["truncated"][i])}) + "\n")
    os.replace(tmp, path)
    return n


def main(argv: Optional[List[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m arld.answers", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    ex = sub.add_parser("export", help="write a run's answers as a Minari dataset")
    ex.add_argument("run_dir")
    ex.add_argument("--dataset-id", required=True, help="namespace/name-vN")
    ex.add_argument("--description")
    ex.add_argument("--author")
    to = sub.add_parser("to-demos", help="write a Minari dataset as a demonstration file for demo_file")
    to.add_argument("dataset", help="a dataset id or a dataset's directory")
    to.add_argument("out")
    to.add_argument("--env", help="the arld environment id (default: the dataset's arld_env)")
    args = parser.parse_args(argv)
    try:
        if args.command == "export":
            ds = export_minari(args.run_dir, args.dataset_id, description=args.description, author=args.author)
            print(f"{args.dataset_id}: {ds.total_episodes} episodes, {ds.total_steps} steps")
        else:
            n = write_demo_file(args.dataset, args.out, args.env)
            print(f"{args.out}: {n} transitions")
    except (OSError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
