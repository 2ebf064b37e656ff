"""The torch core's step-size control on the host: which path a step takes, the
substep loop, and the unstable guard.

:class:`SubstepControl` is a part of :class:`~swarm_envs.envs.torch_core.TorchSwarmNavCore`
(its state, its compiled functions); the semantics are those of the numpy core
(:meth:`~swarm_envs.envs.dynamics.SocialPotentialDynamics.step`,
:meth:`~swarm_envs.envs.core.SwarmNavCore.step`):

- the fused step returns, per swarm, the stable substep ``h*`` of the new state and
  ``h*`` where that state is finite, NaN where not (``"h_guard"``), and whether that is
  at least ``dt`` for the whole batch (``"calm"``;
  :data:`~swarm_envs.envs.torch_step.PACKED_KEYS`). That one value, read on the host
  (:attr:`SubstepControl._calm`), says both that the step went stable and that the
  next one takes the whole ``dt`` in one substep for every swarm: the common case costs
  that read;
- otherwise the substep function (:func:`~swarm_envs.envs.torch_step.build_substep`)
  plans and takes every swarm's substeps but its last
  (:func:`~swarm_envs.envs.torch_step.plan_substep`; one flag read on the host per
  substep), and the fused function takes the last ones and measures the new state (a
  swarm that needed only one takes it in the substep function);
- after the step, :func:`~swarm_envs.envs.common.unstable_swarms` (skipped when the
  comparison above passed and no swarm was over the cap): raise
  :class:`~swarm_envs.envs.common.SwarmUnstableError`, or truncate those swarms at their
  state before the step (``on_unstable``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from swarm_envs.envs.common import (
    SwarmUnstableError,
    beyond_bound,
    unstable_message,
    unstable_swarms,
)
from swarm_envs.envs.task import STAT_KEYS
from swarm_envs.envs.torch_step import PACKED_KEYS

__all__ = ["UNSTABLE", "SubstepControl"]

_H_STABLE = PACKED_KEYS.index("h_stable")
_H_GUARD = PACKED_KEYS.index("h_guard")
_CALM = PACKED_KEYS.index("calm")
#: The column of the ``unstable`` statistic in the packed row.
UNSTABLE = STAT_KEYS.index("unstable")

State = tuple[torch.Tensor, torch.Tensor]


class SubstepControl:
    """The step-size control of :class:`~swarm_envs.envs.torch_core.TorchSwarmNavCore`
    (a base class of it; see the module docstring). It works on the core's state
    (``_x, _v, _f`` ``(d, B, N)``, ``_goal``, the packed rows ``_packed`` and their host
    copy), runs its functions (``_run``: the fused step on the whole batch; ``_substep``:
    the substep function) and keeps ``_counted`` (the ``substeps`` statistic to report)
    and ``_flagged`` (the swarms truncated as unstable) up to date."""

    cfg: Any
    batch: int
    device: torch.device
    _tdtype: torch.dtype
    _x: torch.Tensor
    _v: torch.Tensor
    _f: torch.Tensor
    _goal: torch.Tensor
    _packed: torch.Tensor
    _packed_host: np.ndarray
    _counted: torch.Tensor
    _flagged: np.ndarray | None
    _calm: bool
    _energy_bound: float
    _wide_start: tuple[torch.Tensor, ...]

    def _host_packed(self, whole: bool = True) -> None:
        """Copy the packed rows to the host, and note whether every swarm's state is
        finite and allows the whole ``dt`` in one substep (:attr:`_calm`): the fused
        step's verdict on the batch when it measured all of it (``whole``), else
        recomputed from each row's ``h_guard``."""
        packed = self._packed_host = self._packed.cpu().numpy()
        if whole:
            self._calm = bool(packed[0, _CALM])
        else:  # NaN (a non-finite state) compares False
            self._calm = bool((packed[:, _H_GUARD] >= np.float64(self.cfg.dt)).all())

    def _integrate(self, a: torch.Tensor) -> tuple[State, np.ndarray | None, np.ndarray]:
        """Advance every swarm by ``dt`` with actions ``a`` and measure the new state.

        Returns the state before the step (for the guard), where a swarm needed more
        substeps than ``max_substeps`` (``None``: nowhere) and how many it needed.
        """
        self._flagged = None
        before = (self._x, self._v)
        if self._calm:  # every swarm takes dt in one substep: the fused step alone
            self._counted = self._one_each
            self._run(a, self._dt_each)
            if self._graphed is not None:  # its outputs were overwritten, not its inputs
                before = self._graphed.inputs[0], self._graphed.inputs[1]
            return before, None, self._one_needed
        if self._graphed is not None:  # graph outputs: the last substep overwrites them
            before = before[0].clone(), before[1].clone()
        over, needed = self._substeps(a)
        return before, over, needed

    def _guard(
        self,
        a: torch.Tensor,
        stats: dict[str, np.ndarray],
        before: State,
        over: np.ndarray | None,
        needed: np.ndarray,
    ) -> tuple[dict[str, np.ndarray], np.ndarray | None]:
        """The unstable guard after a step: ``(stats, bad)``, the statistics (re-measured
        when swarms were truncated) and the unstable swarms (``None``: none)."""
        bound = self._energy_bound
        if over is None and self._calm and not beyond_bound(stats, bound):
            return stats, None  # every state finite and within the bound, none over the cap
        no_swarm = np.zeros(self.batch, dtype=bool)
        bad = unstable_swarms(stats, no_swarm if over is None else over, bound)
        if not bad.any():
            return stats, None
        return self._unstable(a, bad, before, stats, needed), bad

    def _substep_inputs(self, a: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """The substep function's arguments for the first substep of a step with
        actions ``a``."""
        remaining, used, needed = self._wide_start  # never written: shared by the steps
        no_swarm = torch.zeros(self.batch, dtype=torch.bool, device=self.device)
        h_stable = self._packed[:, _H_STABLE].contiguous()
        x, v, f, goal = self._x, self._v, self._f, self._goal
        status = self._status_arg()
        return (x, v, f, goal, a, h_stable, remaining, used, no_swarm, needed, *status)

    def _substeps(self, a: torch.Tensor) -> tuple[np.ndarray, np.ndarray]:
        """Take the step's substeps, every swarm until its ``dt`` is spent (at most
        ``max_substeps``): all but each swarm's last through the substep function (with
        one host read per substep), the last ones in the fused step, which measures
        the new state. Sets the state and :attr:`_counted`; returns ``(over_cap,
        needed)`` per swarm on the host, as the numpy core counts them."""
        inputs = self._substep_inputs(a)
        x, v, f, goal, _, h_stable, remaining, used, over, needed, *status = inputs
        for _ in range(self.cfg.max_substeps):
            x, v, f, h_stable, remaining, used, over, needed, more, last = self._substep(
                x, v, f, goal, a, h_stable, remaining, used, over, needed, *status
            )
            if not bool(more):
                break
        else:  # the cap leaves at most max_substeps - 1 substeps before the last
            raise RuntimeError("substeps left after max_substeps substeps")
        h, self._counted, counts = last
        self._x, self._v, self._f = x, v, f
        self._run(a, h)  # the last substeps (h > 0), and the measure of every swarm
        over_cap, needed = counts.cpu().numpy()
        return over_cap > 0, needed

    def _unstable(
        self,
        a: torch.Tensor,
        bad: np.ndarray,
        before: State,
        stats: dict[str, np.ndarray],
        needed: np.ndarray,
    ) -> dict[str, np.ndarray]:
        """Put the swarms ``bad`` back to their state ``before`` the step, re-measured;
        then raise :class:`~swarm_envs.envs.common.SwarmUnstableError` (the core stays
        at the last sound state), or (``on_unstable="truncate"``) mark them
        ``unstable`` and return the statistics."""
        cfg = self.cfg
        message = unstable_message(cfg, stats, bad, needed, self.t)
        idx = np.flatnonzero(bad)
        rows = torch.as_tensor(idx, device=self.device)
        self._x, self._v = self._x.clone(), self._v.clone()  # out of place, as a reset
        self._x[:, rows], self._v[:, rows] = before[0][:, rows], before[1][:, rows]
        self._counted = self._counted.index_put((rows,), self._none_each[rows])  # undone
        self._flagged = None if cfg.on_unstable == "raise" else idx
        self._run(a, self._no_step)
        if cfg.on_unstable == "raise":
            raise SwarmUnstableError(message)
        return self.stats()
