"""The agent statuses of the cut-off core: who acts, moves and takes part in the physics.

:class:`SparseStatuses` is a base class of
:class:`~swarm_envs.envs.sparse_core.SparseSwarmNavCore` that keeps each agent's status
(:mod:`~swarm_envs.envs.task.agent_status`) and takes new ones between steps
(:meth:`SparseStatuses.set_status`, the rules of the numpy core's
:meth:`~swarm_envs.envs.core.SwarmNavCore.set_status`). Where the config needs the
masks (``perturbations.needs_masks``), the core leaves the agents not present out of
its cell lists (they are neither sources nor receivers of a pair term or rate, not
counted in a collision, nobody's neighbour: :mod:`swarm_envs.physics.present_neighbors`
and the ``present`` argument of
:func:`~swarm_envs.physics.compiled_pairs.swarm_pair_sums`), holds the agents that do
not move at rest (zero total force, :meth:`SparseStatuses._hold`), and sums the goal
sink's energy over the present agents; the statistics are over the members (the agents
that move) and a close pair of two agents at rest is no collision. A config that needs
no statuses runs none of this.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from swarm_envs.envs.task.agent_status import keep_measured, masks, status_update

__all__ = ["SparseStatuses"]


class SparseStatuses:
    """Agent statuses of :class:`~swarm_envs.envs.sparse_core.SparseSwarmNavCore` (a
    base class of it; see the module docstring). It works on the core's state and
    measures the swarms it changes with the core's own pair pass and measure."""

    cfg: Any
    batch: int
    dtype: Any
    x: np.ndarray
    v: np.ndarray
    #: Each agent's status ``(B, N)`` int8; ``None`` until set.
    status: np.ndarray | None
    _members: np.ndarray | None
    _state: int
    _f_passive: np.ndarray | None
    _stats: dict[str, np.ndarray]
    _prev: dict[str, np.ndarray]
    _start: dict[str, np.ndarray]
    #: Agents in the physics and agents that move ``(B, N)`` bool, ``None`` while
    #: every agent is (a config that needs no masks).
    _present: np.ndarray | None
    _mobile: np.ndarray | None
    #: The present agents that do not move, where some swarm has two of them (their
    #: close pairs are no collision); else ``None``.
    _still: np.ndarray | None
    # The core's own methods that these use.
    _physics_goal: Callable[[], np.ndarray | None]
    _pair_pass: Callable[..., Any]
    _keep: Callable[[np.ndarray | None, Any], None]
    _measure: Callable[..., None]

    def _init_statuses(self) -> None:
        """No statuses set yet: every agent active."""
        self._present = self._mobile = self._still = None

    def _hold(self, accel: np.ndarray, rows: np.ndarray | None) -> np.ndarray:
        """The total force ``accel`` of the swarms ``rows`` (``None``: all) with the agents
        that do not move at zero (their velocity is zero: they keep their position)."""
        if self._mobile is None:
            return accel
        mobile = self._mobile if rows is None else self._mobile[rows]
        return np.where(mobile[..., None], accel, 0.0).astype(self.dtype, copy=False)

    def set_status(
        self,
        status: np.ndarray,
        place: np.ndarray | None = None,
        at: np.ndarray | None = None,
        *,
        rows: np.ndarray | None = None,
        start: bool = False,
    ) -> None:
        """Give the agents new statuses ``(B, N)`` (agent_status) between steps, as
        :meth:`SwarmNavCore.set_status <swarm_envs.envs.core.SwarmNavCore.set_status>`.

        ``place`` ``(B, N)`` bool: agents put at ``at`` ``(B, N, d)`` (joining agents).
        Agents that no longer move and placed agents are at rest. The swarms whose
        statuses or places changed, and those in ``rows`` ``(B,)``, take a pair pass
        and are measured again (their last step's substep count kept), and their
        previous statistics become these (``start=True``: their episode's start too).
        Where the config needs the masks (``perturbations.needs_masks``), the agents not
        present are then left out of the pair passes and the neighbour search, and the
        total force of the agents that do not move is zero.

        Raises:
            ValueError: ``status`` not ``(B, N)`` with values 0 to 3 (``ABSENT``), or
                ``place``/``at`` of the wrong shape.
        """
        cfg = self.cfg
        shape = (self.batch, cfg.n_agents, cfg.dim)
        status, place, rows = status_update(self.status, status, place, at, rows, shape)
        if place is not None:
            self.x = np.where(place[..., None], at, self.x).astype(self.dtype, copy=False)
        self.status = status
        mask = masks(status)
        self.v = np.where(mask.mobile[..., None], self.v, 0.0).astype(self.dtype, copy=False)
        if place is not None:
            self.v[place] = 0.0
        self._state += 1  # a new state: the neighbours are searched again
        self._members = mask.mobile
        if cfg.perturbations.needs_masks:
            self._present, self._mobile = mask.present, mask.mobile
        still = ~mask.mobile if self._present is None else mask.present & ~mask.mobile
        pairs = cfg.collision_radius > 0 and (np.count_nonzero(still, axis=-1) > 1).any()
        self._still = still if pairs else None
        if not rows.any() or self._f_passive is None:
            return
        idx = np.flatnonzero(rows)
        goal = self._physics_goal()
        res = self._pair_pass(self.x[idx], self.v[idx], None if goal is None else goal[idx], idx)
        self._f_passive[idx] = res.force
        self._keep(idx, res)
        before = self._stats
        with np.errstate(over="ignore", invalid="ignore"):
            self._measure(substeps=before["substeps"])
        keep_measured(self._stats, before, self._prev, self._start, rows, start)
