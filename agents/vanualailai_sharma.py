"""The Lyapunov controller of Vanualailai & Sharma with the goal as target.

Source: J. Vanualailai and B. Sharma, *A Lagrangian-based swarming behavior in the
absence of obstacles* (seed ``004``), §§4–5: velocities are ``ẋ_i = −α_i ∂L/∂x_i``
(eq. 7) for a Lyapunov function ``L`` built from attraction terms (``γ_i R_i``, §4.1)
and pair-avoidance terms (``β_ij R_i/R_ij``, §4.2), so that ``L̇ ≤ 0``. Their method with
a target ``r_g`` adds the target's attraction term to ``L``.

In ``dynamics="lagrangian"`` the passive physics already is ``−α ∂L/∂x`` (cohesion and
avoidance; with ``gradient="exact"`` a true gradient flow), and the action is a velocity
added to it. :class:`LyapunovTargetController` supplies the target term: with
``u_i = −∇V_t(r_i)`` for the saturated quadratic target potential

``V_t(r) = ½ k |r − r_g|²`` for ``|r − r_g| ≤ u_max/k``, and
``u_max (|r − r_g| − u_max/(2k))`` beyond,

the closed loop with a uniform scalar ``α = 1`` is ``ẋ = −∇(L + Σ_i V_t(x_i))``, so
``L + Σ V_t`` never increases (the paper's Theorem 3 argument with one more term) and
no bins ever overlap. The saturation keeps ``|u_i| ≤ u_max``, within the action bound.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from agents.base import Controller
from swarm_envs.physics._validation import check_real

__all__ = ["LyapunovTargetController", "target_potential"]


def target_potential(offset: np.ndarray, gain: float, u_max: float) -> np.ndarray:
    """``V_t`` of the module docstring for offsets ``r − r_g`` shaped ``(..., d)`` → ``(...)``."""
    rho = np.sqrt(np.einsum("...k,...k->...", offset, offset))
    knee = u_max / gain
    return np.where(rho <= knee, 0.5 * gain * rho * rho, u_max * (rho - 0.5 * knee))


class LyapunovTargetController(Controller):
    """Target attraction for the Lagrangian model: ``u_i = −∇V_t``, ``a_i = u_i / u_max``.

    From agent i's observation it reads the goal offset ``r_g − r_i`` and returns
    ``a_i = k (r_g − r_i) / max(u_max, k |r_g − r_i|)``: a proportional pull of gain
    ``k`` (1/s) that saturates at the action bound (norm 1; the box's corners are never
    used, so the field stays a gradient, see the module docstring).

    Args:
        env: any swarm_envs environment (possibly wrapped) or a ``SwarmConfig``.
        gain: ``k > 0``; default 1 per second.

    >>> from swarm_envs.config import SwarmConfig
    >>> ctrl = LyapunovTargetController(SwarmConfig(dynamics="lagrangian"))  # u_max = 3
    >>> obs = np.zeros(ctrl.obs_dim, np.float32)
    >>> obs[:2] = [0.03, 0.04]                             # offset (0.3, 0.4): unsaturated
    >>> [round(float(a), 4) for a in ctrl.predict(obs)[0]]  # (0.3, 0.4) / 3
    [0.1, 0.1333]
    >>> obs[:2] = [0.6, 0.8]                               # offset (6, 8): saturated
    >>> [round(float(a), 4) for a in ctrl.predict(obs)[0]]
    [0.6, 0.8]
    """

    def __init__(self, env: Any, gain: float = 1.0) -> None:
        super().__init__(env)
        self.gain: float = check_real(
            type(self).__name__, "gain", gain, low=0.0, low_inclusive=False
        )
        self.obs_goal_scale: float = self.cfg.obs_goal_scale

    def action_from_offset(self, offset: np.ndarray) -> np.ndarray:
        """The action for world-frame goal offsets ``r_g − r_i`` shaped ``(..., d)``."""
        offset = np.asarray(offset, dtype=np.float64)
        if offset.ndim == 0 or offset.shape[-1] != self.dim:
            raise ValueError(f"offset must be shaped (..., {self.dim}), got {offset.shape}")
        rho = np.sqrt(np.einsum("...k,...k->...", offset, offset))[..., None]
        return self.gain * offset / np.maximum(self.u_max, self.gain * rho)

    def _actions(self, obs: np.ndarray, deterministic: bool) -> np.ndarray:
        return self.action_from_offset(obs[:, : self.dim] * self.obs_goal_scale)
