"""The goal-sink controller of Mabrouk & McInnes, as a policy of the SwarmNav envs.

Source: M. H. Mabrouk and C. R. McInnes, *Social potential model to simulate emergent
behaviour for swarm robots*, §4 (navigation; eqs. 19–21 and Fig. 11). The paper steers
the swarm to a goal ``r_g`` by adding a sink potential ``V_goal(r_i) = −C_g
e^{−|r_i − r_g|/l_g}`` (eq. 19) to the social potential; every agent then feels

``F_goal_i = −∇V_goal = (C_g/l_g) e^{−|r_g − r_i|/l_g} (r_g − r_i)/|r_g − r_i|``

(eq. 21 as ``docs/models.md`` §1 reads it: the printed eq. 21 drops the unit vector
and writes ``l_a`` for ``l_g``). :class:`PotentialFieldController` applies exactly that
force as the agent's control, so the passive physics plus this controller is the
paper's navigating swarm (eq. 21), and learned policies are measured against it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from agents.base import Controller
from swarm_envs.envs.task import OBS_BOUND
from swarm_envs.physics import goal_force

__all__ = ["PotentialFieldController"]


class PotentialFieldController(Controller):
    """Goal-sink controller (Mabrouk & McInnes, eqs. 19–21): the action is ``F_goal / u_max``.

    From agent i's observation it reads the goal offset ``r_g − r_i = obs[:d] ·
    obs_goal_scale`` and returns

    ``a_i = F_goal_i / u_max``, ``F_goal_i = (C_g/l_g) e^{−|r_g − r_i|/l_g}
    (r_g − r_i)/|r_g − r_i|``

    with ``C_g, l_g`` from the environment's physics parameters (the task's sink), so
    the control force ``u_i = u_max · a_i`` the environment applies is exactly the sink
    force of the paper's eq. 21 (computed by :func:`swarm_envs.physics.goal_force`, the
    same function the passive physics uses). An agent exactly on the goal gets zero.
    It looks at nothing else (neighbours and velocities enter through the passive
    physics, as in the paper).

    Where the action bound clips it:

    - The force's magnitude peaks at ``C_g/l_g`` on the goal. When ``C_g/l_g > u_max``
      (:attr:`saturates`), agents closer than ``l_g ln(C_g/(l_g u_max))`` would need
      more than ``u_max``; the controller then caps the magnitude at ``u_max`` and keeps
      the direction (``|a_i| ≤ 1``; it never uses the box's corners, so its force field
      stays isotropic). With the paper's navigation set and the default ``u_max = 3 =
      C_g/l_g`` nothing is ever capped: "passive physics + this controller" is eq. 21.
    - The observation clips each goal-offset component at ``±10 · obs_goal_scale``
      (±100 by default). Beyond that the observed offset is wrong, but the force
      there is below ``(C_g/l_g) e^{−10 obs_goal_scale / l_g}`` (``3 e^{−20} ≈ 6e−9``
      by default): negligible.
    - The observations are float32, so through the environment's API the offset (and
      hence the force) carries a relative rounding error of about ``6e−8``;
      :meth:`action_from_offset` computes it from an exact (float64) offset instead.

    With ``C_g = 0`` (no sink in the config, e.g. ``paper_default.yaml``) it returns
    zero actions. With ``integrator: velocity_verlet`` the environment holds the control
    over the step (zero-order hold), so the equivalence with the passive sink is exact
    only for the default semi-implicit Euler integrator.

    Args:
        env: any swarm_envs environment (possibly wrapped) or a ``SwarmConfig``.

    >>> import numpy as np, swarm_envs
    >>> from swarm_envs.config import SwarmConfig
    >>> ctrl = PotentialFieldController(SwarmConfig())  # C_g = 15, l_g = 5, u_max = 3
    >>> obs = np.zeros(ctrl.obs_dim, np.float32)
    >>> obs[:2] = [0.3, 0.4]                          # goal offset (3, 4): distance 5
    >>> action, _ = ctrl.predict(obs)
    >>> [round(float(a), 4) for a in action]           # e^{-1} (0.6, 0.8)
    [0.2207, 0.2943]
    """

    def __init__(self, env: Any) -> None:
        super().__init__(env)
        self.params = self.cfg.physics
        self.C_g: float = self.params.C_g
        self.l_g: float = self.params.l_g
        self.obs_goal_scale: float = self.cfg.obs_goal_scale

    @property
    def peak_action(self) -> float:
        """``C_g / (l_g u_max)``: the largest action norm the sink force asks for."""
        return self.C_g / (self.l_g * self.u_max)

    @property
    def saturates(self) -> bool:
        """Whether ``C_g/l_g > u_max``, so that the action is capped near the goal."""
        return self.peak_action > 1.0

    @property
    def observed_range(self) -> float:
        """Goal-offset component beyond which the observation clips (``10 · obs_goal_scale``)."""
        return OBS_BOUND * self.obs_goal_scale

    def action_from_offset(self, offset: np.ndarray) -> np.ndarray:
        """The action for world-frame goal offsets ``r_g − r_i`` shaped ``(..., d)``.

        ``F_goal / u_max``, its norm capped at 1 (only when :attr:`saturates`); same
        shape and float64. Use it to drive the env from its exact state (no float32).
        """
        offset = np.asarray(offset, dtype=np.float64)
        if offset.ndim == 0 or offset.shape[-1] != self.dim:
            raise ValueError(f"offset must be shaped (..., {self.dim}), got {offset.shape}")
        flat = offset.reshape(-1, self.dim)
        # goal_force(x, params, goal) uses goal − x; with goal = 0 and x = −offset the
        # difference is the offset exactly.
        force = goal_force(-flat, self.params, np.zeros(self.dim))
        action = force / self.u_max
        if self.saturates:
            norm = np.sqrt(np.einsum("nk,nk->n", action, action))
            action /= np.maximum(norm, 1.0)[:, None]
        return action.reshape(offset.shape)

    def _actions(self, obs: np.ndarray, deterministic: bool) -> np.ndarray:
        return self.action_from_offset(obs[:, : self.dim] * self.obs_goal_scale)
