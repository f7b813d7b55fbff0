"""Environments for arld: the built-in tasks as Gymnasium environments (`make`), and how any Gymnasium
environment is seen by arld's loop: its observations as flat vectors (`ObsCodec`), its time limit, and the facts
it is registered under.

Observation spaces, as Stable-Baselines3's policies see them:
- a one-dimensional `Box`: as it is;
- `Discrete`: one-hot (n values), as SB3 encodes it;
- `MultiDiscrete` (one-hot per part), `MultiBinary`, a `Box` of more dimensions, and `Dict` and `Tuple` of these:
  flattened by `gymnasium.spaces.flatten` (a `Dict` in its keys' order), as SB3's `MultiInputPolicy` concatenates
  them;
- images (a `Box` of three dimensions, or of `uint8` with two or more) are refused: wrap the environment in
  `gymnasium.wrappers.FlattenObservation` to train on the pixels as one vector, or give arld features.
Experts and `predict` take observations as the environment gives them.

Action spaces: `Discrete` (starting at 0: the DQN family learns) or a `Box` with finite bounds (TD3 learns). A `Box`
of more dimensions is flattened for arld's loop (`BoxActions`); the environment, `predict` and experts see actions
in the space's shape and dtype.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from . import _arld


@dataclass(frozen=True)
class BoxActions:
    """A `Box` action space as arld's loop sees it: flat vectors of float32 numbers in [low, high] (the bounds
    flattened in C order), shaped back as the space (`shape`, `dtype`) for the environment and for `predict`."""

    shape: Tuple[int, ...]
    low: Tuple[float, ...]
    high: Tuple[float, ...]
    dtype: str = "float32"

    @property
    def dim(self) -> int:
        return len(self.low)

    def flat(self, action: Any, who: str = "the expert") -> List[float]:
        """An action in the space's shape (or any array of `dim` numbers) as arld's flat vector."""
        try:
            a = np.asarray(action, dtype=np.float32).reshape(-1)
        except (TypeError, ValueError):
            raise TypeError(f"{who} must answer an action of shape {self.shape} (numbers), got {action!r}") from None
        if a.size != self.dim:
            raise TypeError(f"{who} must answer an action of shape {self.shape} ({self.dim} numbers), got "
                            f"{np.shape(action)}: {action!r}")
        return [float(v) for v in a]

    def shaped(self, flat: Sequence[float]) -> np.ndarray:
        """arld's flat vector as an action of the space (its shape and dtype)."""
        return np.asarray(flat, dtype=np.float32).reshape(self.shape).astype(self.dtype, copy=False)


def box_actions(space: Any, name: str) -> BoxActions:
    """The `BoxActions` of a `Box` action space, or ValueError when a bound is not finite (TD3's actor maps into
    the box)."""
    low = np.asarray(space.low, dtype=np.float64).reshape(-1)
    high = np.asarray(space.high, dtype=np.float64).reshape(-1)
    if not (np.all(np.isfinite(low)) and np.all(np.isfinite(high)) and np.all(low < high)):
        raise ValueError(
            f"{name}'s action space {space!r} needs finite bounds with low < high in every dimension (arld's actor "
            "acts inside the box): rescale it, e.g. with gymnasium.wrappers.RescaleAction, or clip it")
    return BoxActions(tuple(int(n) for n in space.shape), tuple(float(np.float32(v)) for v in low),
                      tuple(float(np.float32(v)) for v in high), str(np.dtype(space.dtype)))


# What a task's actions are: the number of discrete actions, or a box.
Actions = Union[int, BoxActions]
# (id, obs_dim, actions, max_episode_steps, reward_threshold): what arld's registry knows of an environment.
Facts = Tuple[str, int, Actions, int, Optional[float]]

_SUPPORTED = "supported: a Box, Discrete (one-hot), MultiDiscrete, MultiBinary, and Dict or Tuple of these (flattened)"


def _image(space: Any) -> bool:
    return isinstance(space, spaces.Box) and (
        len(space.shape) == 3 or (len(space.shape) >= 2 and space.dtype == np.uint8))


def _check_space(space: Any, name: str, where: str = "") -> None:
    """Refuses an observation space arld cannot flatten, saying what to use."""
    if _image(space):
        raise ValueError(
            f"arld's networks take flat vectors, and {name}'s observations{where} are images "
            f"({space.shape}, {space.dtype}): wrap the environment in gymnasium.wrappers.FlattenObservation to train "
            f"on the pixels as one vector of {int(np.prod(space.shape))} values, or give arld features of them "
            f"(an ObservationWrapper); {_SUPPORTED}")
    if isinstance(space, spaces.Dict):
        for key, sub in space.spaces.items():
            _check_space(sub, name, f"{where}[{key!r}]")
    elif isinstance(space, spaces.Tuple):
        for i, sub in enumerate(space.spaces):
            _check_space(sub, name, f"{where}[{i}]")
    elif not isinstance(space, (spaces.Box, spaces.Discrete, spaces.MultiDiscrete, spaces.MultiBinary)):
        raise ValueError(f"arld cannot use {name}'s observation space{where} {space!r}; {_SUPPORTED}")


class ObsCodec:
    """An observation space's observations as the flat float32 vectors arld's networks take, and back."""

    def __init__(self, space: Any, name: str) -> None:
        if space is None:
            raise ValueError(f"{name} has no observation_space")
        _check_space(space, name)
        self.space, self.name = space, name
        self.flat_box = isinstance(space, spaces.Box) and len(space.shape) == 1
        self.dim = int(spaces.flatdim(space))

    def flat(self, obs: Any) -> List[float]:
        """One observation as arld's vector."""
        if self.flat_box:
            flat: List[float] = np.asarray(obs, dtype=np.float32).reshape(-1).tolist()
        else:
            flat = np.asarray(spaces.flatten(self.space, obs), dtype=np.float32).tolist()
        return flat

    def raw(self, flat: Sequence[float]) -> Any:
        """arld's vector as the environment gives the observation (what experts are shown)."""
        if self.flat_box:
            return np.asarray(flat, dtype=np.float32)
        return spaces.unflatten(self.space, np.asarray(flat, dtype=np.float64))

    def rows(self, observation: Any) -> Tuple[List[List[float]], bool]:
        """One observation, or a batch of them (a leading axis, as a VecEnv gives them), as vectors; and whether
        it was a batch. Wrong shapes and NaN are refused."""
        n = _batch_size(self.space, observation)
        items = [observation] if n is None else [_item(self.space, observation, i) for i in range(n)]
        try:
            rows = [self.flat(o) for o in items]
        except Exception as e:
            raise ValueError(f"predict: not an observation of {self.name} ({self.space}): {e}") from None
        if any(len(r) != self.dim for r in rows):
            raise ValueError(
                f"predict: an observation of {self.name} has the shape of {self.space} (or a batch of them with a "
                f"leading axis); got {np.shape(observation) if not isinstance(observation, dict) else 'a dict'}")
        if not np.all(np.isfinite(np.asarray(rows, dtype=np.float32))):
            raise ValueError("predict: the observation holds NaN or infinity")
        return rows, n is not None


def _shape(space: Any) -> Tuple[int, ...]:
    return () if isinstance(space, spaces.Discrete) else tuple(space.shape)


def _batch_size(space: Any, obs: Any) -> Optional[int]:
    """The batch's length when `obs` has a leading batch axis over `space`'s shape; None for one observation."""
    if isinstance(space, spaces.Dict):
        key = next(iter(space.spaces))
        return _batch_size(space.spaces[key], obs[key])
    if isinstance(space, spaces.Tuple):
        return _batch_size(space.spaces[0], obs[0])
    shape = np.shape(obs)
    expected = _shape(space)
    if shape == expected:
        return None
    if len(shape) == len(expected) + 1 and shape[1:] == expected:
        return int(shape[0])
    raise ValueError(f"predict: an observation of this environment has shape {expected} (or (n, *{expected}) for n "
                     f"of them); got {shape}")


def _item(space: Any, obs: Any, i: int) -> Any:
    if isinstance(space, spaces.Dict):
        return {k: _item(s, obs[k], i) for k, s in space.spaces.items()}
    if isinstance(space, spaces.Tuple):
        return tuple(_item(s, o, i) for s, o in zip(space.spaces, obs))
    return np.asarray(obs)[i]


class EnvBridge:
    """A Gymnasium environment seen through arld's environment interface: reset(seed) -> obs list,
    step(action) -> (obs list, reward, terminated, truncated), and its generator (NumPy's PCG64) as words."""

    def __init__(self, env: Any, codec: ObsCodec) -> None:
        self.env = env
        self.flat = codec.flat
        space = getattr(env, "action_space", None)
        self.box = box_actions(space, env_name(env)) if isinstance(space, spaces.Box) else None
        # What the last step gave, as the environment gave it (callbacks' new_obs and infos): the observation
        # the agent acts on next (the reset's after an episode's end), the step's info, and the observation that
        # ended the episode.
        self.obs: Any = None
        self.info: Dict[str, Any] = {}
        self.final_obs: Any = None

    def reset(self, seed: Optional[int]) -> List[float]:
        obs, _info = self.env.reset() if seed is None else self.env.reset(seed=int(seed))
        self.obs = obs
        return self.flat(obs)

    def step(self, action: Any) -> Tuple[List[float], float, bool, bool]:
        """One step with arld's action: an int, or a flat list of floats for a Box (shaped as the space)."""
        if self.box is not None:
            action = self.box.shaped(action)
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.obs = self.final_obs = obs
        self.info = info
        return self.flat(obs), float(reward), bool(terminated), bool(truncated)

    def _bit_generator(self) -> Any:
        rng = getattr(getattr(self.env, "unwrapped", self.env), "_np_random", None)
        bg = getattr(rng, "bit_generator", None)
        return bg if type(bg).__name__ == "PCG64" else None

    def generator(self) -> Optional[List[int]]:
        bg = self._bit_generator()
        if bg is None:
            return None
        st = bg.state
        mask = (1 << 64) - 1
        s, inc = st["state"]["state"], st["state"]["inc"]
        return [s >> 64, s & mask, inc >> 64, inc & mask, int(st["has_uint32"]), int(st["uinteger"])]

    def set_generator(self, words: Sequence[int]) -> None:
        import numpy.random as npr

        unwrapped = getattr(self.env, "unwrapped", self.env)
        if self._bit_generator() is None:
            unwrapped._np_random = npr.Generator(npr.PCG64())
        bg = self._bit_generator()
        bg.state = {
            "bit_generator": "PCG64",
            "state": {"state": (words[0] << 64) | words[1], "inc": (words[2] << 64) | words[3]},
            "has_uint32": int(words[4]),
            "uinteger": int(words[5]),
        }


def is_vector_env(env: Any) -> bool:
    return hasattr(env, "num_envs") and (hasattr(env, "step_async") or hasattr(env, "single_action_space"))


def as_env(env: Any, max_episode_steps: Optional[int] = None) -> Any:
    """An environment as given: an id string is made with gym.make (as SB3 does); vector environments are
    refused; `max_episode_steps` wraps it in a TimeLimit (as gym.make(..., max_episode_steps=N) does)."""
    if isinstance(env, str):
        env = gym.make(env) if max_episode_steps is None else gym.make(env, max_episode_steps=max_episode_steps)
        return env
    if is_vector_env(env):
        raise TypeError(
            f"arld trains on one environment, not a vector of {env.num_envs} ({type(env).__name__}): pass a single "
            "environment, e.g. gym.make(\"CartPole-v1\") instead of gym.make_vec(...) or DummyVecEnv([...])"
        )
    if max_episode_steps is not None:
        env = gym.wrappers.TimeLimit(env, max_episode_steps=int(max_episode_steps))
    return env


def time_limit(env: Any) -> Optional[int]:
    """The steps after which `env` truncates an episode: the tightest TimeLimit among its wrappers, else its
    spec's max_episode_steps, else the limit an environment that truncates itself declares (`max_steps`, as
    MiniGrid's); None when it declares none."""
    limits = []
    e = env
    while isinstance(e, gym.Wrapper):
        if isinstance(e, gym.wrappers.TimeLimit):
            limits.append(int(e._max_episode_steps))
        e = e.env
    if limits:
        return min(limits)
    spec_limit = getattr(getattr(env, "spec", None), "max_episode_steps", None)
    if spec_limit is not None:
        return int(spec_limit)
    own = getattr(getattr(env, "unwrapped", env), "max_steps", None)
    if isinstance(own, (int, np.integer)) and not isinstance(own, bool) and own > 0:
        return int(own)
    return None


def env_name(env: Any) -> str:
    spec = getattr(env, "spec", None)
    return getattr(spec, "id", None) or type(getattr(env, "unwrapped", env)).__name__


def env_facts(env: Any) -> Facts:
    """(id, obs_dim, actions, max_episode_steps, reward_threshold) of a Gymnasium environment, or ValueError;
    `actions` is the number of discrete actions, or the `BoxActions` of a Box."""
    if isinstance(env, BuiltinEnv):
        return (env.id, env._core.spec[1], env.actions, env.max_episode_steps, env.reward_threshold)
    act_space: Any = getattr(env, "action_space", None)
    name = env_name(env)
    actions: Actions
    if isinstance(act_space, spaces.Box):
        actions = box_actions(act_space, name)
    elif type(act_space).__name__ != "Discrete" or getattr(act_space, "start", 0) != 0:
        raise ValueError(
            f"arld needs a Discrete action space starting at 0 or a Box with finite bounds; {name} has {act_space!r}")
    else:
        actions = int(act_space.n)
    codec = ObsCodec(getattr(env, "observation_space", None), name)
    limit = time_limit(env)
    if limit is None:
        raise ValueError(
            f"{name} has no time limit; arld needs one: gym.make(..., max_episode_steps=N), a "
            "gymnasium.wrappers.TimeLimit, or Agent(..., max_episode_steps=N)"
        )
    threshold = getattr(getattr(env, "spec", None), "reward_threshold", None)
    return (name, codec.dim, actions, limit, threshold)


def codec_of(env: Any) -> ObsCodec:
    return ObsCodec(getattr(env, "observation_space", None), env_name(env))


def register(facts: Facts) -> str:
    """Registers a Python environment's facts; returns the id arld knows it by: the Gymnasium id, or, when that
    id is known with other facts (a built-in task re-limited or wrapped, or another wrapper of the same id in
    this process), the id with the facts that tell it apart."""
    name, obs_dim, actions, limit, threshold = facts
    if isinstance(actions, BoxActions):
        shown = f"action_low={list(actions.low)},action_high={list(actions.high)}"
    else:
        shown = f"n_actions={actions}"
    candidates = [
        name,
        f"{name}[max_episode_steps={limit},reward_threshold={threshold}]",
        f"{name}[max_episode_steps={limit},reward_threshold={threshold},obs_dim={obs_dim},{shown}]",
    ]
    for i, candidate in enumerate(candidates):
        try:
            if isinstance(actions, BoxActions):
                _arld.register_box_env(candidate, obs_dim, list(actions.low), list(actions.high), limit, threshold)
            else:
                _arld.register_env(candidate, obs_dim, actions, limit, threshold)
            return candidate
        except ValueError:
            if i == len(candidates) - 1:
                raise
    raise AssertionError("unreachable")


def copy_env(env: Any) -> Any:
    """A second instance of an environment, wrappers included (a deep copy), for evaluation."""
    try:
        return copy.deepcopy(env)
    except Exception as e:
        raise ValueError(
            f"cannot copy {env!r} for the test episodes ({e}); pass eval_env= a list with one environment per "
            "test episode (eval_episodes)"
        ) from e


class BuiltinEnv(gym.Env[np.ndarray, Any]):
    """A built-in arld task as a Gymnasium environment (`arld.make`): stepped in Rust; when arld trains on it
    unwrapped, the whole run stays in Rust. Its actions are Discrete, or a float32 Box for the continuous tasks
    (Pendulum-v1, MountainCarContinuous-v0, LunarLanderContinuous-v3). It pickles (and copies) by id: a copy is a
    new environment."""

    metadata: Dict[str, Any] = {"render_modes": []}

    def __init__(self, env_id: str) -> None:
        self._core = _arld.BuiltinEnv(env_id)
        env_id, obs_dim, actions, limit, threshold = self._core.spec
        self.id = env_id
        self.observation_space = spaces.Box(-np.inf, np.inf, (obs_dim,), np.float32)
        # What arld's loop sees of its actions: their number, or the box.
        self.actions: Actions
        if isinstance(actions, int):
            self.actions = actions
            self.action_space: Any = spaces.Discrete(actions)
        else:
            low, high = actions
            self.actions = BoxActions((len(low),), tuple(low), tuple(high))
            self.action_space = spaces.Box(np.asarray(low, np.float32), np.asarray(high, np.float32),
                                           dtype=np.float32)
        self.spec = gym.envs.registration.EnvSpec(
            id=env_id, entry_point="arld:make", reward_threshold=threshold, max_episode_steps=limit,
            kwargs={"env_id": env_id})
        self.max_episode_steps = limit
        self.reward_threshold = threshold
        self.render_mode = None

    def reset(self, *, seed: Optional[int] = None,
              options: Optional[Dict[str, Any]] = None) -> Tuple[Any, Dict[str, Any]]:
        super().reset(seed=seed)
        return np.asarray(self._core.reset(seed), dtype=np.float32), {}

    def step(self, action: Any) -> Tuple[Any, float, bool, bool, Dict[str, Any]]:
        taken = int(action) if isinstance(self.actions, int) else self.actions.flat(action, "the action")
        obs, reward, terminated, truncated = self._core.step(taken)
        return np.asarray(obs, dtype=np.float32), reward, terminated, truncated, {}

    def render(self) -> None:
        """Nothing to render (render_mode None): arld's built-in tasks draw no frames from Python."""
        return None

    def __reduce__(self) -> Any:
        return (make, (self.id,))

    def __repr__(self) -> str:
        return f"arld.make({self.id!r})"


def make(env_id: str) -> BuiltinEnv:
    """A built-in environment (CartPole-v0/v1, Acrobot-v1, MountainCar-v0, LunarLander-v2/v3; with actions in a
    box: Pendulum-v1, MountainCarContinuous-v0, LunarLanderContinuous-v3) as a gymnasium.Env; training on it
    unwrapped runs entirely in Rust, without the GIL."""
    return BuiltinEnv(env_id)
