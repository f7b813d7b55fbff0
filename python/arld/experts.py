"""Experts from Python: a callable obs -> action, a model with Stable-Baselines3's predict, an arld.Agent, a
person in the browser (WebExpert) or an arld expert spec; and demonstrations (columns, imitation's transitions,
collect_demos)."""

from __future__ import annotations

from typing import Any, Callable, Dict, List, Optional, Protocol, Tuple, Union, cast

import numpy as np

from . import _arld
from .envs import BoxActions, ObsCodec, as_env as _as_env, box_actions as _box_actions, codec_of as _codec_of

# A person answering in the browser: arld.WebExpert(listen="127.0.0.1:0", fps=None, timeout=None, keys=None,
# wait=True, labels=None, segment_s=None) serves the page (its URL is .url, printed when learn starts the run); pass
# it as expert=
# (one run per WebExpert).
WebExpert = _arld.WebExpert


class Predicts(Protocol):
    """An expert with Stable-Baselines3's predict (asked with deterministic=True)."""

    def predict(self, observation: Any, *, deterministic: bool = ...) -> Tuple[Any, Any]: ...


# An expert: a callable obs -> action, a model with SB3's predict (an arld.Agent has it), a WebExpert, or an expert
# spec string.
ExpertLike = Union[str, Callable[[Any], Any], Predicts, _arld.WebExpert]


def _qualified(obj: Any) -> str:
    module = getattr(obj, "__module__", None) or type(obj).__module__
    name = getattr(obj, "__qualname__", None) or type(obj).__qualname__
    return f"{module}.{name}"


def _expert_callable(expert: Any, box: Optional[BoxActions] = None) -> Tuple[Optional[Callable[[Any], Any]], str]:
    """(callable obs -> action, name) for a Python expert (given observations as the environment gives them), or
    (None, spec) for an arld expert spec. The callable answers an int, or, for a task with actions in the box
    `box`, the action as a flat list of floats (the expert answers it in the space's shape)."""
    if isinstance(expert, str):
        return None, expert
    if isinstance(expert, WebExpert):
        # Not called from Python: the compiled part recognises it and drives the person's page.
        return cast(Callable[[Any], int], expert), "web"
    convert: Callable[[Any], Any] = _as_action if box is None else box.flat
    if hasattr(expert, "predict") and callable(expert.predict):
        # Stable-Baselines3's predict(obs, deterministic=True) -> (action, state); an arld.Agent has it too.
        def ask(obs: Any) -> Any:
            action, _state = expert.predict(obs, deterministic=True)
            return convert(action)

        return ask, _qualified(type(expert))
    if callable(expert):

        def ask_callable(obs: Any) -> Any:
            return convert(expert(obs))

        return ask_callable, _qualified(expert)
    raise TypeError(
        "expert must be a callable obs -> action, an object with predict(obs, deterministic=True) "
        f"(a Stable-Baselines3 model), an arld.Agent or an arld expert spec string; got {type(expert).__name__}"
    )


def gym_spaces() -> Any:
    from gymnasium import spaces

    return spaces


def _shown_raw(ask: Callable[[Any], Any], codec: ObsCodec) -> Callable[[Any], Any]:
    """`ask` given arld's flat vector as the environment gives the observation."""
    if codec.flat_box:
        return lambda flat: ask(np.asarray(flat, dtype=np.float32))
    return lambda flat: ask(codec.raw(flat))


def _as_action(action: Any) -> int:
    a = np.asarray(action)
    if a.size != 1 or not (np.issubdtype(a.dtype, np.integer) or np.issubdtype(a.dtype, np.bool_)):
        if a.size == 1 and np.issubdtype(a.dtype, np.floating) and float(a.reshape(-1)[0]).is_integer():
            return int(a.reshape(-1)[0])
        raise TypeError(f"the expert must answer one integer action, got {action!r}")
    return int(a.reshape(-1)[0])


class _Demos:
    """Demonstrations as rows for the compiled part: an int action per transition, or, for a task with actions in
    a box (`box`), a flat row of float32 numbers per transition (checked against the box there)."""

    def __init__(self, obs: Any, actions: Any, rewards: Any, next_obs: Any, terminated: Any, truncated: Any = None,
                 box: Optional[BoxActions] = None):
        n = len(actions)
        self.obs = np.asarray(obs, dtype=np.float32).reshape(n, -1).tolist()
        if box is None:
            self.actions: List[Any] = [int(a) for a in np.asarray(actions).reshape(-1)]
        else:
            self.actions = [[float(v) for v in row] for row in np.asarray(actions, dtype=np.float32).reshape(n, -1)]
        self.rewards = np.asarray(rewards, dtype=np.float32).reshape(-1).tolist()
        self.next_obs = np.asarray(next_obs, dtype=np.float32).reshape(n, -1).tolist()
        self.terminated = [bool(t) for t in np.asarray(terminated).reshape(-1)]
        self.truncated = [False] * n if truncated is None else [bool(t) for t in np.asarray(truncated).reshape(-1)]


def _demos(demos: Any, box: Optional[BoxActions] = None) -> _Demos:
    """Demonstrations from a dict of columns, from imitation's transitions (duck-typed: obs, acts, next_obs,
    dones, and rews; `infos[i]["TimeLimit.truncated"]` marks a truncation), or from a Minari dataset (a
    MinariDataset, a dataset id or a dataset's directory: `arld.answers.minari_columns`). With `box` (a task with
    actions in a box) each action is a row of numbers in the space's shape."""
    from . import answers
    if answers.is_dataset(demos):
        return _Demos(**answers.minari_columns(demos), box=box)
    if isinstance(demos, dict):
        return _Demos(**demos, box=box)
    if all(hasattr(demos, k) for k in ("obs", "acts", "next_obs", "dones")):
        rews = getattr(demos, "rews", None)
        if rews is None:
            raise ValueError(
                "these transitions carry no rewards (imitation's Transitions): DQfD learns from rewards; give "
                "TransitionsWithRew, a dict with rewards=, or arld.collect_demos(env, expert, n, seed)"
            )
        dones = np.asarray(demos.dones, dtype=bool).reshape(-1)
        infos = getattr(demos, "infos", None)
        truncated = np.zeros_like(dones)
        if infos is not None:
            truncated = np.array([bool(dict(i or {}).get("TimeLimit.truncated", False)) for i in infos], dtype=bool)
        return _Demos(demos.obs, demos.acts, rews, demos.next_obs, dones & ~truncated, truncated, box=box)
    raise TypeError("demos must be a dict of columns (obs, actions, rewards, next_obs, terminated[, truncated]), "
                    "imitation's transitions (obs, acts, rews, next_obs, dones) or a Minari dataset (its id or path)")


def collect_demos(env: Any, expert: Any, n: int, seed: int = 0) -> Dict[str, np.ndarray]:
    """`n` demonstration transitions of `expert` on `env` as given (wrappers applied): the first episode reset with
    `seed`, the next ones without; a dict of columns for `demos=`. In a task with actions in a `Box` the actions
    are rows of float32 numbers (the space's shape flattened)."""
    env = _as_env(env)
    codec = _codec_of(env)
    box = _box_actions(env.action_space, "the environment") if isinstance(env.action_space, gym_spaces().Box) else None
    ask, _name = _expert_callable(expert, box)
    if ask is None or isinstance(expert, WebExpert):
        raise TypeError("collect_demos needs a Python expert (a callable, an SB3 model or an arld.Agent)")
    cols: Dict[str, List[Any]] = {k: [] for k in ("obs", "actions", "rewards", "next_obs", "terminated", "truncated")}
    obs, _ = env.reset(seed=int(seed))
    while len(cols["actions"]) < n:
        flat = codec.flat(obs)
        a = ask(codec.raw(flat))  # what the expert sees during training
        nxt, r, te, tr, _ = env.step(a if box is None else box.shaped(a))
        for k, v in zip(cols, (flat, a, r, codec.flat(nxt), te, tr)):
            cols[k].append(v)
        obs = env.reset()[0] if te or tr else nxt
    return {
        "obs": np.asarray(cols["obs"], dtype=np.float32),
        "actions": np.asarray(cols["actions"], dtype=np.int64 if box is None else np.float32),
        "rewards": np.asarray(cols["rewards"], dtype=np.float32),
        "next_obs": np.asarray(cols["next_obs"], dtype=np.float32),
        "terminated": np.asarray(cols["terminated"], dtype=bool),
        "truncated": np.asarray(cols["truncated"], dtype=bool),
    }
