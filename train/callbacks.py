"""SB3 callbacks: swarm statistics in TensorBoard, periodic evaluation against the analytic
controller (with the best model kept)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecEnvWrapper

from swarm_envs.config import SwarmConfig
from swarm_envs.envs.core import STAT_KEYS
from swarm_envs.envs.vec_env import SwarmNavVecEnv


class SwarmStatsCallback(BaseCallback):
    """Log the swarms' group statistics and task measures as TensorBoard scalars.

    Every step, ``swarm/<stat>`` gets the mean over swarms of each of
    :data:`~swarm_envs.envs.core.STAT_KEYS` (polarization, angular momentum, expanse,
    nearest-neighbour distance, energy, fraction arrived, collisions, distances). At
    every episode end, ``task/episode_success`` and ``task/episode_time_s`` (simulated
    seconds) record how the episode finished. SB3 averages them per logging interval.

    On a :class:`~swarm_envs.envs.vec_env.SwarmNavVecEnv` (wrapped or not) the means come
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
                values = [info[key] for info in rows if key in info]
                if values:
                    self.logger.record_mean(f"swarm/{key}", float(np.mean(values)))
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

        if self._baseline is None:  # the analytic baseline of the config's dynamics
            baseline = make_controller("analytic", self.cfg)
            self._baseline = evaluate_policies(
                {"analytic": baseline}, self.cfg, self.episodes, self.seed, progress=False
            )["policies"]["analytic"]
        learned = evaluate_policies(
            {"learned": self.model}, self.cfg, self.episodes, self.seed, progress=False
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
