"""The torch core's agent statuses: who acts, moves and takes part in the physics.

:class:`StatusControl` is a part of :class:`~swarm_envs.envs.torch_core.TorchSwarmNavCore`
that keeps each agent's status (:mod:`~swarm_envs.envs.task.agent_status`) on the device
and takes new ones between steps (:meth:`StatusControl.set_status`, the numpy core's
:meth:`~swarm_envs.envs.core.SwarmNavCore.set_status`). A core whose config needs
statuses (``perturbations.needs_masks`` or ``observe_status``) passes them to its fused
step and its substep function (:mod:`swarm_envs.envs.torch_step`), which apply the masks;
a core whose config needs none runs the functions without them.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from swarm_envs.envs.task.agent_status import masks, status_update

__all__ = ["StatusControl", "needs_statuses"]


def needs_statuses(cfg: Any) -> bool:
    """Whether a core of ``cfg`` takes agent statuses: agents that leave, stop or join
    the physics (``perturbations.needs_masks``), or statuses in the observation."""
    return bool(cfg.needs_statuses)


class StatusControl:
    """Agent statuses of :class:`~swarm_envs.envs.torch_core.TorchSwarmNavCore` (a base
    class of it; see the module docstring). It works on the core's state (``_x, _v``
    ``(d, B, N)``, the packed rows, the previous and start rows) and measures the swarms
    it changes with the core's own measure (that of a reset)."""

    cfg: Any
    batch: int
    device: torch.device
    dtype: np.dtype
    reset_batch: int | None
    _x: torch.Tensor
    _v: torch.Tensor
    _packed: torch.Tensor
    _prev: torch.Tensor
    _start: torch.Tensor
    #: Whether the functions take statuses (:func:`needs_statuses` of the config).
    _statuses: bool
    #: Each agent's status on the device ``(B, N)`` int8 (all active until set).
    _status: torch.Tensor
    #: Each agent's status ``(B, N)`` int8 on the host; ``None`` until set.
    status: np.ndarray | None

    def _init_statuses(self) -> None:
        """No statuses set yet: every agent active."""
        self._statuses = needs_statuses(self.cfg)
        self.status = None
        shape = (self.batch, self.cfg.n_agents)
        self._status = torch.zeros(shape, dtype=torch.int8, device=self.device)

    def _status_arg(self, rows: torch.Tensor | None = None) -> tuple[torch.Tensor, ...]:
        """The functions' last argument, the statuses (of swarms ``rows``), or nothing
        where the config needs none."""
        if not self._statuses:
            return ()
        return (self._status if rows is None else self._status[rows],)

    def set_status(
        self,
        status: np.ndarray,
        place: np.ndarray | None = None,
        at: np.ndarray | None = None,
        *,
        rows: np.ndarray | None = None,
        start: bool = False,
    ) -> None:
        """Give the agents new statuses ``(B, N)`` (agent_status) between steps.

        ``place`` ``(B, N)`` bool: agents put at ``at`` ``(B, N, d)`` (joining agents).
        Agents that no longer move and placed agents are at rest. The swarms whose
        statuses or places changed, and those in ``rows`` ``(B,)``, are measured
        again, and their previous statistics become these (``start=True``: their
        episode's start too), so that the next reward compares like with like.

        Raises:
            ValueError: the config needs no statuses (the core's functions were built
                without them), or ``status``, ``place`` or ``at`` of the wrong shape or
                values.
        """
        if not self._statuses:
            raise ValueError(
                "set_status needs a config with agent statuses (perturbations that remove, "
                "freeze or add agents, or observe_status); this core's config has none"
            )
        shape = (self.batch, self.cfg.n_agents, self.cfg.dim)
        status, place, rows = status_update(self.status, status, place, at, rows, shape)
        still = ~masks(status).mobile  # at rest: those that no longer move, and placed ones
        if place is not None:
            still = still | place
            where = torch.as_tensor(place, device=self.device)
            # (d, B, N) stored contiguous, as every state tensor the compiled functions
            # read: torch.where lays its result out as its inputs are, and a permuted view
            # would hand them another layout than they were traced for.
            at_t = torch.from_numpy(np.ascontiguousarray(np.moveaxis(at, -1, 0), dtype=self.dtype))
            self._x = torch.where(where, at_t.to(self.device), self._x)  # a new tensor
        self.status = status
        self._status = torch.as_tensor(status, device=self.device).clone()
        if still.any():
            rest = torch.as_tensor(still, device=self.device)
            self._v = torch.where(rest, 0.0, self._v)
        if not rows.any():
            return
        idx = np.flatnonzero(rows)
        changed_rows = torch.as_tensor(idx, device=self.device)
        if self.reset_batch is not None and idx.size <= self.reset_batch:
            self._measure_rows(changed_rows)
        else:
            self._measure()
        measured = self._packed[changed_rows]
        self._prev = self._prev.index_put((changed_rows,), measured)
        if start:
            self._start = self._start.index_put((changed_rows,), measured)
