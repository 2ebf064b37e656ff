"""The torch core's resets: new starts, and the measure of a few swarms alone.

:class:`ResetControl` is a part of :class:`~swarm_envs.envs.torch_core.TorchSwarmNavCore`
(its state, its compiled functions). A reset draws the starts on the host with the numpy
generator, as every core does (:func:`~swarm_envs.envs.common.draw_starts`), moves them to
the device out of place (the old tensors may share memory with arrays handed out), and
measures the new state with the fused function, integration off. A reset of a few swarms
(at most :func:`partial_reset_batch` of them) measures only those, through the same
function compiled for that sub-batch: in a VecEnv some swarm ends on most steps, and
measuring all of them each time would double the step.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from swarm_envs._runtime.torch_compile import MaybeCompiled
from swarm_envs.envs.common import check_start, draw_starts
from swarm_envs.envs.torch_substeps import UNSTABLE

__all__ = ["PARTIAL_RESET_MIN_BATCH", "ResetControl", "partial_reset_batch"]

#: The smallest batch whose resets of a few swarms measure only those (see
#: :func:`partial_reset_batch`); smaller batches re-measure every swarm on a reset.
PARTIAL_RESET_MIN_BATCH = 64


def partial_reset_batch(batch: int) -> int | None:
    """Sub-batch size ``R = batch // 16`` for resets of at most R swarms, or ``None``.

    With ``batch ≥ PARTIAL_RESET_MIN_BATCH`` a reset of at most ``R`` swarms runs the
    fused function on those swarms only (padded to R): 1/16 of a step. Below that size,
    or for larger resets, every swarm is measured, which costs a whole step.
    """
    return batch // 16 if batch >= PARTIAL_RESET_MIN_BATCH else None


class ResetControl:
    """The resets of :class:`~swarm_envs.envs.torch_core.TorchSwarmNavCore` (a base class
    of it; see the module docstring)."""

    cfg: Any
    batch: int
    device: torch.device
    dtype: np.dtype
    t: np.ndarray
    reset_batch: int | None
    _advance_part: MaybeCompiled | None
    _x: torch.Tensor
    _v: torch.Tensor
    _f: torch.Tensor
    _goal: torch.Tensor
    _obs: torch.Tensor
    _obs_given: bool
    _obs_shared: bool
    _packed: torch.Tensor
    _prev: torch.Tensor
    _start: torch.Tensor
    _counted: torch.Tensor
    _none_each: torch.Tensor
    _no_action: torch.Tensor
    _no_step: torch.Tensor
    _flagged: np.ndarray | None

    def _row_args(self, rows: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """The fused function's arguments for swarms ``rows`` only, measuring (no step)."""
        n = rows.shape[0]
        return (
            self._x[:, rows],
            self._v[:, rows],
            self._f[:, rows],
            self._goal[rows],
            self._no_action[:n],
            self._no_step[:n],
            self._counted[rows],
            self._prev[rows],
            self._start[rows],
            *self._status_arg(rows),
        )

    def _measure_rows(self, rows: torch.Tensor) -> None:
        """:meth:`_measure` for swarms ``rows`` (at most :attr:`reset_batch`) only.

        The rows are padded to ``reset_batch`` with copies of the first; the results of
        the real ones are written into the force, observations and statistics; the
        ``unstable`` statistic of every swarm but those :attr:`_flagged` becomes 0, as
        the measure of the whole batch makes it (a reset clears the flags first).
        """
        assert self._advance_part is not None and self.reset_batch is not None
        n = rows.shape[0]
        padded = torch.cat([rows, rows[:1].expand(self.reset_batch - n)])
        _, _, f, obs, packed, _, _ = self._advance_part(*self._row_args(padded))
        self._f = self._f.clone()
        self._f[:, rows] = f[:, :n]
        if self._obs_given or self._obs_shared:  # handed out: leave that memory alone
            self._obs = self._obs.clone()
            self._obs_given = self._obs_shared = False
        self._obs[rows] = obs[:n]
        self._packed = self._packed.index_put((rows,), packed[:n])  # a new tensor
        self._packed[:, UNSTABLE] = 0.0
        if self._flagged is not None:
            self._packed[torch.as_tensor(self._flagged, device=self.device), UNSTABLE] = 1.0
        self._host_packed(whole=False)

    # ------------------------------------------------------------------ reset
    def reset(self, rng: np.random.Generator, which: np.ndarray | None = None) -> None:
        """Draw new starts for the swarms in ``which`` (bool mask ``(B,)``; all if None),
        with :func:`~swarm_envs.envs.common.draw_starts` as every core."""
        idx = np.arange(self.batch) if which is None else np.flatnonzero(which)
        if idx.size == 0:
            return
        x, v, goal = draw_starts(self.cfg, rng, idx.size)
        self.t[idx] = 0
        # Out of place: the old tensors may share memory with arrays handed out.
        rows = torch.as_tensor(idx, device=self.device)
        # No step yet for these swarms; the others keep their last step's substeps.
        self._counted = self._counted.index_put((rows,), self._none_each[rows])
        self._flagged = None
        self._x = self._put(self._x, rows, x)
        self._v = self._put(self._v, rows, v)
        self._goal = self._goal.index_put((rows,), self._to_device(goal))
        if self.reset_batch is not None and idx.size <= self.reset_batch:
            self._measure_rows(rows)
        else:
            self._measure()
        check_start(self.cfg, self.stats(), idx, self.dtype)
        measured = self._packed[rows]
        self._prev = self._prev.index_put((rows,), measured)
        self._start = self._start.index_put((rows,), measured)

    def _put(self, state: torch.Tensor, rows: torch.Tensor, new: np.ndarray) -> torch.Tensor:
        """A copy of ``state`` ``(d, B, N)`` with swarms ``rows`` set from ``new`` ``(n, N, d)``."""
        out = state.clone()
        out[:, rows] = self._to_device(new).permute(2, 0, 1)
        return out
