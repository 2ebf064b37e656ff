"""Informed agents steer, the others follow them: the informed task's simple baseline.

In the informed task (``task="informed"``) only a minority observes the goal. The
papers' reading (Couzin's informed individuals) lets the informed agents act and leaves
the rest to the passive physics. A practitioner with the same observation would also
steer the uninformed agents, from what they do see: each neighbour's offset, relative
velocity and informed flag. :class:`InformedFollowerController` does that:

- an informed agent applies the saturated PD law toward the goal
  (:class:`~agents.SaturatedPDController`, gains ``k_p, k_d``), tethered to its
  neighbours: when their mean offset ``m`` is longer than ``ℓ`` (it has run ahead of
  them), a pull ``k_l (|m| − ℓ) m̂`` toward them is added before the saturation,
  ``a_i = sat((k_p (r_g − r_i) − k_d v_i + k_l max(0, |m| − ℓ) m̂) / u_max)``. Where
  the speed is fixed (the zone model) a leader cannot slow down for its flock, and
  one that outruns it leaves the flock without a guide. With ``goal_pull="saturated"``
  the PD law is saturated first, ``u_max · sat((k_p (r_g − r_i) − k_d v_i) / u_max)``, and
  the tether added to that: far from the goal the raw law grows with the distance, and
  a leader whose tether only balances it runs ``ℓ + k_p |r_g − r_i| / k_l`` ahead of its
  flock, out of the followers' view; saturated, it stays within ``ℓ + √d u_max / k_l``;
- an uninformed agent matches the velocity of its informed neighbours and closes on
  a point ``λ`` ahead of them along their heading:
  ``a_i = sat((k_v ⟨v_j − v_i⟩ + k_c (⟨r_j − r_i⟩ + λ ĥ)) / u_max)``, the means over the
  informed neighbours in its observation and ``ĥ`` the direction of their mean velocity
  ``⟨v_j⟩``; with none in view, over all its neighbours, and the point ``λ_f`` ahead of
  them along their mean heading (velocity matching and cohesion, a flock that carries
  the information on). Without a lead (``λ = 0``) the followers fall in behind their
  leader; with one they converge on its course, and a flock at constant speed reaches a
  goal in a compact group instead of a file. The flock's lead ``λ_f`` (``flock_lead``)
  lets the agents that see no informed agent push the flock on along the way it
  already goes, instead of only matching it: the information reaches the rear of a
  flock with one informed agent sooner, at the risk of carrying on a flock that goes
  the wrong way (too long a lead).

The gains are tuned on training seeds (``swarm-tune``, over the grid of
``configs/baselines/grids.yaml``), like the PD's; ``k_l = 0``, ``λ = λ_f = 0`` and
``goal_pull="raw"`` (the defaults) are the untethered leader and followers that close
on it.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, NamedTuple

import numpy as np

from agents.pd import SaturatedPDController, saturate
from swarm_envs.envs.task.observation import block_size, own_size
from swarm_envs.physics._validation import check_real

__all__ = ["SCHEDULED_GAINS", "InformedFollowerController", "NeighbourView"]

#: The gains of :class:`InformedFollowerController` a learned gain schedule may set per
#: agent (:meth:`InformedFollowerController.actions_with_gains`).
SCHEDULED_GAINS = ("k_p", "k_d", "k_l", "k_v", "k_c", "tether", "lead", "flock_lead")


class NeighbourView(NamedTuple):
    """Each agent's neighbours as :class:`InformedFollowerController` reads them: offsets
    and relative velocities ``(n, k, d)``, and ``(n, k)`` weights: 1 for a real neighbour
    (``real``), 1 for a real informed one (``informed``), else 0."""

    offset: np.ndarray
    rel_velocity: np.ndarray
    real: np.ndarray
    informed: np.ndarray


class InformedFollowerController(SaturatedPDController):
    """Informed agents: saturated PD to the goal; the others: follow the informed ones.

    Args:
        env: any swarm_envs environment (possibly wrapped) or a ``SwarmConfig`` whose
            task is ``"informed"``.
        k_p, k_d, saturation: the informed agents' PD law (:class:`SaturatedPDController`).
        k_v: velocity-matching gain ``≥ 0`` of the uninformed agents.
        k_c: cohesion gain ``≥ 0`` of the uninformed agents (toward the mean offset).
        k_l: tether gain ``≥ 0`` of the informed agents (0: no tether).
        tether: the length ``ℓ ≥ 0`` of the tether: the mean neighbour offset beyond
            which it pulls.
        lead: the lead ``λ ≥ 0``: how far ahead of their informed neighbours, along
            their heading, the uninformed agents close (0: on the neighbours).
        flock_lead: the flock's lead ``λ_f ≥ 0``: how far ahead of their neighbours,
            along their mean heading, the uninformed agents with no informed neighbour
            in view close (0: on the neighbours).
        goal_pull: ``"raw"``: the tether is added to the PD law as it is; ``"saturated"``:
            to the PD law saturated into the action box first, so a tether stretched by
            ``u_max / k_l`` holds the leader back whatever its distance to the goal.
        Every ``None`` gain is the tuned one of the env's scenario (``follow`` in
        ``configs/baselines/tuned.yaml``), else the default.

    >>> from swarm_envs.tasks import task_config
    >>> ctrl = InformedFollowerController(task_config("informed", n_agents=3, n_neighbors=2),
    ...                                   k_p=1.0, k_d=0.0, k_v=3.0, k_c=0.0)
    >>> obs = np.zeros(ctrl.obs_dim, np.float32)      # uninformed: own flag 0
    >>> obs[5:10] = [1.0, 0.0, 0.5, 0.0, 1.0]         # neighbour 1: offset, rel. velocity, mask
    >>> obs[10] = 1.0                                  # ... informed
    >>> [round(float(a), 3) + 0.0 for a in ctrl.predict(obs)[0]]  # 3 · (0.5·2) / 3
    [1.0, 0.0]
    """

    acts_informed_only = False
    DEFAULT_K_V: float = 1.0
    DEFAULT_K_C: float = 0.5
    DEFAULT_K_L: float = 0.0
    DEFAULT_TETHER: float = 1.0
    DEFAULT_LEAD: float = 0.0
    DEFAULT_FLOCK_LEAD: float = 0.0
    DEFAULT_GOAL_PULL: str = "raw"
    GOAL_PULLS: tuple[str, ...] = ("raw", "saturated")
    _TUNED_NAME = "follow"

    def __init__(
        self,
        env: Any,
        k_p: float | None = None,
        k_d: float | None = None,
        k_v: float | None = None,
        k_c: float | None = None,
        saturation: str | None = None,
        k_l: float | None = None,
        tether: float | None = None,
        lead: float | None = None,
        goal_pull: str | None = None,
        flock_lead: float | None = None,
    ) -> None:
        from agents.tuned import Gain, tuned_gains

        super().__init__(env, k_p=k_p, k_d=k_d, saturation=saturation)
        owner = type(self).__name__
        if not self.cfg.informs_agents:
            raise ValueError(f"{owner} needs task='informed', got task={self.cfg.task!r}")
        tuned = tuned_gains(self._TUNED_NAME, self.cfg)
        k_v_value: Gain = tuned.get("k_v", self.DEFAULT_K_V) if k_v is None else k_v
        k_c_value: Gain = tuned.get("k_c", self.DEFAULT_K_C) if k_c is None else k_c
        self.k_v: float = check_real(owner, "k_v", k_v_value, low=0.0)
        self.k_c: float = check_real(owner, "k_c", k_c_value, low=0.0)
        k_l_value: Gain = tuned.get("k_l", self.DEFAULT_K_L) if k_l is None else k_l
        tether_value: Gain = tuned.get("tether", self.DEFAULT_TETHER) if tether is None else tether
        self.k_l: float = check_real(owner, "k_l", k_l_value, low=0.0)
        self.tether: float = check_real(owner, "tether", tether_value, low=0.0)
        lead_value: Gain = tuned.get("lead", self.DEFAULT_LEAD) if lead is None else lead
        self.lead: float = check_real(owner, "lead", lead_value, low=0.0)
        flock_lead_value: Gain = (
            tuned.get("flock_lead", self.DEFAULT_FLOCK_LEAD) if flock_lead is None else flock_lead
        )
        self.flock_lead: float = check_real(owner, "flock_lead", flock_lead_value, low=0.0)
        pull: Gain = (
            tuned.get("goal_pull", self.DEFAULT_GOAL_PULL) if goal_pull is None else goal_pull
        )
        if pull not in self.GOAL_PULLS:
            raise ValueError(f"{owner}.goal_pull must be one of {self.GOAL_PULLS}, got {pull!r}")
        self.goal_pull: str = str(pull)
        self.obs_neighbor_scale: float = self.cfg.obs_neighbor_scale

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}(k_p={self.k_p:g}, k_d={self.k_d:g}, k_v={self.k_v:g}, "
            f"k_c={self.k_c:g}, k_l={self.k_l:g}, tether={self.tether:g}, lead={self.lead:g}, "
            f"flock_lead={self.flock_lead:g}, goal_pull={self.goal_pull!r}, "
            f"saturation={self.saturation!r})"
        )

    def gains(self) -> dict[str, float]:
        """The gains a gain schedule may vary per agent (:data:`SCHEDULED_GAINS`), as
        this controller holds them."""
        return {name: float(getattr(self, name)) for name in SCHEDULED_GAINS}

    def neighbour_view(self, obs: np.ndarray) -> NeighbourView:
        """What the controller reads of each agent's neighbours in per-agent observations
        ``(n, obs_dim)`` (float64, world units)."""
        d, k = self.dim, self.cfg.n_neighbors
        blocks = obs[:, own_size(self.cfg) :].reshape(len(obs), k, block_size(self.cfg))
        real = blocks[..., 2 * d]
        return NeighbourView(
            offset=blocks[..., :d] * self.obs_neighbor_scale,
            rel_velocity=blocks[..., d : 2 * d] * self.obs_velocity_scale,
            real=real,
            informed=blocks[..., -1] * real,
        )

    def _actions(self, obs: np.ndarray, deterministic: bool) -> np.ndarray:
        return self.actions_with_gains(obs, {})

    def actions_with_gains(self, obs: np.ndarray, gains: Mapping[str, Any]) -> np.ndarray:
        """Actions ``(n, d)`` for per-agent observations ``(n, obs_dim)`` with ``gains``
        in place of the controller's own: each of :data:`SCHEDULED_GAINS` a number or a
        column ``(n, 1)``, one value per agent (a learned gain schedule,
        :mod:`train.gain_schedule`); a gain not given is the controller's."""
        unknown = sorted(set(gains) - set(SCHEDULED_GAINS))
        if unknown:
            raise ValueError(
                f"unknown gains {unknown}; a schedule may set {', '.join(SCHEDULED_GAINS)}"
            )
        g = {**self.gains(), **gains}
        d = self.dim
        informed = obs[:, 2 * d] > 0.5
        view = self.neighbour_view(obs)
        offset, rel_velocity, real, told = view.offset, view.rel_velocity, view.real, view.informed
        # Informed neighbours where there are any, else every real neighbour.
        weight = np.where(told.sum(axis=1, keepdims=True) > 0, told, real)
        count = np.maximum(weight.sum(axis=1, keepdims=True), 1.0)
        mean_velocity = np.einsum("nk,nkd->nd", weight, rel_velocity) / count
        mean_offset = np.einsum("nk,nkd->nd", weight, offset) / count
        if np.any(g["lead"] > 0) or np.any(g["flock_lead"] > 0):
            # A point ahead of the neighbours followed (the informed ones where there are
            # any: lead; else all: flock_lead), along their mean velocity.
            heading = mean_velocity + obs[:, d : 2 * d] * self.obs_velocity_scale
            speed = np.sqrt(np.einsum("nd,nd->n", heading, heading))[:, None]
            ahead = told.sum(axis=1, keepdims=True) > 0
            length = np.where(ahead, g["lead"], g["flock_lead"])
            scale = np.where(speed > 0, length / np.where(speed > 0, speed, 1.0), 0.0)
            mean_offset = mean_offset + scale * heading
        followers = saturate(
            (g["k_v"] * mean_velocity + g["k_c"] * mean_offset) / self.u_max, self.saturation
        )
        # The leaders' PD law, with the tether to all their real neighbours.
        pd = self.command(
            obs[:, :d] * self.obs_goal_scale,
            obs[:, d : 2 * d] * self.obs_velocity_scale,
            g["k_p"],
            g["k_d"],
        )
        if self.goal_pull == "saturated":
            pd = self.u_max * saturate(pd / self.u_max, self.saturation)
        if np.any(g["k_l"] > 0):
            flock = np.einsum("nk,nkd->nd", real, offset) / np.maximum(
                real.sum(axis=1, keepdims=True), 1.0
            )
            length = np.sqrt(np.einsum("nd,nd->n", flock, flock))[:, None]
            stretch = np.maximum(length - g["tether"], 0.0) / np.where(length > 0, length, 1.0)
            pd = pd + g["k_l"] * stretch * flock
        leaders = saturate(pd / self.u_max, self.saturation)
        return np.where(informed[:, None], leaders, followers)
