"""Analytic controllers for the two models of Naterop et al., as SwarmNav policies.

Source: the Naterop et al. report (seed ``003``): §4.1, the zone model of Couzin et al.
(2002) with informed individuals (eq. 6); §4.2, Viscido's piecewise force model.

- :class:`InformedIndividualController` (``dynamics="zone"``): every agent applies the
  informed-individual rule of eq. 6, ``d̂_i + ω ĝ_i``. In the zone model the action is
  a bias ``u_i = u_max · a_i`` added to the desired direction, so ``a_i = ω ĝ_i / u_max``
  turns every agent into an informed one.
- :class:`GoalForceController` (``dynamics="piecewise"``): the goal force on top of the
  piecewise model. The report steers nothing; its model takes forces, so the baseline
  adds the task's goal-sink force (Mabrouk & McInnes eq. 21, the same ``C_g, l_g``) as
  the control force, exactly as :class:`~agents.PotentialFieldController` does for the
  social potential.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from agents.base import Controller
from agents.mabrouk_mcinnes import PotentialFieldController
from swarm_envs.physics._validation import check_real

__all__ = ["GoalForceController", "InformedIndividualController"]


class InformedIndividualController(Controller):
    """The informed-individual rule (Naterop eq. 6; Couzin et al. 2005) for every agent.

    From agent i's observation it reads the goal offset ``r_g − r_i`` and returns

    ``a_i = ω ĝ_i / u_max``, ``ĝ_i = (r_g − r_i)/|r_g − r_i|``,

    so the environment's zone model turns each heading toward ``d̂_i + ω ĝ_i``, eq. 6's
    desired direction of an informed individual. An agent exactly on the goal gets zero.
    When ``ω > u_max`` the action norm is capped at 1 (the bias at ``u_max``).

    Args:
        env: any swarm_envs environment (possibly wrapped) or a ``SwarmConfig``.
        omega: the weight ``ω``; default the config's ``zone.omega`` (0.5).

    >>> from swarm_envs.config import SwarmConfig
    >>> ctrl = InformedIndividualController(SwarmConfig(dynamics="zone"))  # ω = 0.5, u_max = 3
    >>> obs = np.zeros(ctrl.obs_dim, np.float32)
    >>> obs[:2] = [0.3, 0.4]                               # goal offset (3, 4)
    >>> [round(float(a), 4) for a in ctrl.predict(obs)[0]]  # 0.5 (0.6, 0.8) / 3
    [0.1, 0.1333]
    """

    def __init__(self, env: Any, omega: float | None = None) -> None:
        super().__init__(env)
        value = self.cfg.zone.omega if omega is None else omega
        self.omega: float = check_real(type(self).__name__, "omega", value, low=0.0)
        self.obs_goal_scale: float = self.cfg.obs_goal_scale

    def action_from_offset(self, offset: np.ndarray) -> np.ndarray:
        """The action for world-frame goal offsets ``r_g − r_i`` shaped ``(..., d)``."""
        offset = np.asarray(offset, dtype=np.float64)
        if offset.ndim == 0 or offset.shape[-1] != self.dim:
            raise ValueError(f"offset must be shaped (..., {self.dim}), got {offset.shape}")
        norm = np.sqrt(np.einsum("...k,...k->...", offset, offset))[..., None]
        unit = np.where(norm > 0, offset / np.where(norm > 0, norm, 1.0), 0.0)
        return unit * min(self.omega / self.u_max, 1.0)

    def _actions(self, obs: np.ndarray, deterministic: bool) -> np.ndarray:
        return self.action_from_offset(obs[:, : self.dim] * self.obs_goal_scale)


class GoalForceController(PotentialFieldController):
    """The goal-sink force on top of Viscido's piecewise model (``dynamics="piecewise"``).

    ``a_i = F_goal_i / u_max`` with ``F_goal_i = (C_g/l_g) e^{−|r_g − r_i|/l_g} ĝ_i``
    (Mabrouk & McInnes eq. 21, ``C_g, l_g`` from the config's ``physics`` section), capped
    at norm 1. In the piecewise model the action is a force, so the closed loop is
    ``m r̈_i = Σ_{λ nearest} F(ρ_ij) u_ij + ξ_i − β v_i + F_goal_i``: the report's model
    with a goal sink on top. See :class:`~agents.PotentialFieldController` for the
    clipping and rounding notes, which apply unchanged.

    >>> from swarm_envs.config import SwarmConfig
    >>> ctrl = GoalForceController(SwarmConfig(dynamics="piecewise"))
    >>> obs = np.zeros(ctrl.obs_dim, np.float32); obs[:2] = [0.3, 0.4]
    >>> [round(float(a), 4) for a in ctrl.predict(obs)[0]]  # e^{-1} (0.6, 0.8)
    [0.2207, 0.2943]
    """
