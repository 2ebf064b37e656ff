"""Perturbations around any core: agents that fail, join or are absent, and noise.

:class:`PerturbedCore` implements :class:`~swarm_envs.envs.protocol.Core` on top of
another core, the same way for every backend (``SwarmConfig.perturbations``):

1. at a reset it draws each swarm's perturbations from the reset's generator
   (:class:`~swarm_envs.envs.task.agent_status.AgentSchedule`) and gives the agents
   their statuses at step 0;
2. a step adds the action noise, zeroes the actions of the agents that do not act
   (:func:`~swarm_envs.envs.task.agent_status.perturb_actions`), steps the core, then
   applies the statuses due after the step to the swarms that go on (failures, joins:
   a joining agent appears at its own start position, at rest);
3. observations get their dropped neighbour slots and noise once per step
   (:func:`~swarm_envs.envs.task.agent_status.perturb_observations`), so every call
   until the next step or reset returns the same values.

Where agents only fail passively the core needs no statuses (every agent stays in the
physics and moves); where agents leave or stop, or the observation shows statuses, the
core takes them through ``set_status`` and applies the masks in its physics, its
statistics and its observations.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from swarm_envs.envs.common import check_actions
from swarm_envs.envs.protocol import StatusCore, StepResult
from swarm_envs.envs.task.agent_status import (
    ABSENT,
    AgentSchedule,
    all_active,
    perturb_actions,
    perturb_observations,
)
from swarm_envs.envs.task.observation import OBS_BOUND, block_size, own_size


class PerturbedCore:
    """``inner`` (any core) with the perturbations of its config (module docstring)."""

    def __init__(self, inner: StatusCore) -> None:
        self.inner = inner
        cfg = inner.cfg
        self.cfg = cfg
        self.batch = inner.batch
        self.dtype = inner.dtype
        self.obs_dim = inner.obs_dim
        p = cfg.perturbations
        self.schedule = AgentSchedule(p, self.batch, cfg.n_agents)
        #: Each agent's status ``(B, N)`` int8 (agent_status).
        self.status = all_active(self.batch, cfg.n_agents)
        self._statuses_in_core = cfg.needs_statuses
        self._noisy_obs = p.bounds("obs_noise")[1] > 0 or p.bounds("neighbor_dropout")[1] > 0
        self._rng: np.random.Generator | None = None
        self._join_x = np.zeros((self.batch, cfg.n_agents, cfg.dim))
        self._obs: np.ndarray | None = None

    @property
    def backend(self) -> str:
        return self.inner.backend

    @property
    def t(self) -> np.ndarray:
        return self.inner.t

    @property
    def x(self) -> np.ndarray:
        return self.inner.x

    @property
    def v(self) -> np.ndarray:
        return self.inner.v

    @property
    def goal(self) -> np.ndarray:
        return self.inner.goal

    def __getattr__(self, name: str) -> Any:
        inner = self.__dict__.get("inner")
        if inner is None:
            raise AttributeError(name)
        return getattr(inner, name)

    # ------------------------------------------------------------------ episode
    def reset(self, rng: np.random.Generator, which: np.ndarray | None = None) -> None:
        """The core's reset, then each reset swarm's perturbations and statuses."""
        self.inner.reset(rng, which)
        rows = np.ones(self.batch, dtype=bool) if which is None else np.asarray(which, bool)
        idx = np.flatnonzero(rows)
        if idx.size == 0:
            return
        self._rng = rng
        self.schedule.draw(rng, idx)
        self._join_x[idx] = self.inner.x[idx]
        status = self.status.copy()
        status[idx] = self.schedule.status(np.zeros(self.batch, np.int64))[idx]
        if self._statuses_in_core:
            self.inner.set_status(status, rows=rows, start=True)
        self.status = status
        if self._noisy_obs:
            fresh = self._perturb(self.inner.observe(rows), idx)
            if idx.size == self.batch:
                self._obs = fresh
            else:
                if self._obs is None:  # a first reset of some swarms: the others have none yet
                    self._obs = np.zeros((self.batch, *fresh.shape[1:]), fresh.dtype)
                self._obs[idx] = fresh

    def step(self, actions: Any) -> StepResult:
        """One step of the core with the perturbed actions; then the statuses due."""
        if self._rng is None:
            raise RuntimeError("step() before reset()")
        shape = (self.batch, self.cfg.n_agents, self.cfg.dim)
        a = check_actions(actions, shape)
        a = perturb_actions(a, self.status, self.schedule.action_noise, self._rng)
        reward, terminated, truncated, stats = self.inner.step(a)
        going = ~(terminated | truncated)
        due = np.where(going[:, None], self.schedule.status(self.inner.t), self.status)
        if (due != self.status).any():
            place = (self.status == ABSENT) & (due != ABSENT) & ~self.schedule.absent
            if self._statuses_in_core:
                at = self._join_x.astype(self.dtype)
                self.inner.set_status(due, place if place.any() else None, at)
                stats = self.inner.stats()
            self.status = due
        if self._noisy_obs:
            self._obs = self._perturb(self.inner.observe(), np.arange(self.batch))
        return reward, terminated, truncated, stats

    # ------------------------------------------------------------------ measures
    def _perturb(self, obs: np.ndarray, idx: np.ndarray) -> np.ndarray:
        assert self._rng is not None
        s = self.schedule
        return perturb_observations(
            obs,
            dim=self.cfg.dim,
            block=block_size(self.cfg),
            n_slots=self.cfg.n_neighbors,
            sigma=s.obs_noise[idx],
            dropout=s.neighbor_dropout[idx],
            rng=self._rng,
            bound=OBS_BOUND,
            own=own_size(self.cfg),
        )

    def observe(self, which: np.ndarray | None = None) -> np.ndarray:
        """The core's observations with this step's dropout and noise (fresh arrays)."""
        if not self._noisy_obs:
            return self.inner.observe(which)
        assert self._obs is not None
        return self._obs.copy() if which is None else self._obs[np.asarray(which, bool)]

    def stats(self) -> dict[str, np.ndarray]:
        return self.inner.stats()

    def __getstate__(self) -> dict[str, Any]:
        return dict(self.__dict__)

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
