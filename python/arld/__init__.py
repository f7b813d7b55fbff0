"""arld from Python: Active Reinforcement Learning with Demonstration on any Gymnasium environment.

    import gymnasium as gym, arld
    model = arld.Agent("adqn", gym.make("CartPole-v1"), net="bootstrap", expert=my_expert, budget=200, seed=0)
    model.learn(total_timesteps=20_000, progress_bar=True)
    action, _ = model.predict(obs)

The training loop is arld's own (Rust); Python is called only to step the environment and to ask the expert.
This module adapts Python objects (Gymnasium environments, callables, Stable-Baselines3 models and callbacks) to
the plain interfaces of the compiled part `arld._arld` and gives them Stable-Baselines3's shape.

The package's modules: `agent` (Agent, presets, SB3's defaults), `envs` (Gymnasium environments as arld sees
them, arld.make), `experts` (experts and demonstrations), `callbacks` (what runs beside a learn), `answers` (a
run's answers as a Minari dataset, and Minari datasets as demonstrations; `python -m arld.answers`).
"""

from . import _arld
from .agent import (DEFAULTS, METHODS, NETS, SB3_DEFAULTS, SB3_NAMES, Agent, Env, EnvLike, Method, Net, config_keys,
                    preset)
from .envs import make
from .experts import ExpertLike, Predicts, WebExpert, collect_demos

__version__ = _arld.__version__

__all__ = ["Agent", "WebExpert", "make", "preset", "config_keys", "collect_demos", "METHODS", "NETS", "SB3_DEFAULTS",
           "SB3_NAMES", "DEFAULTS", "Method", "Net", "Env", "EnvLike", "Predicts", "ExpertLike", "__version__"]
