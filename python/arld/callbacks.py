"""What runs beside a learn: SB3-style callbacks, the episode log of verbose=1, the progress bar, and SIGTERM
turned into a stop."""

from __future__ import annotations

import sys
import time
from typing import Any, Dict, Optional

import numpy as np


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
    every environment step (`n_calls`, `num_timesteps`); one learn is one rollout: on_rollout_end, then
    on_training_end, when learn returns (also after an exception or a stop).

    The locals, as SB3's off-policy loop has them for its one environment: `actions` (the action taken, the
    agent's or the expert's), `rewards`, `dones`, `new_obs` (batches of one, as a vector environment gives
    them: after an episode's end the reset's observation), `infos` (the environment's info of the step: Monitor's
    `episode` when it wraps the environment; with `terminal_observation` and `TimeLimit.truncated` at an
    episode's end, as SB3's vector environments add them), and arld's own: `step`, `episode`, `budget_used`,
    `queries`, `last_eval`, `total_timesteps`. An environment that arld.make gives, trained unwrapped, runs in Rust:
    its infos hold only what SB3's vector environment adds.

    With SB3's logger set (`set_logger`) and log_interval, every log_interval finished episodes the run's values
    are recorded and dumped, as SB3's DQN does (`_dump`)."""

    # `model` is the arld.Agent that learns (typed Any: the agent module imports this one).
    def __init__(self, callback: Any, model: Any, total_timesteps: int,
                 episode_log: Optional[_EpisodeLog] = None, log_interval: Optional[int] = None) -> None:
        self.items = [] if callback is None else list(callback) if isinstance(callback, (list, tuple)) else [
            callback]
        self.episode_log = episode_log
        self.log_interval = log_interval
        self.model = model
        self.episode: Optional[int] = None
        self.t0 = time.perf_counter()
        self.start_step: Optional[int] = None
        self.locals: Dict[str, Any] = {
            "self": model, "total_timesteps": total_timesteps, "callback": self, "log_interval": log_interval,
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

    def _step_locals(self, taken: Any) -> Dict[str, Any]:
        """SB3's locals of the step the run took: (action, reward, terminated, truncated, ended, obs) from the run,
        the environment's own observation and info from its bridge (a Python environment)."""
        action, reward, terminated, truncated, ended, flat_obs = taken
        model = self.model
        box = model._box
        bridge = model._bridge
        done = bool(terminated or truncated)
        if bridge is not None:
            info = dict(bridge.info)
            new_obs = _batch_of_one(bridge.obs)
            if done:
                info["terminal_observation"] = bridge.final_obs
        else:
            info = {}
            new_obs = np.asarray(flat_obs, dtype=np.float32)[None]
        if done:
            info["TimeLimit.truncated"] = bool(truncated and not terminated)
            episode = info.get("episode")
            # SB3's ep_info_buffer: Monitor's episode info when it wraps the environment, else arld's own.
            if isinstance(episode, dict) and "r" in episode:
                model._ep_infos.append(dict(episode))
            elif ended is not None:
                model._ep_infos.append({"r": float(ended[0]), "l": int(ended[1]),
                                        "t": round(time.perf_counter() - self.t0, 6)})
        actions: np.ndarray
        if box is None:
            actions = np.array([-1 if action is None else action], dtype=np.int64)
        else:
            actions = np.asarray(action if action is not None else np.zeros(box.dim), dtype=np.float32).reshape(
                (1,) + box.shape)
        return {"actions": actions, "rewards": np.array([reward], dtype=np.float32),
                "dones": np.array([done]), "new_obs": new_obs, "infos": [info]}

    def __call__(self, step: int, episode: int, budget_used: int, queries: int, last_eval: Any,
                 taken: Any = None) -> bool:
        model = self.model
        model._live_step = step
        if self.start_step is None:
            self.start_step = step - 1
        self.episode = episode
        self.locals.update(
            step=step, num_timesteps=step, episode=episode, budget_used=budget_used, queries=queries,
            last_eval=None if last_eval is None else {"step": last_eval[0], "mean": last_eval[1]},
        )
        if taken is not None:
            self.locals.update(self._step_locals(taken))
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
        # After the callbacks, as SB3's loop dumps after on_step.
        if self.log_interval is not None and bool(self.locals["dones"][0]) and episode % self.log_interval == 0:
            self._dump(step, episode, budget_used, queries)
        return go_on

    def _dump(self, step: int, episode: int, budget_used: int, queries: int) -> None:
        """SB3's DQN's dump_logs with arld's values besides: the run's step, episodes, the last 100 episodes'
        mean return and length, ε, steps per second, and the learning rate, budget, queries and last evaluation."""
        model, logger = self.model, self.model.logger
        elapsed = max(time.perf_counter() - self.t0, 1e-9)
        logger.record("time/episodes", episode, exclude="tensorboard")
        infos = list(model._ep_infos)
        if infos:
            logger.record("rollout/ep_rew_mean", float(np.mean([e["r"] for e in infos])))
            logger.record("rollout/ep_len_mean", float(np.mean([e["l"] for e in infos])))
        logger.record("rollout/exploration_rate", model.exploration_rate)
        logger.record("time/fps", int((step - (self.start_step or 0)) / elapsed))
        logger.record("time/time_elapsed", int(elapsed), exclude="tensorboard")
        logger.record("time/total_timesteps", step, exclude="tensorboard")
        logger.record("train/learning_rate", model.learning_rate)
        logger.record("arld/budget_used", budget_used)
        logger.record("arld/queries", queries)
        last = self.locals["last_eval"]
        if last is not None:
            logger.record("eval/mean_reward", float(last["mean"]))
        logger.dump(step=step)

    def end(self) -> None:
        for cb in self.items:
            if hasattr(cb, "on_rollout_end"):
                cb.on_rollout_end()
        for cb in self.items:
            if hasattr(cb, "on_training_end"):
                cb.on_training_end()


def _batch_of_one(obs: Any) -> Any:
    """An observation as a vector environment of one gives it: a leading axis of 1 (per key of a dict)."""
    if isinstance(obs, dict):
        return {k: _batch_of_one(v) for k, v in obs.items()}
    return np.asarray(obs)[None]


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
