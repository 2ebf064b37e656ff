"""An analytic controller for the mill task: reach the goal, then push tangentially.

The mill task (``task="mill"``, ``swarm_envs/SwarmMill-v0``) runs the self-propelled
social potential: the Rayleigh term ``(α − β|v|²) v`` drives every agent's speed to
``v₀ = √(α/β)`` (D'Orsogna et al. 2006) and the goal sink acts passively. Left alone the
swarm falls into the sink and, slowly, into a mill around it: the sink and the pair
forces are central, so nothing but the leftover spin of the approach turns the swarm,
and the Rayleigh term then keeps whatever rotation there is at ``v₀``
(``docs/models.md`` §1.7). A tangential force gives that rotation at once:
the torque ``(r_i − r_g) × u_i`` about the goal is what no passive force supplies.

:class:`MillController` reads the goal offset ``r_g − r_i`` from the observation and

- outside the arrival radius, pushes straight to the goal with gain ``approach``
  (the sink's own pull, ``C_g/l_g e^{−D/l_g}``, is weak far out);
- inside it, pushes along the counter-clockwise tangent ``ẑ × (r_i − r_g)/|r_i − r_g|``
  with gain ``spin``, so the agents circle the goal at about ``v₀`` or a little above.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from agents.base import Controller
from swarm_envs.physics._validation import check_real

__all__ = ["MillController"]


class MillController(Controller):
    """Approach the goal, then spin about it (module docstring); 2-D.

    Args:
        env: any swarm_envs environment (possibly wrapped) or a ``SwarmConfig``.
        approach: the action's norm toward the goal outside the arrival radius, in
            ``[0, 1]`` (default 1: full thrust).
        spin: the action's norm along the tangent inside it, in ``[0, 1]`` (default
            0.2: with the mill task's defaults the agents circle at about ``1.1 v₀``).
        Either ``None``: the gain ``swarm-tune`` found for the scenario
        (``configs/baselines/tuned.yaml``), else the default.

    >>> from swarm_envs.tasks import task_config
    >>> ctrl = MillController(task_config("mill"), approach=1.0, spin=0.2)
    >>> obs = np.zeros(ctrl.obs_dim, np.float32)
    >>> obs[:2] = [0.0, 0.05]            # the goal 0.5 above: inside the arrival radius
    >>> [round(float(a), 4) + 0.0 for a in ctrl.predict(obs)[0]]  # tangent: ẑ × (0, −1)
    [0.2, 0.0]
    >>> obs[:2] = [0.0, 0.5]             # 5 above: outside, straight up
    >>> [round(float(a), 4) + 0.0 for a in ctrl.predict(obs)[0]]
    [0.0, 1.0]
    """

    #: Gains used when neither the caller nor the tuned table gives one.
    DEFAULT_APPROACH: float = 1.0
    DEFAULT_SPIN: float = 0.2

    def __init__(self, env: Any, approach: float | None = None, spin: float | None = None) -> None:
        from agents.tuned import Gain, tuned_gains

        super().__init__(env)
        if self.dim != 2:
            raise ValueError(f"MillController circles in the plane: dim must be 2, got {self.dim}")
        owner = type(self).__name__
        tuned = tuned_gains("mill", self.cfg)
        approach_value: Gain = (
            tuned.get("approach", self.DEFAULT_APPROACH) if approach is None else approach
        )
        spin_value: Gain = tuned.get("spin", self.DEFAULT_SPIN) if spin is None else spin
        self.approach = check_real(owner, "approach", approach_value, low=0.0, high=1.0)
        self.spin = check_real(owner, "spin", spin_value, low=0.0, high=1.0)
        self.radius: float = self.cfg.arrival_radius
        self.obs_goal_scale: float = self.cfg.obs_goal_scale

    def action_from_offset(self, offset: np.ndarray) -> np.ndarray:
        """The action for world-frame goal offsets ``r_g − r_i`` shaped ``(..., 2)``."""
        offset = np.asarray(offset, dtype=np.float64)
        if offset.ndim == 0 or offset.shape[-1] != 2:
            raise ValueError(f"offset must be shaped (..., 2), got {offset.shape}")
        dist = np.sqrt(np.einsum("...k,...k->...", offset, offset))[..., None]
        toward = np.where(dist > 0, offset / np.where(dist > 0, dist, 1.0), 0.0)
        # r_i − r_g = −toward · D; its counter-clockwise tangent ẑ × (−toward).
        tangent = np.stack([toward[..., 1], -toward[..., 0]], axis=-1)
        return np.where(dist > self.radius, self.approach * toward, self.spin * tangent)

    def _actions(self, obs: np.ndarray, deterministic: bool) -> np.ndarray:
        return self.action_from_offset(obs[:, : self.dim] * self.obs_goal_scale)
