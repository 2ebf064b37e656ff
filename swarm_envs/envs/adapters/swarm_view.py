"""What both SwarmNav adapters share: the state accessors and the rendering.

:class:`SwarmState` gives the one swarm's state as fresh arrays (``positions``,
``velocities``, ``goal``, ``active``, ``status``); :class:`Rendering` draws frames on
demand, loading the drawing libraries on first use. Both are base classes of
:class:`~swarm_envs.envs.adapters.swarm_nav.SwarmNavParallelEnv` and
:class:`~swarm_envs.envs.adapters.swarm_nav.SwarmNavEnv`.
"""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np

from swarm_envs.config import SwarmConfig
from swarm_envs.envs.protocol import Core
from swarm_envs.envs.task.agent_status import ACTIVE

__all__ = ["Rendering", "SwarmState"]


class SwarmState:
    """Read-only views of the one swarm's state, shared by both adapters.

    Each accessor returns a fresh float64 array without the batch dimension; changing
    it does not change the env. They are defined once ``reset()`` has been called, and
    keep the last state after an episode ends, until the next ``reset()``.
    """

    core: Core
    cfg: SwarmConfig
    _has_state: bool = False

    def _require_state(self, name: str) -> None:
        if not self._has_state:
            raise RuntimeError(f"{name} is defined after reset(); call reset() first")

    @property
    def positions(self) -> np.ndarray:
        """Every agent's position ``r_i``, ``(N, d)`` float64, world units."""
        self._require_state("positions")
        return np.array(self.core.x[0], dtype=np.float64)

    @property
    def velocities(self) -> np.ndarray:
        """Every agent's velocity ``v_i``, ``(N, d)`` float64."""
        self._require_state("velocities")
        return np.array(self.core.v[0], dtype=np.float64)

    @property
    def goal(self) -> np.ndarray:
        """The goal ``r_g``, ``(d,)`` float64."""
        self._require_state("goal")
        return np.array(self.core.goal[0], dtype=np.float64)

    @property
    def active(self) -> np.ndarray:
        """Which agents act, ``(N,)`` bool, in agent order: those whose status is active
        (every agent unless ``perturbations`` fail, remove or hold back some; see
        :attr:`status`)."""
        self._require_state("active")
        return self._status() == ACTIVE

    @property
    def status(self) -> np.ndarray:
        """Each agent's status, ``(N,)`` int8: 0 active, 1 failed (passive), 2 frozen,
        3 absent (removed, absent for the episode or not yet joined);
        :mod:`swarm_envs.envs.task.agent_status`."""
        self._require_state("status")
        return self._status().copy()

    def _status(self) -> np.ndarray:
        status = getattr(self.core, "status", None)
        if status is None:
            return np.zeros(self.cfg.n_agents, dtype=np.int8)
        return np.asarray(status[0])

    def _kinematics(self) -> dict[str, np.ndarray]:
        """``pos``, ``vel``, ``goal_offset`` (``r_g − r_i``), each ``(N, d)`` float32."""
        x = np.asarray(self.core.x[0], dtype=np.float32)
        v = np.asarray(self.core.v[0], dtype=np.float32)
        goal = np.asarray(self.core.goal[0], dtype=np.float32)
        return {"pos": x, "vel": v, "goal_offset": goal[None, :] - x}


class Rendering:
    """Lazy rendering shared by both adapters (drawing libraries load on first use)."""

    core: Core
    render_mode: str | None
    _renderer: Any = None

    def _render_frame(self) -> np.ndarray:
        if self._renderer is None:
            from swarm_envs.render import SwarmRenderer

            self._renderer = SwarmRenderer()
            self._renderer.record(self.core.x[0])
        return self._renderer.frame(
            self.core.x[0],
            goal=self.core.goal[0],
            goal_radius=self.core.cfg.arrival_radius,
            velocities=self.core.v[0],
        )

    def _after_reset_render(self) -> None:
        if self._renderer is not None:
            self._renderer.reset()
            self._renderer.record(self.core.x[0])
        if self.render_mode == "human":
            self.render()

    def _after_step_render(self) -> None:
        if self._renderer is not None:
            self._renderer.record(self.core.x[0])
        if self.render_mode == "human":
            self.render()

    def render(self) -> np.ndarray | None:
        """``rgb_array``: uint8 (H, W, 3) frame; ``human``: draw in a window."""
        if self.render_mode is None:
            gymnasium.logger.warn("render() called without a render_mode; returning None")
            return None
        frame = self._render_frame()
        if self.render_mode == "human":
            self._renderer.show(frame)
            return None
        return frame

    def close(self) -> None:
        """Release the window, if any; safe to call twice."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
