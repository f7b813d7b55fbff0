"""What runs beside a learn: SB3-style callbacks, the episode log of verbose=1, the progress bar, and SIGTERM
turned into a stop."""

from __future__ import annotations

import copy
import difflib
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, Dict, List, Literal, Optional, Protocol, Sequence, Tuple, Union, cast

import numpy as np
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .agent import Agent


class _stop_on_sigterm:
    """During learn: SIGTERM stops the run as Ctrl-C does (a KeyboardInterrupt once the run has paused whole),
    where the program keeps Python's default for it (a handler of its own is left alone)."""

    def __enter__(self) -> None:
        import signal
        import threading

        self.previous: Any = None
        if threading.current_thread() is threading.main_thread() and \
                signal.getsignal(signal.SIGTERM) == signal.SIG_DFL:
            def stop(signum: int, frame: Any) -> None:
                raise KeyboardInterrupt("SIGTERM")
            self.previous = signal.signal(signal.SIGTERM, stop)

    def __exit__(self, *exc: Any) -> None:
        if self.previous is not None:
            import signal
            signal.signal(signal.SIGTERM, self.previous)


class _Logger:
    """The part of SB3's logger a callback may use: `record(key, value)` keeps the latest value."""

    def __init__(self) -> None:
        self.name_to_value: Dict[str, Any] = {}

    def record(self, key: str, value: Any, exclude: Any = None) -> None:
        self.name_to_value[key] = value

    def dump(self, step: int = 0) -> None:
        pass


class _Callbacks:
    """SB3-style callbacks (BaseCallback subclasses, CallbackList, lists of them, or objects with the same
    methods) or a plain callable `callback(locals, globals) -> bool`, called by the run after every step on the
    run's thread, with the live model: `predict`, `get_parameters`, `evaluations` and `queries` are those of that
    step, and `save` writes the run as it stands at that step (when the callback returns).

    Moments, as SB3's DQN has them: on_training_start, then on_rollout_start, when learn begins; on_step after
    every environment step (`n_calls`, `num_timesteps`; the locals hold `dones`, `infos`, `rewards` is not
    given, `step`, `episode`, `budget_used` (the demonstrated transitions so far, whatever unit the budget counts
    in), `queries` (the questions asked so far), `last_eval`, `total_timesteps`); one learn is one rollout:
    on_rollout_end, then on_training_end, when learn returns (also after an exception or a stop)."""

    def __init__(self, callback: Any, model: "Agent", total_timesteps: int,
                 episode_log: Optional[_EpisodeLog] = None) -> None:
        self.items = [] if callback is None else list(callback) if isinstance(callback, (list, tuple)) else [
            callback]
        self.episode_log = episode_log
        self.model = model
        self.episode: Optional[int] = None
        self.locals: Dict[str, Any] = {
            "self": model, "total_timesteps": total_timesteps, "callback": self, "log_interval": None,
            "dones": np.zeros(1, dtype=bool), "infos": [{}], "last_eval": None,
        }
        for cb in self.items:
            if hasattr(cb, "init_callback"):
                cb.init_callback(model)

    def start(self) -> None:
        for cb in self.items:
            if hasattr(cb, "on_training_start"):
                cb.on_training_start(self.locals, {})
        for cb in self.items:
            if hasattr(cb, "on_rollout_start"):
                cb.on_rollout_start()

    def __call__(self, step: int, episode: int, budget_used: int, queries: int, last_eval: Any) -> bool:
        model = self.model
        model._live_step = step
        done = self.episode is not None and episode > self.episode
        self.episode = episode
        self.locals.update(
            step=step, num_timesteps=step, episode=episode, budget_used=budget_used, queries=queries,
            dones=np.array([done]), infos=[{}],
            last_eval=None if last_eval is None else {"step": last_eval[0], "mean": last_eval[1]},
        )
        if self.episode_log is not None:
            self.episode_log(step, episode, budget_used, self.locals["last_eval"])
        go_on = True
        for cb in self.items:
            if hasattr(cb, "update_locals"):
                cb.update_locals(self.locals)
            if hasattr(cb, "on_step"):
                answer = cb.on_step()
            else:
                answer = cb(self.locals, {})
            if answer is False:
                go_on = False
        return go_on

    def end(self) -> None:
        for cb in self.items:
            if hasattr(cb, "on_rollout_end"):
                cb.on_rollout_end()
        for cb in self.items:
            if hasattr(cb, "on_training_end"):
                cb.on_training_end()


class _EpisodeLog:
    """SB3's log_interval: with verbose >= 1, one line on standard output every `interval` finished episodes
    (steps, episodes, the latest evaluation, the budget used, steps per second)."""

    def __init__(self, interval: int, label: str) -> None:
        self.interval, self.label = interval, label
        self.t0 = time.perf_counter()
        self.start_step: Optional[int] = None
        self.logged_episodes = -1

    def __call__(self, step: int, episode: int, budget_used: int, last_eval: Any) -> None:
        if self.start_step is None:
            self.start_step = step - 1
        if episode == self.logged_episodes or episode == 0 or episode % self.interval != 0:
            return
        self.logged_episodes = episode
        rate = (step - self.start_step) / max(1e-9, time.perf_counter() - self.t0)
        evaluation = "none yet" if last_eval is None else f"{last_eval['mean']:.2f} at step {last_eval['step']}"
        print(f"{self.label} | steps {step} | episodes {episode} | last evaluation {evaluation} | "
              f"budget used {budget_used} | {rate:.0f} steps/s", flush=True)


class _ProgressBar:
    """A text progress bar on standard error (a terminal or a notebook), left in place when training ends."""

    def __init__(self, start: int, total: int, label: str) -> None:
        self.start, self.total, self.label = start, total, label
        self.t0 = time.perf_counter()
        self.last = ""

    def __call__(self, step: int) -> None:
        done = max(0, step - self.start)
        frac = min(1.0, done / max(1, self.total))
        rate = done / max(1e-9, time.perf_counter() - self.t0)
        bar = "#" * int(30 * frac) + "-" * (30 - int(30 * frac))
        text = f"\r{self.label} [{bar}] {done}/{self.total} steps {rate:.0f} steps/s"
        if text != self.last:
            sys.stderr.write(text)
            sys.stderr.flush()
            self.last = text

    def close(self, step: int) -> None:
        self(step)
        sys.stderr.write("\n")
        sys.stderr.flush()


# ------------------------------------------------------------------------------------------------------ agent
