"""The saturated PD goal controller: the first controller a roboticist would write.

The papers' controllers are goal-sink forces whose pull decays exponentially with the
distance to the goal, weak by design far from it. A practitioner with the same
observation — the goal offset ``r_g − r_i`` and the agent's own velocity ``v_i`` — would
write a proportional–derivative law toward the goal and saturate it at the actuator's
bound:

    ``u_i = u_max · sat((k_p (r_g − r_i) − k_d v_i) / u_max)``,  ``sat(z) = z / max(1, |z|)``

so an agent far away thrusts at ``u_max`` straight at the goal, and one near it brakes
with the derivative term. Two gains, tuned on training seeds only (``swarm-tune``, whose
results live in ``configs/baselines/tuned.yaml``), never on the evaluation seeds.

How the control acts depends on the model (``swarm_envs.envs.dynamics``): a force for
the social potential and the piecewise model, a velocity for the Lagrangian model, a
bias of the desired heading for Couzin's zone model. The same law serves all four: for
the zone model, whose agents fly at constant speed, the derivative term turns against
the heading, and the tuning picks ``k_d`` (zero is on the grid) and a proportional gain
whose bias saturates toward the goal.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from agents.base import Controller
from swarm_envs.physics._validation import check_real

__all__ = ["SATURATIONS", "SaturatedPDController", "saturate"]

#: How the PD law is brought into the action box (:func:`saturate`).
SATURATIONS = ("norm", "box", "clip")


class SaturatedPDController(Controller):
    """Saturated PD law toward the goal (module docstring), for every dynamics.

    Reads agent i's goal offset ``obs[:d] · obs_goal_scale`` and own velocity
    ``obs[d:2d] · obs_velocity_scale`` and returns
    ``a_i = sat((k_p (r_g − r_i) − k_d v_i) / u_max)``, scaled into the action box with
    its direction kept (:func:`saturate`).

    In the informed task only the informed agents act (:attr:`acts_informed_only`);
    :class:`~agents.InformedFollowerController` adds a rule for the others.

    Args:
        env: any swarm_envs environment (possibly wrapped) or a ``SwarmConfig``.
        k_p: proportional gain ``≥ 0`` (force or velocity per unit distance). ``None``:
            the tuned gain of the env's task and dynamics (:mod:`agents.tuned`), else
            :data:`DEFAULT_K_P`.
        k_d: derivative gain ``≥ 0`` (per unit velocity). ``None``: as ``k_p``.
        saturation: ``"norm"`` (the norm capped at 1), ``"box"`` (the largest
            component capped at 1: more thrust along the diagonals) or ``"clip"``
            (each component on its own), see :func:`saturate`. ``None``: as ``k_p``
            (its tuned ``saturation``), else ``"norm"``.

    >>> from swarm_envs.config import SwarmConfig
    >>> ctrl = SaturatedPDController(SwarmConfig(), k_p=1.0, k_d=0.5, saturation="norm")
    >>> obs = np.zeros(ctrl.obs_dim, np.float32)
    >>> obs[:2] = [0.3, 0.4]                    # goal offset (3, 4): distance 5
    >>> [round(float(a), 4) for a in ctrl.predict(obs)[0]]  # saturated: unit (0.6, 0.8)
    [0.6, 0.8]
    >>> obs[:2] = [0.06, 0.0]; obs[2:4] = [0.25, 0.0]  # offset (0.6, 0), velocity (0.5, 0)
    >>> [round(float(a), 4) + 0.0 for a in ctrl.predict(obs)[0]]  # (0.6 − 0.25) / 3
    [0.1167, 0.0]
    """

    #: Gains used when neither the caller nor the tuned table gives one.
    DEFAULT_K_P: float = 1.0
    DEFAULT_K_D: float = 1.0
    #: The entry of the tuned table (:mod:`agents.tuned`) this controller reads.
    _TUNED_NAME = "pd"

    def __init__(
        self,
        env: Any,
        k_p: float | None = None,
        k_d: float | None = None,
        saturation: str | None = None,
    ) -> None:
        super().__init__(env)
        from agents.tuned import Gain, tuned_gains

        tuned = tuned_gains(self._TUNED_NAME, self.cfg)
        owner = type(self).__name__
        k_p_value: Gain = tuned.get("k_p", self.DEFAULT_K_P) if k_p is None else k_p
        k_d_value: Gain = tuned.get("k_d", self.DEFAULT_K_D) if k_d is None else k_d
        self.k_p: float = check_real(owner, "k_p", k_p_value, low=0.0)
        self.k_d: float = check_real(owner, "k_d", k_d_value, low=0.0)
        if saturation is None:
            saturation = str(tuned.get("saturation", "norm"))
        if saturation not in SATURATIONS:
            raise ValueError(f"{owner}.saturation must be one of {SATURATIONS}, got {saturation!r}")
        self.saturation: str = saturation
        self.obs_goal_scale: float = self.cfg.obs_goal_scale
        self.obs_velocity_scale: float = self.cfg.obs_velocity_scale

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}(k_p={self.k_p:g}, k_d={self.k_d:g}, "
            f"saturation={self.saturation!r})"
        )

    def action_from_state(self, offset: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        """The action for world-frame goal offsets ``r_g − r_i`` and velocities ``v_i``,
        both shaped ``(..., d)``; float64, norm at most 1."""
        offset = np.asarray(offset, dtype=np.float64)
        velocity = np.asarray(velocity, dtype=np.float64)
        if offset.ndim == 0 or offset.shape[-1] != self.dim or velocity.shape != offset.shape:
            raise ValueError(
                f"offset and velocity must both be shaped (..., {self.dim}), got "
                f"{offset.shape} and {velocity.shape}"
            )
        return saturate(self.command(offset, velocity) / self.u_max, self.saturation)

    def command(
        self,
        offset: np.ndarray,
        velocity: np.ndarray,
        k_p: float | np.ndarray | None = None,
        k_d: float | np.ndarray | None = None,
    ) -> np.ndarray:
        """The PD law before its saturation, ``k_p (r_g − r_i) − k_d v_i`` (control
        units, float64), for goal offsets and velocities shaped alike ``(..., d)``; with
        ``k_p``, ``k_d`` (numbers or arrays that broadcast, e.g. one per agent) in place
        of the controller's own."""
        k_p = self.k_p if k_p is None else k_p
        k_d = self.k_d if k_d is None else k_d
        offset = np.asarray(offset, dtype=np.float64)
        return k_p * offset - k_d * np.asarray(velocity, dtype=np.float64)

    def _actions(self, obs: np.ndarray, deterministic: bool) -> np.ndarray:
        d = self.dim
        return self.action_from_state(
            obs[:, :d] * self.obs_goal_scale, obs[:, d : 2 * d] * self.obs_velocity_scale
        )


def saturate(z: np.ndarray, saturation: str = "norm") -> np.ndarray:
    """``z`` scaled down into the action box, its direction kept, along the last axis.

    ``"norm"``: ``z / max(1, |z|)``, the Euclidean norm capped at 1 (the same thrust in
    every direction). ``"box"``: ``z / max(1, max_k |z_k|)``, the largest component
    capped at 1, so a saturated action reaches the box's face: up to ``√d`` times more
    thrust along the diagonals than ``"norm"``. ``"clip"``: each component clipped to
    ``[−1, 1]`` on its own (the direction is not kept: far from the goal every axis
    thrusts bang-bang, and each axis brakes as its own offset closes).

    >>> saturate(np.array([[3.0, 4.0], [0.3, 0.4]])).round(3).tolist()
    [[0.6, 0.8], [0.3, 0.4]]
    >>> saturate(np.array([[3.0, 4.0], [0.3, 0.4]]), "box").round(3).tolist()
    [[0.75, 1.0], [0.3, 0.4]]
    >>> saturate(np.array([[3.0, 0.4]]), "clip").round(3).tolist()
    [[1.0, 0.4]]
    """
    if saturation == "clip":
        return np.clip(z, -1.0, 1.0)
    if saturation == "box":
        size = np.max(np.abs(z), axis=-1, keepdims=True)
    else:
        size = np.sqrt(np.einsum("...k,...k->...", z, z))[..., None]
    return z / np.maximum(size, 1.0)
