"""SB3 callbacks: swarm statistics in TensorBoard, periodic evaluation against the analytic
controller (with the best model kept), progress lines for logs (no terminal), and the run
guard that checkpoints between updates and stops on request."""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, CallbackList
from stable_baselines3.common.vec_env import VecEnvWrapper

from swarm_envs.config import SwarmConfig
from swarm_envs.envs.adapters.vec_env import SwarmNavVecEnv
from swarm_envs.envs.task import STAT_KEYS


class SwarmStatsCallback(BaseCallback):
    """Log the swarms' group statistics and task measures as TensorBoard scalars.

    Every step, ``swarm/<stat>`` gets the mean over swarms of each of
    :data:`~swarm_envs.envs.cores.numpy.STAT_KEYS` (polarization, angular momentum, expanse,
    nearest-neighbour distance, energy, fraction arrived, collisions, distances). At
    every episode end, ``task/episode_success`` and ``task/episode_time_s`` (simulated
    seconds) record how the episode finished. SB3 averages them per logging interval.

    On a :class:`~swarm_envs.envs.adapters.vec_env.SwarmNavVecEnv` (wrapped or not) the means come
    from its ``last_stats`` arrays, the same numbers as the infos hold: a loop over the
    B·N infos would cost as much as the env step at 1024 × 32.
    """

    def __init__(self, cfg: SwarmConfig, verbose: int = 0) -> None:
        super().__init__(verbose)
        self.cfg = cfg

    def _batched_env(self) -> SwarmNavVecEnv | None:
        """The :class:`SwarmNavVecEnv` under the training env's wrappers, if it is one."""
        env = self.training_env
        while isinstance(env, VecEnvWrapper):
            env = env.venv
        return env if isinstance(env, SwarmNavVecEnv) else None

    def _on_step(self) -> bool:
        infos: list[dict[str, Any]] = self.locals.get("infos", [])
        dones = self.locals.get("dones")
        batched = self._batched_env()
        if batched is not None:  # its (B,) statistics, not a loop over B·N infos
            for key, values in batched.last_stats.items():
                self.logger.record_mean(f"swarm/{key}", float(np.mean(values)))
        else:
            rows = [info for info in infos if "polarization" in info]
            for key in STAT_KEYS:
                found = [info[key] for info in rows if key in info]
                if found:
                    self.logger.record_mean(f"swarm/{key}", float(np.mean(found)))
        if dones is not None:
            for i in np.flatnonzero(dones):
                info = infos[i]
                if "success" in info:  # first slot of a swarm (shared) or the env (central)
                    self.logger.record_mean("task/episode_success", float(info["success"]))
                    length = info.get("swarm_episode", info.get("episode", {})).get("l")
                    if length is not None and info["success"]:
                        self.logger.record_mean("task/episode_time_s", length * self.cfg.dt)
        return True


class AnalyticBaselineEvalCallback(BaseCallback):
    """Every ``eval_freq`` timesteps, evaluate the model beside the analytic controller.

    Both run on the same seeded episodes (:func:`train.evaluate.evaluate_policies`);
    ``eval/<policy>_<measure>`` is logged for return, success rate and time to goal, and
    the model with the best mean return so far is saved as ``best_model.zip``.
    """

    def __init__(
        self,
        cfg: SwarmConfig,
        eval_freq: int,
        episodes: int,
        seed: int,
        out_dir: Path,
        verbose: int = 0,
    ) -> None:
        super().__init__(verbose)
        self.cfg = cfg
        self.eval_freq = eval_freq
        self.episodes = episodes
        self.seed = seed
        self.out_dir = Path(out_dir)
        self.best_return = -np.inf
        self.history: list[dict[str, Any]] = []
        self._next_eval = eval_freq
        self._baseline: dict[str, Any] | None = None

    def _evaluate(self) -> None:
        from agents import make_controller
        from train.evaluate import evaluate_policies
        from train.residual import as_policy

        if self._baseline is None:  # the analytic baseline of the config's dynamics
            baseline = make_controller("analytic", self.cfg)
            self._baseline = evaluate_policies(
                {"analytic": baseline}, self.cfg, self.episodes, self.seed, progress=False
            )["policies"]["analytic"]
        learned = evaluate_policies(
            {"learned": as_policy(self.model)}, self.cfg, self.episodes, self.seed, progress=False
        )["policies"]["learned"]
        for name, res in (("learned", learned), ("analytic", self._baseline)):
            self.logger.record(f"eval/{name}_mean_return", res["mean_return"])
            self.logger.record(f"eval/{name}_success_rate", res["success_rate"])
            if res["mean_time_to_goal"] is not None:
                self.logger.record(f"eval/{name}_time_to_goal_s", res["mean_time_to_goal"])
        self.history.append({"timesteps": int(self.num_timesteps), "learned": learned})
        if learned["mean_return"] > self.best_return:
            self.best_return = learned["mean_return"]
            self.model.save(self.out_dir / "best_model.zip")
        if self.verbose:
            print(
                f"[eval @ {self.num_timesteps}] learned return {learned['mean_return']:.2f} "
                f"success {learned['success_rate']:.2f} | analytic return "
                f"{self._baseline['mean_return']:.2f} success {self._baseline['success_rate']:.2f}"
            )

    def _on_step(self) -> bool:
        if self.num_timesteps >= self._next_eval:
            self._next_eval += self.eval_freq
            self._evaluate()
        return True

    def state(self) -> dict[str, Any]:
        """What a resumed run needs to continue the evaluations (JSON-ready)."""
        best = self.best_return if math.isfinite(self.best_return) else None
        return {"history": self.history, "best_return": best, "next_eval": self._next_eval}

    def load_state(self, state: dict[str, Any]) -> None:
        """Continue from :meth:`state` of an earlier run."""
        self.history = list(state["history"])
        best = state["best_return"]
        self.best_return = -np.inf if best is None else float(best)
        self._next_eval = int(state["next_eval"])


def progress_line(done: int, total: int, done_at_start: int, elapsed: float) -> str:
    """``progress: <done> / <total> timesteps (<percent> %), <seconds> s, <rate>
    timesteps/s``, the rate over this process's ``elapsed`` seconds.

    >>> progress_line(500, 1000, 100, 4.0)
    'progress: 500 / 1,000 timesteps (50 %), 4 s, 100 timesteps/s'
    """
    rate = (done - done_at_start) / elapsed if elapsed > 0 else 0.0
    percent = 100.0 * done / total if total > 0 else 100.0
    return (
        f"progress: {done:,} / {total:,} timesteps ({percent:.0f} %), "
        f"{elapsed:.0f} s, {rate:,.0f} timesteps/s"
    )


class ProgressLines(BaseCallback):
    """One progress line at least every ``every_seconds`` of wall time, for a log file.

    The line gives the timesteps done of ``total``, the percentage, the time so far and
    the throughput of this run: ``progress: <done> / <total> timesteps (<percent> %),
    <seconds> s, <rate> timesteps/s``. It replaces the progress bar where the output is not a
    terminal (``swarm-train > log``), and is checked at every vector step, so a line is
    late by at most one step (or one policy update).
    """

    def __init__(self, total: int, every_seconds: float = 30.0, file: Any = None) -> None:
        super().__init__()
        self.total = int(total)
        self.every_seconds = every_seconds
        self.file = file
        self._start = (0.0, 0)
        self._last = 0.0

    def _on_training_start(self) -> None:
        now = time.monotonic()
        self._start, self._last = (now, self.model.num_timesteps), now

    def _line(self, now: float) -> str:
        clock, steps = self._start
        return progress_line(self.model.num_timesteps, self.total, steps, now - clock)

    def _emit(self, now: float) -> None:
        self._last = now
        print(self._line(now), file=self.file or sys.stdout, flush=True)

    def _on_step(self) -> bool:
        now = time.monotonic()
        if now - self._last >= self.every_seconds:
            self._emit(now)
        return True

    def _on_rollout_end(self) -> None:  # a long update follows: report before it
        now = time.monotonic()
        if now - self._last >= self.every_seconds:
            self._emit(now)

    def _on_training_end(self) -> None:
        self._emit(time.monotonic())


class RunGuard(BaseCallback):
    """Checkpoints between updates, and the stop on request, around the other callbacks.

    At the start of each rollout, where the training state is complete (see
    :mod:`train.checkpoints`), it calls ``save()`` when a checkpoint is due: every
    ``every_seconds`` of wall time and/or every ``every_steps`` timesteps (0 turns
    either off). When ``should_stop()`` is true there, it saves and ends training: the
    rollout's first step returns False, and the children do not see that step (it is
    not part of the saved state). :attr:`last_checkpoint` is the folder of the latest
    save and :attr:`stopped` tells whether training ended on request.
    """

    def __init__(
        self,
        save: Callable[[], Path],
        should_stop: Callable[[], bool],
        children: list[BaseCallback],
        every_seconds: float = 0.0,
        every_steps: int = 0,
    ) -> None:
        super().__init__()
        self.save = save
        self.should_stop = should_stop
        self.children = CallbackList(children)
        self.every_seconds = every_seconds
        self.every_steps = every_steps
        self.stopped = False
        self.last_checkpoint: Path | None = None
        self._saved_at = (0.0, 0)

    def _init_callback(self) -> None:
        self.children.init_callback(self.model)

    def _on_training_start(self) -> None:
        self._saved_at = (time.monotonic(), self.model.num_timesteps)
        self.children.on_training_start(self.locals, self.globals)

    def _due(self) -> bool:
        clock, steps = self._saved_at
        by_time = self.every_seconds > 0 and time.monotonic() - clock >= self.every_seconds
        by_steps = self.every_steps > 0 and self.model.num_timesteps - steps >= self.every_steps
        return by_time or by_steps

    def checkpoint(self) -> Path:
        """Save now (call between updates only)."""
        self.last_checkpoint = self.save()
        self._saved_at = (time.monotonic(), self.model.num_timesteps)
        return self.last_checkpoint

    def _on_rollout_start(self) -> None:
        if self.should_stop():
            self.checkpoint()
            self.stopped = True
            return
        if self._due():
            self.checkpoint()
        self.children.on_rollout_start()

    def _on_step(self) -> bool:
        if self.stopped:
            return False
        return self.children.on_step()

    def update_child_locals(self, locals_: dict[str, Any]) -> None:
        self.children.update_locals(locals_)

    def _on_rollout_end(self) -> None:
        if not self.stopped:
            self.children.on_rollout_end()

    def _on_training_end(self) -> None:
        self.children.on_training_end()
