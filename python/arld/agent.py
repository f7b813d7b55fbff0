"""The Agent: arld's training loop (Rust) with Stable-Baselines3's shape; its configuration (the paper's presets or
SB3's DQN defaults), environments given as Gymnasium ones, saving and loading."""

from __future__ import annotations

import collections
import copy
import difflib
import json
import os
import shutil
import sys
import tempfile
import weakref
from pathlib import Path
from typing import (TYPE_CHECKING, Any, Deque, Dict, List, Literal, Optional, Protocol, Sequence, Tuple, TypedDict,
                    Union, cast)

import numpy as np

if TYPE_CHECKING:
    from typing_extensions import Unpack

from . import _arld
from .callbacks import _Callbacks, _EpisodeLog, _Logger, _ProgressBar, _stop_on_sigterm
from .envs import (BoxActions, BuiltinEnv, EnvBridge, ObsCodec, as_env as _as_env, codec_of as _codec_of,
                   copy_env as _copy_env, env_facts as _env_facts, make, register as _register)
from .experts import ExpertLike, WebExpert, _demos, _expert_callable, _shown_raw, gym_spaces

Method = Literal["dqn", "dqfd", "gdqn", "bdqn", "adqn", "adqnp"]
Net = Literal["plain", "bootstrap", "noisy"]
METHODS: Tuple[Method, ...] = ("dqn", "dqfd", "gdqn", "bdqn", "adqn", "adqnp")
NETS: Tuple[Net, ...] = ("plain", "bootstrap", "noisy")


class EnvLike(Protocol):
    """What arld needs of an environment: Gymnasium's spaces, reset and step (gymnasium.Env has them)."""

    @property
    def observation_space(self) -> Any: ...

    @property
    def action_space(self) -> Any: ...

    def reset(self, *, seed: Optional[int] = None, options: Optional[Dict[str, Any]] = None) -> Tuple[Any, Any]: ...

    def step(self, action: Any) -> Tuple[Any, Any, Any, Any, Any]: ...


# An environment: a Gymnasium one, or the id for gym.make.
Env = Union[str, EnvLike]
# Keys that name the run rather than tune it: given as arguments of Agent, not as keyword hyperparameters.
_IDENTITY = ("env", "method", "net", "seed")
# Stable-Baselines3's names for arld's keys of the same meaning.
SB3_NAMES = {
    "learning_rate": "lr",
    "buffer_size": "replay_size",
    "exploration_fraction": "eps_fraction",
    "exploration_initial_eps": "eps_start",
    "exploration_final_eps": "eps_end",
    "target_update_interval": "target_period",
    "max_grad_norm": "grad_clip",
    "lambda_margin": "lambda",
}
# defaults="sb3": Stable-Baselines3's DQN defaults in arld's keys. SB3 trains once num_timesteps > learning_starts
# (arld: >=), so its 100 is arld's 101, and acts uniformly at random before (random_before_learning); its
# target_update_interval counts environment steps from the first (target_period_in_steps), copying when
# _n_calls % 10,000 == 0. `train_steps` (the ε schedule's horizon) is each new run's learn(total_timesteps) unless
# given.
SB3_DEFAULTS: Dict[str, Any] = {
    "lr": 1e-4,
    "replay_size": 1_000_000,
    "learning_starts": 101,
    "batch_size": 32,
    "gamma": 0.99,
    "train_freq": 4,
    "target_period": 10_000,
    "target_period_in_steps": True,
    "random_before_learning": True,
    "eps_start": 1.0,
    "eps_end": 0.05,
    "eps_fraction": 0.1,
    "grad_clip": 10.0,
    "loss": "huber",
    "double_q": False,
    "prioritized": False,
    "hidden": [64, 64],
    "timeout_as_terminal": False,
}
DEFAULTS = ("arld", "sb3")


def _json_default(value: Any) -> Any:
    """NumPy numbers and arrays, and other sequences, as JSON sees them (for hyperparameters)."""
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, (tuple, range)):
        return list(value)
    raise TypeError(f"{value!r} ({type(value).__name__}) is not a number, boolean, string or list")


def _config_name(key: str, where: str) -> str:
    """arld's configuration key for the keyword `key` (SB3's name or arld's), or TypeError naming the closest."""
    name = SB3_NAMES.get(key, key)
    valid = set(config_keys())
    if name not in valid:
        close = difflib.get_close_matches(key, sorted(valid | set(SB3_NAMES)), n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        if key == "net_arch":
            hint = "; pass it as policy_kwargs=dict(net_arch=[...]), or as hidden=[...]"
        raise TypeError(f"{where} got an unexpected keyword argument {key!r}{hint} (valid hyperparameters: "
                        + ", ".join(sorted(valid | set(SB3_NAMES))) + ")")
    return name


def config_keys() -> List[str]:
    """Every hyperparameter keyword (the CLI's `--set` keys) that `Agent` accepts."""
    return [k for k in _arld.config_keys() if k not in _IDENTITY]


def preset(method: Method, env: str, net: Net = "bootstrap", seed: int = 0) -> Dict[str, Any]:
    """The paper's configuration for `method` with `net` on `env` (a Gymnasium id), as a dict."""
    return dict(json.loads(_arld.resolve_config(env, method, net, seed, [])))


# --------------------------------------------------------------------------------------------- environments


# The environments' part (observation spaces, time limits, registration, arld.make) is in envs.py.
_BuiltinEnv = BuiltinEnv


# Configuration keys that shape the network: they cannot change once the agent has one.
_SHAPE_KEYS = ("hidden", "heads", "algo")


# Every hyperparameter keyword of Agent (and of Agent.load, which applies them to the loaded agent): SB3's names
# where the meaning is the same, arld's names otherwise, and arld's names of SB3's too (lr, replay_size, ...). None
# is the preset's value. A TypedDict, so that a type checker catches a misspelt keyword.
Hyperparameters = TypedDict("Hyperparameters", {
    "learning_rate": Optional[float],
    "buffer_size": Optional[int],
    "batch_size": Optional[int],
    "gamma": Optional[float],
    "exploration_fraction": Optional[float],
    "exploration_initial_eps": Optional[float],
    "exploration_final_eps": Optional[float],
    "target_update_interval": Optional[int],
    "learning_starts": Optional[int],
    "train_freq": Optional[int],
    "max_grad_norm": Optional[float],
    "train_steps": Optional[int],
    "budget": Optional[int],
    "budget_unit": Optional[str],
    "segment_len": Optional[int],
    "t_query": Optional[float],
    "query_rule": Optional[str],
    "n_r": Optional[int],
    "heads": Optional[int],
    "hidden": Optional[Sequence[int]],
    "loss": Optional[str],
    "double_q": Optional[bool],
    "timeout_as_terminal": Optional[bool],
    "eps_greedy_on_top": Optional[bool],
    "prioritized": Optional[bool],
    "alpha": Optional[float],
    "beta0": Optional[float],
    "eps_agent": Optional[float],
    "eps_demo": Optional[float],
    "margin": Optional[float],
    "lambda_margin": Optional[float],
    "lambda_n": Optional[float],
    "n_step": Optional[int],
    "l2": Optional[float],
    "n_demo": Optional[int],
    "pretrain_steps": Optional[int],
    "queries_from_learning_starts": Optional[bool],
    "random_before_learning": Optional[bool],
    "algo": Optional[str],
    "tau": Optional[float],
    "policy_delay": Optional[int],
    "target_noise": Optional[float],
    "noise_clip": Optional[float],
    "exploration_noise": Optional[float],
    "target_entropy": Optional[float],
    "alpha_lr": Optional[float],
    "initial_alpha": Optional[float],
    "uncertainty": Optional[str],
    "target_period_in_steps": Optional[bool],
    "exact_factorised_var": Optional[bool],
    "expert_timeout": Optional[float],
    "demo_file": Optional[str],
    "eval_period": Optional[int],
    "eval_episodes": Optional[int],
    "checkpoint_every": Optional[int],
    "snapshot_every": Optional[int],
    "lr": Optional[float],
    "replay_size": Optional[int],
    "eps_start": Optional[float],
    "eps_end": Optional[float],
    "eps_fraction": Optional[float],
    "target_period": Optional[int],
    "grad_clip": Optional[float],
    "lambda": Optional[float],
}, total=False)

def _given_hyperparameters(given: Dict[str, Any], policy_kwargs: Optional[Dict[str, Any]]) -> Dict[str, Any]:
    """The hyperparameters given to Agent(), in arld's names (None: not given), with SB3's policy_kwargs net_arch
    as `hidden`; two names of one key, or net_arch and hidden of different widths, are refused."""
    hyper: Dict[str, Any] = {}
    for key, value in given.items():
        name = _config_name(key, "Agent()")
        if value is None:
            continue
        if name in hyper:
            raise TypeError(f"{key!r} and another name for {name!r} were both given")
        hyper[name] = value
    if policy_kwargs:
        unknown = set(policy_kwargs) - {"net_arch"}
        if unknown:
            raise TypeError(f"policy_kwargs: only net_arch is understood, not {', '.join(sorted(unknown))}")
        if "net_arch" in policy_kwargs:
            arch = policy_kwargs["net_arch"]
            if isinstance(arch, (dict, str, bytes)) or not hasattr(arch, "__iter__"):
                raise TypeError(
                    f"policy_kwargs: net_arch is the list of the hidden layers' widths, e.g. [256, 256]; got {arch!r}"
                )
            arch = list(arch)
            if "hidden" in hyper and list(hyper["hidden"]) != arch:
                raise TypeError("policy_kwargs net_arch and hidden= give different widths: give one of them")
            hyper["hidden"] = arch
    return hyper


class Agent:
    """An arld agent with Stable-Baselines3's shape: `Agent(method, env, net=..., expert=..., **hyperparameters)`.

    method: dqn, dqfd, gdqn, bdqn, adqn, adqnp (DQfD and ADQNP pre-train on demonstrations; GDQN, BDQN, ADQN,
    ADQNP ask the expert during training). net: plain, bootstrap (10 heads), noisy. env: a Gymnasium environment
    with a Discrete action space, or a Box one (continuous actions: TD3 learns them, with the same methods'
    queries; `predict`, experts and demos= give actions in the space's shape; dqfd and adqnp pre-train the actor
    by cloning the demonstrations; a WebExpert sets them with keys, sliders or a pad's sticks), exactly as given
    (wrappers, time limits), an id string (made with gym.make), or
    `arld.make(id)` (the built-in one: trained entirely in Rust). Observations reach the network as SB3's policies
    see them (a vector Box as it is, Discrete one-hot, MultiDiscrete/MultiBinary/Dict/Tuple flattened; images are
    refused: see arld.envs); experts and `predict` take them as the environment gives them. The time limit is the
    tightest TimeLimit wrapper, else the spec's, else what an environment that truncates itself declares
    (`max_steps`); `max_episode_steps=N` wraps the environment (and eval_env) in a TimeLimit of N steps.
    seed=None draws a seed (recorded in `seed` and config.toml).

    Queries: when the query rule fires, the expert takes over for a segment of up to `segment_len` (5) steps; the
    budget (`budget`) counts the demonstrated transitions (environment steps the expert acted), or the queries
    when `budget_unit="queries"`. `queries` lists every query (step, episode, uncertainty, threshold, actions).
    Evaluations: every `eval_period` environment steps, `eval_episodes` (20) test episodes with the test policy
    (no exploration) run on `eval_env` (copies of it, or of `env`); `evaluations` lists their returns.

    expert: a callable obs -> action, an object with SB3's predict(obs, deterministic=True), an arld.Agent, or
    an arld expert spec ("shipped:weak", "checkpoint:PATH", "cmd:python my_expert.py"). demos (dqfd, adqnp): a
    dict of columns (obs, actions, rewards, next_obs, terminated[, truncated]), imitation's transitions with
    rewards, `arld.collect_demos(env, expert, n, seed)`, or a Minari dataset (a MinariDataset, its id or its
    directory: an earlier run's answers exported with `arld.answers`); by default collected from the expert on `env`.

    Run length and schedules: `train_steps` is the run's length, the horizon of the schedules (ε anneals from
    `exploration_initial_eps` to `exploration_final_eps` over `exploration_fraction × train_steps` steps; PER's
    β anneals to 1 over `train_steps`), fixed when the agent is made (the paper's preset for its tasks, 100k
    otherwise). `learn(n)` trains n environment steps of that run; past `train_steps` ε and β keep their final
    values. So `learn(a)` then `learn(b, reset_num_timesteps=False)` is exactly `learn(a + b)`; `learn(n)` with
    the default reset_num_timesteps=True starts a new run from the network the last one left (SB3's second learn).

    Every hyperparameter is a keyword (None: the preset's value; `arld.preset(method, env_id)` shows them).
    SB3's names are accepted where the meaning is the same (learning_rate=lr, buffer_size=replay_size,
    exploration_fraction=eps_fraction, exploration_initial_eps=eps_start, exploration_final_eps=eps_end,
    target_update_interval=target_period, counted in updates (in environment steps as SB3 with defaults="sb3"),
    max_grad_norm=grad_clip).

    defaults="sb3": Stable-Baselines3's DQN defaults instead of the paper's preset (`arld.SB3_DEFAULTS`): a plain
    network (unless net= is given), learning_rate 1e-4, buffer_size 1M, batch 32, gamma 0.99, train_freq 4, the
    first update after step 100 (arld's learning_starts 101: SB3 starts when num_timesteps > learning_starts, arld
    when >=), uniformly random actions before it (random_before_learning), a target copy after every 10,000th
    environment step counted from the first, before that step's update, as SB3's `_n_calls %
    target_update_interval == 0` (target_update_interval 10,000 with target_period_in_steps), Huber loss,
    max_grad_norm 10, no double Q, no prioritized replay, ε from 1.0 to 0.05 over the first 10% of each new run's
    `learn(total_timesteps)` (unless train_steps= is given). Keywords given still win (in arld's units). One
    difference remains: `learn(n, reset_num_timesteps=False)` keeps the run's horizon, where SB3 stretches its
    schedule to num_timesteps + n. arld's horizon is the run's `train_steps`, part of its configuration
    (config.toml, the snapshot) and fixed for the run, which is what makes learn(a) then learn(b,
    reset_num_timesteps=False) equal learn(a + b); SB3's ε after the second learn depends on how the run was
    split. To have SB3's schedule of one learn(total), give train_steps=total when making the agent.

    Network: two hidden layers, 64 and 64 wide as in the paper; `hidden=[256, 256]` (or SB3's
    `policy_kwargs=dict(net_arch=[256, 256])`) sets their widths, and `hidden=[64, 64, 64]` adds a layer
    (1 to 8 layers).

    Hyperparameters (keywords; [default], "preset" when it depends on the task and method):

    - learning_rate: Adam's step size (lr) [preset: 1e-3 CartPole, 1e-4 others]
    - buffer_size: agent part of the replay memory (replay_size) [preset]
    - batch_size: minibatch size [32]
    - gamma: discount factor [preset]
    - exploration_fraction: fraction of train_steps over which ε anneals [0.1]
    - exploration_initial_eps: ε at the start (eps_start) [0.9]
    - exploration_final_eps: ε at the end (eps_end) [0.01]
    - target_update_interval: updates between target copies (target_period) [preset]; environment steps with
      target_period_in_steps
    - target_period_in_steps: target_update_interval counts environment steps from the first, as SB3 [False]
    - random_before_learning: uniformly random actions before learning_starts, as SB3 [False]
    - algo: the learner of an environment with a Box action space, "td3" or "sac" ["td3"]
    - tau: Polyak rate of a Box learner's target networks [0.005]
    - policy_delay: TD3's critic updates per actor update [2]
    - target_noise: TD3's target smoothing noise, in half-widths of the box [0.2]
    - noise_clip: the clip of TD3's target smoothing noise, in half-widths of the box [0.5]
    - exploration_noise: TD3's exploration noise, in half-widths of the box [0.1]
    - target_entropy: SAC's entropy target [-dim(A)]
    - alpha_lr: SAC's temperature learning rate [learning_rate]
    - initial_alpha: SAC's temperature before the first update [1]
    - uncertainty: what a Box learner's query rule reads, "critic_variance" (the critic heads' standard deviation at
      the action) or "action_disagreement" (the heads' disagreement about the best action) ["critic_variance"]
    - learning_starts: environment steps before the first update [500/1000]
    - train_freq: environment steps per update [1]
    - max_grad_norm: global gradient-norm clip (grad_clip) [10]
    - train_steps: the run's length: the schedules' horizon [preset]
    - budget: expert transitions (or queries) allowed during training [preset]
    - budget_unit: "transitions" or "queries" [transitions]
    - segment_len: expert steps per query [5]
    - t_query: ADQN's query fraction; BDQN's query probability [preset]
    - query_rule: when to ask, as a rule spec, e.g. "paced(horizon=0.1)" (docs/algorithm.md) [the method's own]
    - n_r: window of recent uncertainties [1000]
    - heads: bootstrapped heads [10]
    - hidden: widths of the hidden layers, 1 to 8 of them (net_arch) [64, 64]
    - loss: TD loss: "mse" or "huber" [mse]
    - double_q: double DQN targets [True]
    - timeout_as_terminal: treat truncation as terminal [False]
    - eps_greedy_on_top: ε-greedy also for bootstrap/noisy nets [True]
    - prioritized: prioritized replay [True]
    - alpha: priority exponent [0.6]
    - beta0: initial importance-sampling exponent [0.4]
    - eps_agent: priority bonus of agent transitions [0.001]
    - eps_demo: priority bonus of demonstrations [1.0]
    - margin: large-margin loss margin [0.8]
    - lambda_margin: weight of the margin loss (config key `lambda`) [preset]
    - lambda_n: weight of DQfD's n-step loss [0]
    - n_step: horizon of the n-step loss [10]; in a Box task the critics' n-step target [3]
    - l2: L2 weight [0]
    - n_demo: demonstrations collected before training (dqfd, adqnp) [preset]
    - pretrain_steps: pre-training updates (dqfd, adqnp) [preset]
    - queries_from_learning_starts: no queries before learning_starts [False]
    - exact_factorised_var: exact noisy-net variance [False]
    - expert_timeout: seconds an expert process may take per answer [30]
    - demo_file: demonstration file for pre-training [none]
    - eval_period: environment steps between evaluations [preset]
    - eval_episodes: test episodes per evaluation [20]
    - checkpoint_every: save weights every this many steps in the run dir [0: off]
    - snapshot_every: unused from Python (the run stays alive between learn calls)
    - max_episode_steps: wraps env and eval_env in a TimeLimit of this many steps [none]
    - policy_kwargs: SB3's dict(net_arch=[...]) (only net_arch); tensorboard_log: a folder for numbered run
      directories; verbose: 1 prints a line every log_interval episodes [0]; eval_env, demos, defaults: above
    """

    def __init__(
        self,
        method: Method,
        env: Env,
        net: Optional[Net] = None,
        expert: Optional[ExpertLike] = None,
        *,
        defaults: str = "arld",
        seed: Optional[int] = 0,
        eval_env: Union[Env, Sequence[Env], None] = None,
        demos: Any = None,
        policy_kwargs: Optional[Dict[str, Any]] = None,
        tensorboard_log: Optional[Union[str, os.PathLike]] = None,  # type: ignore[type-arg]
        verbose: int = 0,
        max_episode_steps: Optional[int] = None,
        **hyperparameters: Unpack[Hyperparameters],
    ) -> None:
        given: Dict[str, Any] = dict(hyperparameters)
        hyper = _given_hyperparameters(given, policy_kwargs)
        if method not in METHODS:
            raise ValueError(f"unknown method {method!r}; known: {', '.join(METHODS)}")
        if defaults not in DEFAULTS:
            raise ValueError(f"unknown defaults {defaults!r}; known: {', '.join(DEFAULTS)}")
        self.defaults = defaults
        self._horizon_from_learn = defaults == "sb3" and "train_steps" not in hyper
        if defaults == "sb3":
            hyper = {**{k: v for k, v in SB3_DEFAULTS.items() if k not in hyper}, **hyper}
            if net is None:
                net = "plain"
        if net is None:
            net = "bootstrap"
        if net not in NETS:
            raise ValueError(f"unknown net {net!r}; known: {', '.join(NETS)}")
        if seed is None:
            # As SB3: a seed drawn from the operating system's entropy, recorded in `seed` and config.toml.
            import secrets

            seed = secrets.randbits(62)
        self.method, self.net, self.seed = method, net, int(seed)
        self.verbose = int(verbose)
        self.tensorboard_log = None if tensorboard_log is None else str(tensorboard_log)
        self.policy_kwargs = dict(policy_kwargs or {})
        self._logger: Any = _Logger()
        self._expert_obj = expert
        # Hyperparameters changed (attributes set, Agent.load's keywords) since the last run began: they take effect
        # at the next new run; a run continued exactly keeps its configuration.
        self._changed: Dict[str, Any] = {}
        self._hyper = hyper
        self._max_episode_steps = max_episode_steps
        self._vec_env: Any = None
        self._set_env(env)
        self.eval_env = None if eval_env is None else _as_env(eval_env, max_episode_steps)
        self._check_eval_env()
        self._take_expert(expert, demos)
        self._take_demos(demos)
        self.config = self._resolve_given(given)  # fails early on a bad value
        self._clear_run()

    def _take_expert(self, expert: Optional[ExpertLike], demos: Any) -> None:
        """The expert the method asks (a callable, a web expert, or a spec arld builds), checked against the method."""
        method = self.method
        if expert is not None:
            self._expert, name = _expert_callable(expert, self._box)
            self._expert_name = name
            if self._expert is not None and not isinstance(expert, WebExpert):
                # Asked with the observation as the environment gives it (arld's loop holds flat vectors).
                self._expert = _shown_raw(self._expert, self._codec)
            if self._expert is None:
                self._hyper["expert"] = name
            elif method == "dqn":
                raise ValueError("dqn never asks an expert; drop expert=")
        else:
            self._expert, self._expert_name = None, ""
            if method != "dqn" and not (method == "dqfd" and demos is not None):
                raise ValueError(f"{method} needs an expert: pass expert= (or demos= for dqfd)")

    def _take_demos(self, demos: Any) -> None:
        """The demonstrations given for pre-training (dqfd, adqnp); with them DQfD runs no expert."""
        method = self.method
        if demos is not None and method not in ("dqfd", "adqnp"):
            raise ValueError(f"{method} does not pre-train on demonstrations; demos= is for dqfd and adqnp")
        self._demos = None if demos is None else _demos(demos, self._box)
        if demos is not None and method == "dqfd":
            # DQfD never asks during training: with demos= no expert runs, and the records say where the
            # demonstrations came from instead of naming one.
            self._hyper["demo_file"] = "python:demos"
            self._expert, self._expert_name = None, ""

    def _resolve_given(self, given: Dict[str, Any]) -> Dict[str, Any]:
        """The configuration of the hyperparameters, refused in the names the caller used (`given`)."""
        try:
            return self._resolve(self._hyper)
        except ValueError as e:
            if "net_arch" in self.policy_kwargs and "hidden" in str(e):
                raise ValueError(f"policy_kwargs net_arch (arld's hidden): {e}") from None
            message = str(e)
            for key in given:  # the names the caller used, where arld's differ
                if key in SB3_NAMES and given[key] is not None:
                    message = message.replace(f"`{SB3_NAMES[key]}`", f"`{key}` (arld's `{SB3_NAMES[key]}`)")
            if message != str(e):
                raise ValueError(message) from None
            raise

    def _clear_run(self) -> None:
        """No run yet: no policy, run, snapshot to continue, run directory, episodes, evaluations or queries."""
        self._policy: Any = None
        self._run: Any = None
        self._resume: Optional[str] = None
        self._run_dir: Optional[str] = None
        self._started_from: Optional[str] = None
        self._learner_dir: Optional[str] = None
        self._params_set = False
        self._bridge: Optional[EnvBridge] = None
        # The last 100 episodes' return, length and time (SB3's ep_info_buffer: Monitor's when it is there).
        self._ep_infos: Deque[Dict[str, float]] = collections.deque(maxlen=100)
        self._live_step = 0
        self._evaluations: List[Dict[str, Any]] = []
        # A loaded run's evaluations before its snapshot (the continued run reports those after it).
        self._prior_evaluations: List[Dict[str, Any]] = []
        self._queries: List[Dict[str, Any]] = []
        self.summary: Optional[Dict[str, Any]] = None

    # --- environments

    def _set_env(self, env: Any) -> None:
        env = _as_env(env, getattr(self, "_max_episode_steps", None))
        facts = _env_facts(env)
        self._builtin = isinstance(env, _BuiltinEnv)
        self.env_id = facts[0] if self._builtin else _register(facts)
        self._base_id = facts[0]
        self._facts = facts
        # The Box of a task with continuous actions (None for discrete actions).
        self._box: Optional[BoxActions] = facts[2] if isinstance(facts[2], BoxActions) else None
        self._codec = _codec_of(env)
        self.env = env
        self._vec_env = None

    def _check_eval_env(self) -> None:
        given = self.eval_env if isinstance(self.eval_env, (list, tuple)) else [] if self.eval_env is None else [
            self.eval_env]
        if any(_env_facts(e)[1:3] != self._facts[1:3] for e in given):
            raise ValueError("eval_env must have the same spaces as env")

    def get_env(self) -> Any:
        """The training environment as SB3 gives it: a DummyVecEnv of one environment (the one arld steps; a
        callback that steps it changes the run), or the environment itself when SB3 is not installed."""
        if self._vec_env is None:
            try:
                from stable_baselines3.common.vec_env import DummyVecEnv
            except ImportError:
                return self.env
            env = self.env
            self._vec_env = DummyVecEnv([lambda: env])
        return self._vec_env

    def get_vec_normalize_env(self) -> Any:
        """None: arld normalises no observations (SB3's VecNormalize is not used)."""
        return None

    @property
    def observation_space(self) -> Any:
        """The training environment's observation space (as it gives observations; arld flattens them)."""
        return self.env.observation_space

    @property
    def action_space(self) -> Any:
        """The training environment's action space."""
        return self.env.action_space

    @property
    def exploration_rate(self) -> float:
        """ε of the run's exploration at its current step (the preset's start before any run)."""
        if self._run is not None:
            return float(self._run.exploration_rate)
        return float(self.config.get("eps_start", 0.0))

    @property
    def n_envs(self) -> int:
        """1: arld trains on one environment."""
        return 1

    def set_env(self, env: Any, force_reset: bool = True) -> None:
        """Trains on `env` from the next `learn` that starts a run (same spaces; a live run keeps its own)."""
        env = _as_env(env, self._max_episode_steps)
        if _env_facts(env)[1:3] != self._facts[1:3]:
            raise ValueError("the new environment must have the same observation size and actions")
        self._set_env(env)
        self.config = self._resolve(self._hyper)

    # --- Stable-Baselines3's attributes

    @property
    def logger(self) -> Any:
        """The logger (SB3's `Logger` after `set_logger`, e.g. `configure(folder, ["csv", "stdout"])`): callbacks'
        `self.logger.record(...)` go to it, and arld records its own values (time/..., rollout/ep_rew_mean,
        rollout/ep_len_mean, rollout/exploration_rate, train/learning_rate, arld/budget_used, arld/queries,
        eval/mean_reward) and dumps them every `log_interval` episodes, as SB3's DQN does. Without set_logger it
        keeps the latest values and writes nowhere (SB3 with verbose=0)."""
        return self._logger

    def set_logger(self, logger: Any) -> None:
        """Uses `logger` (SB3's `stable_baselines3.common.logger.Logger`, or anything with record and dump)."""
        self._logger = logger

    def _set_hyper(self, key: str, value: Any) -> None:
        """Sets the hyperparameter `key` (SB3's or arld's name) for the next new run, checked now; a run continued
        exactly (learn(..., reset_num_timesteps=False)) refuses to start while it differs from the run's."""
        name = SB3_NAMES.get(key, key)
        if name in _SHAPE_KEYS and self._has_run() and self.config.get(name) != value:
            raise ValueError(f"{key} cannot change once the agent has a network: it is "
                             f"{self.config.get(name)!r} (start a new Agent for another network)")
        hyper = {**self._hyper, name: value}
        config = self._resolve(hyper)
        self._hyper, self.config = hyper, config
        if self._has_run():
            self._changed[key] = value

    def _has_run(self) -> bool:
        """Whether the agent has a run to go on from (live, closed, loaded, or a copy's)."""
        return self._run is not None or self._resume is not None

    def _check_continuable(self) -> None:
        if self._changed:
            shown = ", ".join(f"{k}={v!r}" for k, v in self._changed.items())
            raise ValueError(
                f"{shown} changed since the run began: a run continued exactly (learn(..., "
                "reset_num_timesteps=False)) keeps the configuration it began with; learn(n) starts a new run "
                "from this agent's network with the new values")

    @property
    def learning_rate(self) -> float:
        """Adam's step size (arld's `lr`); setting it applies from the next new run (learn with
        reset_num_timesteps=True)."""
        return float(self.config["lr"])

    @learning_rate.setter
    def learning_rate(self, value: float) -> None:
        self._set_hyper("learning_rate", float(value))

    @property
    def gamma(self) -> float:
        """The discount factor; setting it applies from the next new run."""
        return float(self.config["gamma"])

    @gamma.setter
    def gamma(self, value: float) -> None:
        self._set_hyper("gamma", float(value))

    @property
    def batch_size(self) -> int:
        """The minibatch size; setting it applies from the next new run."""
        return int(self.config["batch_size"])

    @batch_size.setter
    def batch_size(self, value: int) -> None:
        self._set_hyper("batch_size", int(value))

    @property
    def buffer_size(self) -> int:
        """The agent's part of the replay memory (arld's `replay_size`; demonstrations have room of their own);
        setting it applies from the next new run."""
        return int(self.config["replay_size"])

    @buffer_size.setter
    def buffer_size(self, value: int) -> None:
        self._set_hyper("buffer_size", int(value))

    @property
    def replay_buffer(self) -> Any:
        """Not available: arld's replay memory lives inside the run (in Rust, with the demonstrations and their
        priorities). `save` writes it with the rest of the run and `Agent.load` brings it back, so SB3's
        save_replay_buffer/load_replay_buffer have nothing to do (CheckpointCallback's save_replay_buffer=True
        finds no replay_buffer and writes the run alone, which holds it)."""
        raise AttributeError(
            "arld's replay memory lives inside the run (Rust), not in Python: agent.save(path) writes it with the "
            "whole run and Agent.load(path, env) brings it back")

    @property
    def device(self) -> str:
        """"cpu": arld trains on the CPU (one thread per run)."""
        return "cpu"

    def set_random_seed(self, seed: Optional[int] = None) -> None:
        """The seed of the next new run (every draw of a run comes from its seed); None does nothing, as SB3."""
        if seed is None:
            return
        self.seed = int(seed)
        self.config = self._resolve(self._hyper)
        if self._has_run():
            self._changed["seed"] = self.seed

    @property
    def policy(self) -> "AgentPolicy":
        """The network the agent acts with, as SB3's `model.policy`: predict, state_dict, and set_training_mode
        (which does nothing: arld's policy has no dropout or batch norm)."""
        return AgentPolicy(self)

    # --- configuration

    def _resolve(self, hyper: Dict[str, Any]) -> Dict[str, Any]:
        # A re-limited or wrapped built-in task keeps the paper's values for that task (resolved as for it).
        preset_of = self._base_id if (self.env_id != self._base_id
                                      and self._base_id in _arld.builtin_env_ids()) else None
        pairs = [(k, json.dumps(v, default=_json_default)) for k, v in hyper.items()]
        # A person in real time: a question's segment lasts their seconds of play unless segment_len is given.
        expert = getattr(self, "_expert", None)
        person = expert.spec if isinstance(expert, WebExpert) else None
        cfg = dict(json.loads(_arld.resolve_config(self.env_id, self.method, self.net, self.seed, pairs,
                                                   preset_of, person)))
        if self._expert_name and getattr(self, "_expert", None) is not None:
            cfg["expert"] = f"python:{self._expert_name}"  # what was asked, for config.toml
        return cfg

    # --- training

    @property
    def num_timesteps(self) -> int:
        """Environment steps of the current run so far."""
        return int(self._live_step)

    def _test_envs(self, episodes: int) -> List[Any]:
        """One environment per test episode (the test episodes run in lockstep): `eval_env` when it is a list of
        that length; otherwise `eval_env` (or a copy of `env`) and copies of it."""
        if isinstance(self.eval_env, (list, tuple)):
            if len(self.eval_env) != episodes:
                raise ValueError(
                    f"eval_env is a list of {len(self.eval_env)} environments, but there are {episodes} test "
                    "episodes (eval_episodes): give one environment per episode, or one to copy"
                )
            return list(self.eval_env)
        first = self.eval_env if self.eval_env is not None else _copy_env(self.env)
        return [first] + [_copy_env(first) for _ in range(episodes - 1)]

    def _log_dir(self, tb_log_name: Optional[str], reset: bool) -> Optional[str]:
        if self.tensorboard_log is None:
            return None
        name = tb_log_name or self.method.upper()
        root = Path(self.tensorboard_log)
        root.mkdir(parents=True, exist_ok=True)
        numbers = [int(p.name[len(name) + 1:]) for p in root.glob(f"{name}_*") if p.name[len(name) + 1:].isdigit()]
        n = max(numbers, default=0) + 1
        return str(root / f"{name}_{n}")

    def _learner_file(self) -> Optional[str]:
        """A snapshot of the last run (live, or loaded or closed) whose learner a new run begins with; None for a
        first run (or one that ended with an error: nothing to go on from); the weights given to set_parameters
        when there are some (a file of weights)."""
        if self._params_set:
            path = os.path.join(self._private_dir(), "given.safetensors")
            self._policy.save(path, {})
            return path
        if self._run is None:
            return self._resume
        if self._run.num_timesteps == 0:
            return self._started_from  # the learner it began with, untouched
        # One file per agent: the run it began the last run with has read it when its first step was taken.
        path = os.path.join(self._private_dir(), "learner.arld")
        try:
            self._run.save(path)
        except RuntimeError:
            return None
        return path

    def _private_dir(self) -> str:
        """A directory of this agent's own, removed with it."""
        if self._learner_dir is None:
            self._learner_dir = tempfile.mkdtemp(prefix="arld-agent-")
            weakref.finalize(self, shutil.rmtree, self._learner_dir, True)
        return self._learner_dir

    def _start_run(self, log_dir: Optional[str], resume: Optional[str], start_from: Optional[str] = None) -> Any:
        if self._builtin:
            # Trained entirely in Rust; the test episodes too, unless eval_env is another environment.
            env = demo_env = None
            given = self.eval_env if isinstance(self.eval_env, (list, tuple)) else [self.eval_env]
            if all(e is None or (isinstance(e, _BuiltinEnv) and e.id == self.env_id) for e in given):
                test_envs = None
            else:
                test_envs = [EnvBridge(e, _codec_of(e)) for e in self._test_envs(self.config["eval_episodes"])]
        else:
            env = EnvBridge(self.env, self._codec)
            test_envs = [EnvBridge(e, _codec_of(e)) for e in self._test_envs(self.config["eval_episodes"])]
            demo_env = EnvBridge(self.env, self._codec)
        # The run writes its directory until it ends, maybe after the working directory changed: fix it now.
        log_dir = None if log_dir is None else os.path.abspath(log_dir)
        self._run_dir = log_dir
        # The training environment's bridge: what its last step gave (callbacks' locals).
        self._bridge = env
        return _arld.start_run(json.dumps(self.config), {
            "env": env, "test_envs": test_envs, "expert": self._expert, "expert_name": self._expert_name,
            "demos": self._demos, "log_dir": log_dir, "resume": resume, "start_from": start_from,
            "demo_env": demo_env,
        })

    def learn(
        self,
        total_timesteps: int,
        callback: Any = None,
        log_interval: Optional[int] = 4,
        tb_log_name: Optional[str] = None,
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
        log_dir: Optional[Union[str, os.PathLike]] = None,  # type: ignore[type-arg]
    ) -> "Agent":
        """Trains `total_timesteps` environment steps with arld's loop and returns self.

        reset_num_timesteps=True (as SB3) starts a new run that keeps the network: the weights, target network and
        optimiser go on from where the last run (live, closed, loaded or copied) left them, and the counters
        begin again (num_timesteps, episodes, the ε and β schedules, learning_starts), with a new replay memory,
        budget and evaluations, and the hyperparameters as they are now (attributes set, Agent.load's
        keywords). False continues the current run exactly (network, optimiser, replay, schedules, budget,
        generators), so learn(a) then learn(b, reset_num_timesteps=False) equals learn(a + b) byte for byte, and
        Agent.load(path, env).learn(n, reset_num_timesteps=False) goes on as if the run had not been saved.
        callback: SB3-style callback objects
        (BaseCallback subclasses, CallbackList, EvalCallback, CheckpointCallback, StopTrainingOn...) or a callable
        (locals, globals) -> bool, called after every step with the live model (predict, get_parameters, save,
        evaluations and queries are those of that step; a save is written when the callback returns); returning
        False stops training there (the run can be continued). One learn is one rollout: on_rollout_start when it
        begins, on_rollout_end when it returns. An exception from a callback, a Python expert or the environment
        (its step or reset) pauses the run whole (num_timesteps, weights, replay, queries and budget kept; the
        expert's open question is asked again, the environment's step or reset is taken again): learn raises it
        with a note, with a run directory a snapshot is written there, and learn(..., reset_num_timesteps=False)
        goes on as if it had not happened. log_dir (or tensorboard_log= of the agent, in numbered folders
        <tb_log_name>_<n>) writes the run directory: config.toml, CSVs, TensorBoard events, weights,
        summary.json; the run holds its lock (.arld.lock) until close() (or a new run), so no other Agent or
        `arld train` writes there meanwhile. log_interval: with verbose >= 1, a line on standard output every
        log_interval finished episodes (as SB3's DQN); None or a verbose of 0 prints none (the run directory and
        TensorBoard get every value either way).
        """
        if total_timesteps < 1:
            raise ValueError(f"total_timesteps must be at least 1, got {total_timesteps}")
        if log_interval is not None and (not isinstance(log_interval, (int, np.integer)) or log_interval < 1):
            raise ValueError(f"log_interval must be a whole number of episodes, 1 or more (or None); got "
                             f"{log_interval!r}")
        start = 0
        if self._has_run() and not reset_num_timesteps:
            self._check_continuable()
        if self._run is not None and not reset_num_timesteps:
            start = self._run.num_timesteps
        elif self._run is None and self._resume is not None and not reset_num_timesteps:
            start = self._live_step
            self._run = self._start_run(None if log_dir is None else str(log_dir), self._resume)
            self._resume = None
        else:
            # A new run (SB3's reset_num_timesteps=True): steps, schedules, replay, budget and evaluations
            # start afresh; the learner (weights, target, optimiser) goes on from where the last run left it.
            start_from = self._learner_file()
            if self._run is not None:
                self._run.close()
                self._run = None
            self._resume = None
            self._changed = {}
            self._prior_evaluations = []
            directory = str(log_dir) if log_dir is not None else self._log_dir(tb_log_name, True)
            if self._horizon_from_learn:
                # As SB3: the ε schedule runs over this learn's total_timesteps.
                self.config = self._resolve({**self._hyper, "train_steps": int(total_timesteps)})
            self._run = self._start_run(directory, None, start_from)
            self._started_from, self._params_set = start_from, False
            self._live_step = 0
            self._ep_infos.clear()
        until = start + int(total_timesteps)
        label = f"{self.method.upper()}-{self.net}"
        episode_log = _EpisodeLog(int(log_interval), label) if self.verbose >= 1 and log_interval else None
        callbacks = None
        logs = log_interval is not None and not isinstance(self._logger, _Logger)
        if callback is not None or episode_log is not None or logs:
            callbacks = _Callbacks(callback, self, int(total_timesteps), episode_log,
                                   int(log_interval) if logs and log_interval else None)
        bar = _ProgressBar(start, int(total_timesteps), label) if progress_bar else None
        if callbacks is not None:
            callbacks.start()
        try:
            with _stop_on_sigterm():
                self._live_step = self._run.advance(until, callbacks, bar)
        except BaseException as e:
            # The run paused whole (an exception from a callback, an expert or the environment, Ctrl-C) or
            # ended (an error of the run itself): it stands where its last step left it.
            self._live_step = self._run.num_timesteps
            if not isinstance(e, KeyboardInterrupt):
                if self._run_dir is not None and self._run.num_timesteps > 0:
                    path = os.path.join(self._run_dir, "snapshot.safetensors")
                    try:
                        self.save(path)
                    except RuntimeError:
                        pass  # the run ended: nothing to continue from
                    else:
                        if hasattr(e, "add_note"):  # Python 3.11 on
                            e.add_note(f"arld: the run's snapshot is in {path}")
                raise
            # A stop (Ctrl-C, SIGTERM), also while a person's question is open: the run paused whole (a question
            # open is asked again by the next learn). With a run directory, its snapshot goes there too.
            if self._run_dir is not None:
                path = os.path.join(self._run_dir, "snapshot.safetensors")
                self.save(path)
                print(f"arld: stopped; the run's snapshot is in {path} (learn(..., reset_num_timesteps=False) goes "
                      f"on in this process, Agent.load({path!r}) in another)", file=sys.stderr, flush=True)
            raise
        finally:
            if self._run is not None:
                try:
                    self._refresh()
                except RuntimeError:
                    pass
            if bar is not None:
                bar.close(self._live_step)
            if callbacks is not None:
                callbacks.end()
        if self.verbose >= 1 and self.summary is not None:
            score = self.summary.get("final_score")
            shown = "none yet" if score is None else f"{score:.1f}"
            print(f"arld {self.method}-{self.net} on {self.env_id}: {self._live_step} steps, last evaluation "
                  f"{shown}, demonstrated transitions asked for {self.summary['demos_queried']}")
        return self

    def close(self) -> None:
        """Ends the run's thread: its files are finished, and its run directory's lock (.arld.lock) is released,
        so that another Agent or `arld train --resume` may continue there. The agent keeps everything: predict,
        evaluations, queries and save work as before, and the next learn(..., reset_num_timesteps=False) continues
        the run as for an agent from Agent.load (in a run directory only when given again as log_dir). Nothing
        happens when no run is alive."""
        run = self._run
        if run is None:
            return
        if self._in_callback():
            raise RuntimeError("close() cannot be called from inside a callback; return False to stop training")
        if run.num_timesteps > 0:
            # The run's state, to continue from as from Agent.load of a save.
            keep = tempfile.mkdtemp(prefix="arld-closed-")
            weakref.finalize(self, shutil.rmtree, keep, True)
            path: Optional[str] = os.path.join(keep, "run.arld")
            try:
                run.save(path)
            except RuntimeError:
                path = None  # the run had ended: it cannot be continued
            self._refresh()
            self._prior_evaluations = list(self._evaluations)
            self._resume = path
        run.close()
        self._run = None

    def _refresh(self) -> None:
        run = self._run
        self._policy = run.policy()
        self._evaluations = self._with_prior(run.evaluations())
        self._queries = list(run.queries())
        # Its `expert` is the one that ran (python:<qualified name> for a Python expert), as in summary.json.
        self.summary = json.loads(run.summary())

    # --- acting

    def _in_callback(self) -> bool:
        """Whether this run's callback is running (on this thread): the live run is lent to it."""
        return self._run is not None and bool(self._run.in_callback)

    def _with_prior(self, evaluations: Any) -> List[Dict[str, Any]]:
        prior = self._prior_evaluations
        last = prior[-1]["step"] if prior else -1
        return prior + [e for e in evaluations if e["step"] > last]

    @property
    def evaluations(self) -> List[Dict[str, Any]]:
        """The run's evaluations (step, mean, std, min, max of the test returns), live inside a callback."""
        if self._in_callback():
            return self._with_prior(self._run.evaluations())
        return self._evaluations

    @evaluations.setter
    def evaluations(self, value: List[Dict[str, Any]]) -> None:
        self._evaluations = value

    @property
    def queries(self) -> List[Dict[str, Any]]:
        """The run's queries (step, episode, uncertainty, threshold, expert and agent action), live inside a
        callback."""
        if self._in_callback():
            return list(self._run.queries())
        return self._queries

    @queries.setter
    def queries(self, value: List[Dict[str, Any]]) -> None:
        self._queries = value

    def _require_policy(self) -> Any:
        if self._in_callback():
            return self._run.live_policy()
        if self._policy is None:
            raise RuntimeError("the agent has not been trained or loaded yet: call learn() or Agent.load()")
        return self._policy

    def predict(
        self,
        observation: Any,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = True,
    ) -> Tuple[np.ndarray, None]:
        """(action, None) for one observation, or (array of actions, None) for a batch of them (rows).
        deterministic=True: the test policy (greedy, bootstrap heads voting, mean noisy weights);
        False: the exploration policy of training at the run's current step (ε-greedy with the current ε, the
        episode's bootstrap head, sampled noise; `episode_start` begins a new episode). For a Box action space
        the actions are arrays of the space's shape and dtype (a batch: one more leading axis), the actor's
        action in either case (as SB3's TD3: its exploration noise belongs to training)."""
        rows, batch = self._codec.rows(observation)
        live = self._run.live_actions(rows) if deterministic and self._in_callback() else None
        if live is not None:
            actions = live
        else:
            policy = self._require_policy()
            if deterministic:
                actions = [policy.act(r) for r in rows]
            else:
                starts = np.zeros(len(rows), dtype=bool) if episode_start is None else np.broadcast_to(
                    np.asarray(episode_start, dtype=bool).reshape(-1), (len(rows),))
                actions = [policy.explore(r, bool(s)) for r, s in zip(rows, starts)]
        if self._box is not None:
            shaped = np.asarray(actions, dtype=np.float32).reshape((len(rows),) + self._box.shape)
            shaped = shaped.astype(self._box.dtype, copy=False)
            return (shaped if batch else shaped[0]), None
        out = np.asarray(actions, dtype=np.int64)
        return (out if batch else out.reshape(())), None

    # --- parameters, saving, loading

    def get_parameters(self) -> Dict[str, Dict[str, np.ndarray]]:
        """The network's weights: {"policy": {name: array}}, as in saved files: a DQN-family network's in PyTorch's
        layout and names; a TD3/SAC actor's as one flat `actor.params` (layer by layer, the weight `[in][out]`
        then the bias)."""
        policy = self._require_policy()
        with tempfile.TemporaryDirectory() as tmp:
            path = os.path.join(tmp, "w.safetensors")
            policy.save(path, {})
            return {"policy": _read_safetensors(path)}

    def set_parameters(self, load_path_or_dict: Any, exact_match: bool = True, device: str = "auto") -> None:
        """Sets the network's weights from `get_parameters()`'s dict ({"policy": {name: array}} or the inner dict),
        a weights file, or a saved agent (`save`'s file: its network). exact_match=False (as SB3's) takes the
        weights the dict has and keeps the others, ignoring names the network does not have; True wants every
        weight. Works before any learn (the network then has the configuration's shape).

        The agent acts with them (predict, save of weights), and the next new run (learn with
        reset_num_timesteps=True) trains from them (a DQN-family network; a TD3/SAC actor's weights are for acting
        only, its critics are not in them). A run continued exactly cannot take them: after set_parameters,
        learn(..., reset_num_timesteps=False) is refused until a new run begins."""
        _check_device(device)
        if isinstance(load_path_or_dict, (str, os.PathLike)):
            path = str(load_path_or_dict)
            if not os.path.exists(path) and os.path.exists(path + ".zip"):
                path += ".zip"
            if _arld.snapshot_config(path) is not None:
                policy = _arld.snapshot_policy(path)[0]
            else:
                policy, _meta = _load_policy(path)
        else:
            policy = self._policy_from_dict(load_path_or_dict, exact_match)
        current = self._policy if self._policy is not None else self._fresh_policy()
        if _policy_shape(policy) != _policy_shape(current):
            raise ValueError("the parameters are for another observation size, number of actions or action box")
        self._policy = policy
        self._params_set = self._box is None
        if self._has_run():
            self._changed["parameters"] = "set_parameters(...)"

    def _fresh_policy(self) -> Any:
        """A network of this agent's configuration (its weights to be set)."""
        if self._in_callback():
            return self._run.live_policy()
        return _arld.fresh_policy(json.dumps(self.config))

    def _policy_from_dict(self, given: Any, exact_match: bool) -> Any:
        params = dict(given.get("policy", given)) if isinstance(given, dict) else None
        if params is None:
            raise TypeError(f"set_parameters takes a dict of weights or a file's path, not {type(given).__name__}")
        current_policy = self._policy if self._policy is not None and not self._in_callback() else \
            self._fresh_policy()
        with tempfile.TemporaryDirectory() as tmp:
            path = os.path.join(tmp, "w.safetensors")
            # The network's description (kind, heads or layer widths, box) from the current weights' file.
            current_policy.save(path, {})
            current = _read_safetensors(path)
            metadata = _read_safetensors_metadata(path)
            missing, unexpected = sorted(set(current) - set(params)), sorted(set(params) - set(current))
            if exact_match and (missing or unexpected):
                raise ValueError(
                    "the parameters do not match the network"
                    + (f"; missing: {', '.join(missing)}" if missing else "")
                    + (f"; not in the network: {', '.join(unexpected)}" if unexpected else "")
                    + " (exact_match=False sets those the network has and keeps the others)")
            for name in sorted(set(params) & set(current)):
                shape = np.shape(params[name])
                if shape != current[name].shape:
                    raise ValueError(f"the parameter {name} has shape {shape}, the network's has "
                                     f"{current[name].shape}")
            merged = {**current, **{k: v for k, v in params.items() if k in current}}
            _write_safetensors(path, merged, metadata)
            return _load_policy(path)[0]

    def save(self, path: Union[str, os.PathLike]) -> None:  # type: ignore[type-arg]
        """Writes the run's full state (network, optimiser, replay, query state, generators: arld's run snapshot
        format) to `path` (".zip" added when it has no suffix, as SB3 does), so that `Agent.load(path,
        env).learn(n)` continues the run; an agent loaded from plain weights writes its weights. Inside a
        callback the file is written when the callback returns, with the run as it stands at that step."""
        path = str(path)
        if not Path(path).suffix:
            path += ".zip"
        if self._run is None:
            if self._resume is not None:
                shutil.copyfile(self._resume, path)
                return
            meta = {"env": self.env_id, "method": self.method, "net": self.net, "seed": str(self.seed)}
            self._require_policy().save(str(path), meta)
            return
        self._run.save(os.path.abspath(path))

    @classmethod
    def load(cls, path: Union[str, os.PathLike], env: Any = None,  # type: ignore[type-arg]
             device: str = "auto", custom_objects: Optional[Dict[str, Any]] = None, print_system_info: bool = False,
             force_reset: bool = True, *, expert: Any = None, eval_env: Any = None, demos: Any = None,
             policy_kwargs: Optional[Dict[str, Any]] = None, **kwargs: Unpack[Hyperparameters]) -> "Agent":
        """An agent from `save` (the run's full state; pass the environment, and the expert when it was a Python
        one) or from plain weights (`arld train`'s weights.safetensors: it acts only). A loaded run has its
        `evaluations` and its `queries` as the agent that saved it had them (both are in the file; a file written
        before the queries were kept there has none, and its run directory's queries.csv holds them).
        learn(n, reset_num_timesteps=False) continues the saved run exactly; learn(n) starts a new run from its
        network (as SB3's load then learn).

        Hyperparameter keywords (and `custom_objects`, as SB3 applies them: the keywords win) set the loaded
        agent's values, as SB3 sets them as attributes after loading: they apply to the next new run, and a run
        continued exactly refuses them (it keeps the configuration it was saved with). Those that shape the
        network (hidden, heads, algo, policy_kwargs' net_arch) cannot change and are refused when they differ.
        SB3's schedule and space objects in custom_objects (lr_schedule, exploration_schedule, clip_range,
        observation_space, action_space) have nothing to replace: arld's file holds no pickled objects.
        device: "auto" or "cpu" (arld trains on the CPU); print_system_info and force_reset are accepted as SB3's
        (the environment is reset when a run begins either way). demos: the demonstrations a DQfD or ADQNP run
        was given as demos= (they are not in the file), for its next new run to pre-train on."""
        _check_device(device)
        given: Dict[str, Any] = {k: v for k, v in dict(custom_objects or {}).items() if k not in _SB3_OBJECTS}
        given.update(kwargs)
        arch = given.pop("policy_kwargs", None) or policy_kwargs
        if arch:
            if set(arch) - {"net_arch"}:
                unknown = ", ".join(sorted(set(arch) - {"net_arch"}))
                raise TypeError(f"policy_kwargs: only net_arch is understood, not {unknown}")
            given["hidden"] = list(arch["net_arch"])
        for key in given:
            _config_name(key, "Agent.load()")
        path = str(path)
        if not os.path.exists(path) and os.path.exists(path + ".zip"):
            path += ".zip"
        if env is not None:
            env = _as_env(env)
            facts = _env_facts(env)
            env_id = facts[0] if isinstance(env, _BuiltinEnv) else _register(facts)
        config = _arld.snapshot_config(path)
        if config is None:
            if given:
                raise ValueError(f"{path} holds weights only (it acts, it does not train): "
                                 f"{', '.join(sorted(given))} have nothing to apply to")
            policy, meta = _load_policy(path)
            box = _box_of(policy)
            if env is not None:
                _id, obs_dim, actions, _limit, _thr = _env_facts(env)
                if box is None and not isinstance(actions, BoxActions):
                    if (obs_dim, actions) != (policy.obs_dim, policy.n_actions):
                        raise ValueError(
                            f"{path} has {policy.obs_dim} inputs and {policy.n_actions} actions, the environment "
                            f"{obs_dim} and {actions}"
                        )
                elif box is None or not isinstance(actions, BoxActions) or (
                        (obs_dim, actions.low, actions.high) != (policy.obs_dim, box.low, box.high)):
                    raise ValueError(f"{path} has {policy.obs_dim} inputs and acts in "
                                     f"{_actions_text(box or policy.n_actions)}; the environment has {obs_dim} "
                                     f"and {_actions_text(actions)}")
                box = actions if isinstance(actions, BoxActions) else None
            agent = cls.__new__(cls)
            agent.method = cast(Method, meta.get("method", "dqn"))
            agent.net = cast(Net, policy.net)
            agent.seed = int(meta.get("seed", 0))
            agent.env = env
            agent._codec = _codec_of(env) if env is not None else ObsCodec(
                gym_spaces().Box(-np.inf, np.inf, (policy.obs_dim,), np.float32), path)
            agent._max_episode_steps, agent._vec_env, agent._box = None, None, box
            agent.env_id = meta.get("env", "")
            agent.eval_env = eval_env
            agent._policy, agent._run, agent._resume, agent._live_step = policy, None, None, 0
            agent._hyper, agent.config = {}, {}
            agent.evaluations, agent.queries, agent.summary = [], [], None
            agent._prior_evaluations = []
            agent.verbose, agent.tensorboard_log, agent.policy_kwargs = 0, None, {}
            agent._logger, agent._expert_obj, agent._changed = _Logger(), expert, {}
            agent._started_from, agent._learner_dir, agent._params_set = None, None, False
            agent._bridge, agent._ep_infos = None, collections.deque(maxlen=100)
            return agent
        cfg = json.loads(config)
        if env is None:
            env = make(cfg["env"]) if cfg["env"] in _arld.builtin_env_ids() else None
            if env is None:
                raise ValueError(f"{path} trained on {cfg['env']}: pass that environment as env=")
            env_id = cfg["env"]
        if env_id != cfg["env"]:
            raise ValueError(f"{path} trained on {cfg['env']}, not {env_id}")
        spec = str(cfg.get("expert", ""))
        if expert is None and cfg["method"] != "dqn":
            if spec.startswith("python:"):
                raise ValueError(f"{path} was trained with the Python expert {spec[7:]}: pass it as expert=")
            expert = spec
        agent = cls(cfg["method"], env, cfg["net"], expert, seed=cfg["seed"], eval_env=eval_env, demos=demos)
        run_policy, _cfg, step, curve, queries = _arld.snapshot_policy(path)
        agent.config = cfg
        # The saved run's values are the agent's hyperparameters (what a new run resolves from).
        saved = {k: cfg[k] for k in config_keys() if k in cfg and k != "expert"}
        agent._hyper = {**saved, **agent._hyper}
        # The evaluations and the queries travel in the snapshot.
        agent._evaluations = list(json.loads(curve))
        agent._queries = list(queries)
        agent._prior_evaluations = list(agent._evaluations)
        agent.policy_kwargs = {"net_arch": list(cfg["hidden"])}
        agent._policy, agent._resume, agent._live_step = run_policy, path, step
        for key, value in given.items():
            if value is not None:
                agent._set_hyper(key, value)
        return agent

    # --- copies

    # What a copy does not take over as it is: the live run and its network (the copy gets them through a saved
    # file), views and files of this agent's own, and the expert as the run calls it (bound again).
    _NOT_COPIED = ("_run", "_policy", "_vec_env", "_expert", "_resume", "_started_from", "_learner_dir", "_logger",
                   "_bridge")

    def _copy_state(self) -> Dict[str, Any]:
        """The agent as plain data: its attributes and its run as the bytes `save` writes (as Agent.load would
        read them), its network's weights as a weights file's bytes."""
        if self._in_callback():
            raise RuntimeError("an agent cannot be copied or pickled inside its callback; save(path) there writes "
                               "the run as it stands at that step")
        if isinstance(self._expert_obj, WebExpert):
            raise TypeError("an agent asking a person (WebExpert) cannot be copied or pickled: save it with "
                            "agent.save(path) and go on with Agent.load(path, env, expert=arld.WebExpert(...))")
        state = {k: v for k, v in self.__dict__.items() if k not in self._NOT_COPIED}
        state["_logger"] = self._logger if isinstance(self._logger, _Logger) else _Logger()
        state["_expert_bound"] = self._expert is not None
        state["_run_bytes"] = state["_policy_bytes"] = None
        with tempfile.TemporaryDirectory() as tmp:
            if self._has_run():
                path = os.path.join(tmp, "run.arld")
                self.save(path)
                state["_run_bytes"] = Path(path).read_bytes()
            if self._policy is not None:
                path = os.path.join(tmp, "weights.safetensors")
                self._policy.save(path, {})
                state["_policy_bytes"] = Path(path).read_bytes()
        return state

    def __getstate__(self) -> Dict[str, Any]:
        """For pickle: the agent's data and its run's saved bytes (see __setstate__). The environments and the
        expert must pickle too (a lambda does not: save and Agent.load then, or copy.deepcopy in this process)."""
        state = self._copy_state()
        import pickle

        for what, obj in (("expert", self._expert_obj), ("environment", self.env), ("eval_env", self.eval_env)):
            try:
                pickle.dumps(obj)
            except Exception as e:
                raise TypeError(
                    f"cannot pickle this agent: its {what} {obj!r} cannot be pickled ({e}); save it with "
                    "agent.save(path) and load it with Agent.load(path, env, expert=...), or copy it in this process "
                    "with copy.deepcopy(agent)") from e
        return state

    def __setstate__(self, state: Dict[str, Any]) -> None:
        """An agent from `_copy_state`: it stands where the original stood, as an agent from Agent.load of its
        save (learn(n, reset_num_timesteps=False) continues the run exactly; learn(n) starts a new run from its
        network); its logger is SB3's default (none is copied)."""
        run_bytes, policy_bytes = state.pop("_run_bytes"), state.pop("_policy_bytes")
        bound = state.pop("_expert_bound")
        self.__dict__.update(state)
        self._run, self._vec_env, self._resume, self._policy = None, None, None, None
        self._started_from, self._learner_dir = None, None
        self._expert = None
        if bound:
            ask, _name = _expert_callable(self._expert_obj, self._box)
            self._expert = None if ask is None else _shown_raw(ask, self._codec)
        if run_bytes is not None:
            path = os.path.join(self._private_dir(), "copied.arld")
            Path(path).write_bytes(run_bytes)
            self._resume = path
            self._policy = _arld.snapshot_policy(path)[0]
        if policy_bytes is not None and (self._params_set or self._policy is None):
            path = os.path.join(self._private_dir(), "copied.safetensors")
            Path(path).write_bytes(policy_bytes)
            self._policy = _load_policy(path)[0]

    def __deepcopy__(self, memo: Dict[int, Any]) -> "Agent":
        """A copy standing where this agent stands (see __setstate__); the environments and the expert are deep
        copies (a function is shared, as deepcopy does)."""
        state = self._copy_state()
        other = type(self).__new__(type(self))
        memo[id(self)] = other
        other.__setstate__(copy.deepcopy(state, memo))
        return other

    def __repr__(self) -> str:
        return f"arld.Agent({self.method!r}, {self.env_id!r}, net={self.net!r}, seed={self.seed})"


# Stable-Baselines3's pickled objects that its load's custom_objects replace; arld's file holds none of them.
_SB3_OBJECTS = ("lr_schedule", "exploration_schedule", "clip_range", "observation_space", "action_space")


def _check_device(device: Any) -> None:
    if str(device) not in ("auto", "cpu"):
        raise ValueError(f"arld trains on the CPU: device must be \"auto\" or \"cpu\", got {device!r}")


def _load_policy(path: str) -> Tuple[Any, Dict[str, str]]:
    """The policy of a weights file (a TD3/SAC actor or a DQN-family network, whichever it holds), with the file's
    metadata."""
    policy, meta = _arld.Policy.load(path)
    return policy, dict(meta)


def _box_of(policy: Any) -> Optional[BoxActions]:
    """The Box a TD3/SAC policy acts in (flat, float32), None for a DQN-family network."""
    if policy.bounds is None:
        return None
    low, high = policy.bounds
    return BoxActions((len(low),), tuple(low), tuple(high))


def _policy_shape(policy: Any) -> Tuple[Any, ...]:
    """What two policies must share to stand for each other: inputs, and the actions or the box."""
    box = _box_of(policy)
    return (policy.obs_dim, policy.n_actions) if box is None else (policy.obs_dim, box.low, box.high)


def _actions_text(actions: Any) -> str:
    if isinstance(actions, BoxActions):
        return f"a Box of {actions.dim} dimensions from {list(actions.low)} to {list(actions.high)}"
    return f"{actions} discrete actions"


def _read_safetensors(path: str) -> Dict[str, np.ndarray]:
    data = Path(path).read_bytes()
    n = int.from_bytes(data[:8], "little")
    header = json.loads(data[8:8 + n])
    out: Dict[str, np.ndarray] = {}
    for name, info in header.items():
        if name == "__metadata__":
            continue
        start, end = info["data_offsets"]
        out[name] = np.frombuffer(data[8 + n + start:8 + n + end], dtype="<f4").reshape(info["shape"]).copy()
    return out


def _read_safetensors_metadata(path: str) -> Dict[str, str]:
    data = Path(path).read_bytes()
    n = int.from_bytes(data[:8], "little")
    return dict(json.loads(data[8:8 + n]).get("__metadata__", {}))


def _write_safetensors(path: str, params: Dict[str, Any], metadata: Optional[Dict[str, str]] = None) -> None:
    header: Dict[str, Any] = {} if not metadata else {"__metadata__": metadata}
    blobs = []
    offset = 0
    for name in sorted(params):
        arr = np.ascontiguousarray(np.asarray(params[name], dtype="<f4"))
        raw = arr.tobytes()
        header[name] = {"dtype": "F32", "shape": list(arr.shape), "data_offsets": [offset, offset + len(raw)]}
        blobs.append(raw)
        offset += len(raw)
    text = json.dumps(header).encode()
    text += b" " * (-len(text) % 8)
    Path(path).write_bytes(len(text).to_bytes(8, "little") + text + b"".join(blobs))


class AgentPolicy:
    """An agent's network as Stable-Baselines3's `model.policy` is used: `predict` (the agent's), `state_dict` (its
    weights, as get_parameters()["policy"]), `load_state_dict` (set_parameters), `set_training_mode`."""

    def __init__(self, agent: Agent) -> None:
        self.agent = agent

    def predict(self, observation: Any, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> Tuple[np.ndarray, None]:
        return self.agent.predict(observation, state, episode_start, deterministic)

    def state_dict(self) -> Dict[str, np.ndarray]:
        return self.agent.get_parameters()["policy"]

    def load_state_dict(self, state_dict: Dict[str, Any], strict: bool = True) -> None:
        self.agent.set_parameters({"policy": state_dict}, exact_match=strict)

    def set_training_mode(self, mode: bool) -> None:
        """Nothing to switch: arld's networks have no dropout or batch normalisation."""

    @property
    def observation_space(self) -> Any:
        return self.agent.observation_space

    @property
    def action_space(self) -> Any:
        return self.agent.action_space

    def __repr__(self) -> str:
        return f"policy of {self.agent!r}"
