"""The agent statuses' masks in the cut-off core's physics.

:class:`PhysicsMasks` is held by :class:`~swarm_envs.envs.cores.cutoff.core.CutoffSwarmNavCore`:
where the config needs the masks (``perturbations.needs_masks``), the core leaves the
agents not present out of its cell lists (they are neither sources nor receivers of a
pair term or rate, not counted in a collision, nobody's neighbour:
:mod:`swarm_envs.physics.present_neighbors` and the ``present`` argument of
:func:`~swarm_envs.physics.compiled_pairs.swarm_pair_sums`), holds the agents that do not
move at rest (zero total force, :meth:`PhysicsMasks.hold`), and sums the goal sink's
energy over the present agents; the statistics are over the members (the agents that
move) and a close pair of two agents at rest is no collision. A config that needs no
statuses runs none of this. The statuses themselves, and what a change of them does to
the episode, are the task layer's (:mod:`swarm_envs.envs.task.layer`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from swarm_envs.envs.task.agent_status import AgentMasks

if TYPE_CHECKING:
    from swarm_envs.config import SwarmConfig

__all__ = ["PhysicsMasks"]


class PhysicsMasks:
    """Which agents take part in the cut-off core's physics, ``(B, N)`` bool each.

    Attributes:
        present: the agents in the physics; ``None`` while every agent is (a config
            that needs no masks).
        mobile: the agents that move; ``None`` likewise.
        still: the present agents that do not move, where some swarm has two of them
            (their close pairs are no collision); else ``None``.
    """

    def __init__(self) -> None:
        self.present: np.ndarray | None = None
        self.mobile: np.ndarray | None = None
        self.still: np.ndarray | None = None

    def take(self, mask: AgentMasks, cfg: SwarmConfig) -> None:
        """The masks of new statuses (the physics' only where ``perturbations.needs_masks``)."""
        if cfg.perturbations.needs_masks:
            self.present, self.mobile = mask.present, mask.mobile
        still = ~mask.mobile if self.present is None else mask.present & ~mask.mobile
        pairs = cfg.collision_radius > 0 and (np.count_nonzero(still, axis=-1) > 1).any()
        self.still = still if pairs else None

    def hold(self, accel: np.ndarray, rows: np.ndarray | None) -> np.ndarray:
        """The total force ``accel`` of the swarms ``rows`` (``None``: all) with the agents
        that do not move at zero (their velocity is zero: they keep their position)."""
        if self.mobile is None:
            return accel
        mobile = self.mobile if rows is None else self.mobile[rows]
        return np.where(mobile[..., None], accel, 0.0).astype(accel.dtype, copy=False)
