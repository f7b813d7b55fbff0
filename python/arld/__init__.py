"""arld from Python: Active Reinforcement Learning with Demonstration on any Gymnasium environment.

    import gymnasium as gym, arld
    model = arld.Agent("adqn", gym.make("CartPole-v1"), net="bootstrap", expert=my_expert, budget=200, seed=0)
    model.learn(total_timesteps=20_000, progress_bar=True)
    action = model.predict(obs)

The training loop is arld's own (Rust); Python is called only to step the environment and to ask the expert.
This module adapts Python objects (Gymnasium environments, callables, Stable-Baselines3 models) to the plain
interfaces of the compiled part `arld._arld` and gives them Stable-Baselines3's shape.
"""

import json

import numpy as np

from . import _arld

__version__ = _arld.__version__

__all__ = ["Agent", "WebExpert", "make", "preset", "config_keys", "METHODS", "NETS"]

# A person answering in the browser: arld.WebExpert(listen="127.0.0.1:0", fps=None, timeout=None, keys=None,
# wait=True) prints the page's URL (also .url); pass it as expert= (one run per WebExpert).
WebExpert = _arld.WebExpert

METHODS = ("dqn", "dqfd", "gdqn", "bdqn", "adqn", "adqnp")
NETS = ("plain", "bootstrap", "noisy")
# Keys that name the run rather than tune it: given as arguments of Agent, not as keyword hyperparameters.
_IDENTITY = ("env", "method", "net", "seed")


def config_keys():
    """Every hyperparameter keyword (the CLI's `--set` keys) that `Agent` accepts."""
    return [k for k in _arld.config_keys() if k not in _IDENTITY]


def preset(method, env, net="bootstrap", seed=0):
    """The paper's configuration for `method` with `net` on `env` (a Gymnasium id), as a dict."""
    return json.loads(_arld.resolve_config(env, method, net, seed, []))


# --------------------------------------------------------------------------------------------- environments


class _EnvBridge:
    """A Gymnasium environment seen through arld's environment interface: reset(seed) -> obs list,
    step(action) -> (obs list, reward, terminated, truncated)."""

    def __init__(self, env):
        self.env = env

    def reset(self, seed):
        obs, _info = self.env.reset() if seed is None else self.env.reset(seed=int(seed))
        return np.asarray(obs, dtype=np.float32).reshape(-1).tolist()

    def step(self, action):
        obs, reward, terminated, truncated, _info = self.env.step(action)
        return (
            np.asarray(obs, dtype=np.float32).reshape(-1).tolist(),
            float(reward),
            bool(terminated),
            bool(truncated),
        )


def _env_facts(env):
    """(id, obs_dim, n_actions, max_episode_steps, reward_threshold) of a Gymnasium environment, or ValueError."""
    if isinstance(env, _BuiltinEnv):
        return env._core.spec
    obs_space = getattr(env, "observation_space", None)
    act_space = getattr(env, "action_space", None)
    spec = getattr(env, "spec", None)
    name = getattr(spec, "id", None) or type(getattr(env, "unwrapped", env)).__name__
    if type(act_space).__name__ != "Discrete" or getattr(act_space, "start", 0) != 0:
        raise ValueError(
            f"arld needs a Discrete action space starting at 0; {name} has {act_space!r}"
        )
    shape = getattr(obs_space, "shape", None)
    if type(obs_space).__name__ != "Box" or shape is None or len(shape) != 1:
        raise ValueError(
            f"arld needs a flat Box observation space (one dimension); {name} has {obs_space!r}"
        )
    limit = getattr(spec, "max_episode_steps", None)
    if limit is None:
        raise ValueError(
            f"{name} has no time limit; arld needs one (gym.make(..., max_episode_steps=N) gives it one)"
        )
    threshold = getattr(spec, "reward_threshold", None)
    return (name, int(shape[0]), int(act_space.n), int(limit), threshold)


def _same_spec_env(env):
    """A second instance of a Gymnasium environment for evaluation."""
    import gymnasium as gym

    if getattr(env, "spec", None) is None:
        raise ValueError("the environment has no spec to make an evaluation copy from; pass eval_env=")
    try:
        return gym.make(env.spec)
    except Exception as e:
        raise ValueError(
            f"cannot make a second instance of {env.spec.id} for evaluation from its spec ({e}); pass eval_env="
        ) from e


class _BuiltinEnv:
    """A built-in arld environment with Gymnasium's API (`arld.make`)."""

    metadata = {"render_modes": []}

    def __init__(self, env_id):
        self._core = _arld.BuiltinEnv(env_id)
        env_id, obs_dim, n_actions, limit, threshold = self._core.spec
        self.id = env_id
        try:
            import gymnasium as gym

            self.observation_space = gym.spaces.Box(-np.inf, np.inf, (obs_dim,), np.float32)
            self.action_space = gym.spaces.Discrete(n_actions)
        except ImportError:
            self.observation_space = None
            self.action_space = None
        self.max_episode_steps = limit
        self.reward_threshold = threshold

    def reset(self, seed=None, options=None):
        return np.asarray(self._core.reset(seed), dtype=np.float32), {}

    def step(self, action):
        obs, reward, terminated, truncated = self._core.step(int(action))
        return np.asarray(obs, dtype=np.float32), reward, terminated, truncated, {}

    def close(self):
        pass

    def __repr__(self):
        return f"arld.make({self.id!r})"


def make(env_id):
    """A built-in environment (CartPole-v0/v1, Acrobot-v1, MountainCar-v0, LunarLander-v2/v3) with
    Gymnasium's reset/step API; training on it runs entirely in Rust."""
    return _BuiltinEnv(env_id)


# ---------------------------------------------------------------------------------------------------- experts


def _expert_callable(expert, n_actions):
    """(callable obs list -> int, name) for a Python expert, or (None, spec) for an arld expert spec."""
    if isinstance(expert, str):
        return None, expert
    if isinstance(expert, WebExpert):
        return expert, "web"
    if isinstance(expert, Agent):
        policy = expert._require_policy()
        return policy.act, "arld.Agent"
    if hasattr(expert, "predict") and callable(expert.predict):
        # Stable-Baselines3's predict(obs, deterministic=True) -> (action, state).
        def ask(obs):
            action, _state = expert.predict(np.asarray(obs, dtype=np.float32), deterministic=True)
            return _as_action(action)

        return ask, type(expert).__name__
    if callable(expert):

        def ask(obs):
            return _as_action(expert(np.asarray(obs, dtype=np.float32)))

        return ask, getattr(expert, "__name__", type(expert).__name__)
    raise TypeError(
        "expert must be a callable obs -> action, an object with predict(obs, deterministic=True) "
        f"(a Stable-Baselines3 model), an arld.Agent or an arld expert spec string; got {type(expert).__name__}"
    )


def _as_action(action):
    a = np.asarray(action)
    if a.size != 1 or not (np.issubdtype(a.dtype, np.integer) or np.issubdtype(a.dtype, np.bool_)):
        if a.size == 1 and np.issubdtype(a.dtype, np.floating) and float(a.reshape(-1)[0]).is_integer():
            return int(a.reshape(-1)[0])
        raise TypeError(f"the expert must answer one integer action, got {action!r}")
    return int(a.reshape(-1)[0])


class _Demos:
    def __init__(self, obs, actions, rewards, next_obs, terminated, truncated=None):
        n = len(actions)
        self.obs = np.asarray(obs, dtype=np.float32).reshape(n, -1).tolist()
        self.actions = [int(a) for a in np.asarray(actions).reshape(-1)]
        self.rewards = np.asarray(rewards, dtype=np.float32).reshape(-1).tolist()
        self.next_obs = np.asarray(next_obs, dtype=np.float32).reshape(n, -1).tolist()
        self.terminated = [bool(t) for t in np.asarray(terminated).reshape(-1)]
        self.truncated = (
            [False] * n if truncated is None else [bool(t) for t in np.asarray(truncated).reshape(-1)]
        )


# ------------------------------------------------------------------------------------------------------ agent


class Agent:
    """An arld agent (SB3-shaped): `Agent(method, env, net=..., expert=..., **hyperparameters)`.

    method: dqn, dqfd, gdqn, bdqn, adqn, adqnp. net: plain, bootstrap, noisy. env: a Gymnasium environment with
    a flat Box observation space and a Discrete action space (wrappers included), or `arld.make(id)`.
    expert: a callable obs -> action, an object with SB3's predict(obs, deterministic=True), an arld.Agent, or
    an arld expert spec ("shipped:weak", "checkpoint:PATH", "cmd:python my_expert.py", ...).
    demos: for dqfd/adqnp, a dict with obs, actions, rewards, next_obs, terminated (and optionally truncated);
    by default they are collected from the expert (built-in environments only).
    Hyperparameters: the CLI's configuration keys with the same names and defaults (see `arld.config_keys()`);
    `total_timesteps` of `learn` sets `train_steps`.
    """

    def __init__(self, method, env, net="bootstrap", expert=None, seed=0, eval_env=None, demos=None, **hyperparameters):
        valid = config_keys()
        unknown = sorted(set(hyperparameters) - set(valid))
        if unknown:
            raise TypeError(
                f"Agent() got unexpected keyword argument(s) {', '.join(unknown)}; valid hyperparameters: "
                + ", ".join(valid)
            )
        if method not in METHODS:
            raise ValueError(f"unknown method {method!r}; known: {', '.join(METHODS)}")
        if net not in NETS:
            raise ValueError(f"unknown net {net!r}; known: {', '.join(NETS)}")
        self.method, self.net, self.seed = method, net, int(seed)
        self.env = env
        facts = _env_facts(env)
        self._builtin = isinstance(env, _BuiltinEnv)
        if not self._builtin:
            _arld.register_env(*facts)
        self.env_id = facts[0]
        self.eval_env = eval_env
        given = eval_env if isinstance(eval_env, (list, tuple)) else [] if eval_env is None else [eval_env]
        if any(_env_facts(e)[1:3] != facts[1:3] for e in given):
            raise ValueError("eval_env must have the same spaces as env")
        self._hyper = dict(hyperparameters)
        if expert is not None:
            self._expert, name = _expert_callable(expert, facts[2])
            self._expert_name = name
            if self._expert is None:
                self._hyper["expert"] = name
            elif method == "dqn":
                raise ValueError("dqn never asks an expert; drop expert=")
        else:
            self._expert, self._expert_name = None, ""
            if method != "dqn":
                raise ValueError(f"{method} needs an expert: pass expert=")
        self._demos = None if demos is None else _Demos(**demos)
        self.config = self._resolve(self._hyper)  # fails early on a bad value
        self._policy = None
        self.evaluations = []
        self.queries = []
        self.summary = None

    def _resolve(self, hyper):
        values = [(k, json.dumps(v)) for k, v in hyper.items()]
        return json.loads(_arld.resolve_config(self.env_id, self.method, self.net, self.seed, values))

    def learn(self, total_timesteps=None, progress_bar=False, log_dir=None):
        """Trains a fresh agent for `total_timesteps` environment steps (default: the preset's train_steps) with
        arld's loop. `log_dir` writes the usual run directory (config, CSVs, TensorBoard events, weights,
        summary). Returns self."""
        hyper = dict(self._hyper)
        if total_timesteps is not None:
            hyper["train_steps"] = int(total_timesteps)
        self.config = self._resolve(hyper)
        if self._builtin:
            env = test_envs = None
        else:
            env = _EnvBridge(self.env)
            test_envs = [_EnvBridge(e) for e in self._test_envs(self.config["eval_episodes"])]
        policy, evaluations, queries, summary = _arld.train(
            json.dumps(self.config),
            env=env,
            test_envs=test_envs,
            expert=self._expert,
            expert_name=self._expert_name,
            demos=self._demos,
            log_dir=None if log_dir is None else str(log_dir),
            progress=bool(progress_bar),
        )
        self._policy, self.evaluations, self.queries = policy, evaluations, queries
        self.summary = json.loads(summary)
        return self

    def _test_envs(self, episodes):
        """One environment per test episode (the test episodes run in lockstep): `eval_env` when it is a list of
        that length; otherwise `eval_env` (or a copy of `env` from its spec) and copies of it from its spec."""
        if isinstance(self.eval_env, (list, tuple)):
            if len(self.eval_env) != episodes:
                raise ValueError(
                    f"eval_env is a list of {len(self.eval_env)} environments, but there are {episodes} test "
                    "episodes (eval_episodes): give one environment per episode, or one to copy"
                )
            return list(self.eval_env)
        if self.eval_env is not None:
            return [self.eval_env] + [_same_spec_env(self.eval_env) for _ in range(episodes - 1)]
        return [_same_spec_env(self.env) for _ in range(episodes)]

    def _require_policy(self):
        if self._policy is None:
            raise RuntimeError("the agent has not been trained or loaded yet: call learn() or Agent.load()")
        return self._policy

    def predict(self, obs, deterministic=True):
        """The test policy's action (no exploration) for one observation."""
        return self._require_policy().act(np.asarray(obs, dtype=np.float32).reshape(-1).tolist())

    def save(self, path):
        """Writes the network's weights (safetensors) with the run's identity as metadata."""
        meta = {"env": self.env_id, "method": self.method, "net": self.net, "seed": str(self.seed)}
        self._require_policy().save(str(path), meta)

    @classmethod
    def load(cls, path, env=None):
        """An agent acting with saved weights (from `save` or `arld train`). `env` (optional) is checked
        against the weights' sizes."""
        policy, meta = _arld.Policy.load(str(path))
        if env is not None:
            _id, obs_dim, n_actions, _limit, _thr = _env_facts(env)
            if (obs_dim, n_actions) != (policy.obs_dim, policy.n_actions):
                raise ValueError(
                    f"{path} has {policy.obs_dim} inputs and {policy.n_actions} actions, the environment "
                    f"{obs_dim} and {n_actions}"
                )
        agent = cls.__new__(cls)
        agent.method = meta.get("method", "dqn")
        agent.net = "bootstrap"
        agent.seed = int(meta.get("seed", 0))
        agent.env = env
        agent.env_id = meta.get("env", "")
        agent._policy = policy
        agent.evaluations, agent.queries, agent.summary = [], [], None
        return agent

    def __repr__(self):
        return f"arld.Agent({self.method!r}, {self.env_id!r}, net={self.net!r}, seed={self.seed})"
