"""The task layer: what a SwarmNav episode is, written once above the cores.

A core is an execution strategy (:class:`~swarm_envs.envs.protocol.Execution`): it holds
the state of ``B`` swarms, advances their physics and measures them (the statistics, the
actions' effort, whether a swarm may have gone unstable, the observation's inputs). The
:class:`TaskLayer` it holds owns the rest, for every backend alike:

- the **previous and start statistics** of each swarm (:class:`HostRecords`, or a core's
  own :class:`Records` where they stay on its device);
- the **reward** (:func:`~swarm_envs.envs.task.reward.reward` over
  :data:`~swarm_envs.envs.task.reward.REWARD_TERMS`), from this step's statistics, the
  previous step's, the episode start's and the effort; a fused kernel (the compiled
  torch step) may compute it inside its graph from the same declarations and report it;
- the **episode end** (:func:`~swarm_envs.envs.task.episode.episode_end`);
- the **unstable guard**: a swarm whose state stopped being finite, whose energy left
  its bound (:func:`~swarm_envs.envs.common.energy_bound`) or that needed more substeps
  than ``max_substeps`` is put back to its state before the step by its core; then
  :class:`~swarm_envs.envs.common.SwarmUnstableError` is raised (``on_unstable="raise"``)
  or the swarm's episode is truncated with reward 0 and ``unstable`` 1;
- the **starts** (:func:`~swarm_envs.envs.common.draw_starts`, then the start's check)
  and the **agent statuses** given between steps
  (:func:`~swarm_envs.envs.task.agent_status.status_update`, then
  :func:`~swarm_envs.envs.task.agent_status.keep_measured`: the swarms measured again
  start comparing from their new statistics).

:class:`TaskCore` gives a core the ``reset``, ``step`` and ``set_status`` of
:class:`~swarm_envs.envs.protocol.StatusCore` by calling its task layer with itself.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import TYPE_CHECKING, Any, NamedTuple, Protocol

import numpy as np

from swarm_envs._array import NUMPY, SCALAR
from swarm_envs.envs.common import (
    SwarmUnstableError,
    beyond_bound,
    check_start,
    draw_starts,
    energy_bound,
    unstable_message,
    unstable_swarms,
)
from swarm_envs.envs.stiffness import StiffnessWatch
from swarm_envs.envs.task.agent_status import keep_measured, status_update
from swarm_envs.envs.task.episode import episode_end
from swarm_envs.envs.task.reward import RewardInputs, reward

if TYPE_CHECKING:
    from swarm_envs.config import SwarmConfig
    from swarm_envs.envs.protocol import Execution, StepResult

__all__ = ["Advance", "HostRecords", "Records", "TaskCore", "TaskLayer"]

Stats = dict[str, np.ndarray]


class Advance(NamedTuple):
    """What a core's step reports to its task layer, per swarm ``(B,)``.

    Attributes:
        stats: the new state's statistics (``STAT_KEYS``), arrays the step's caller gets.
        measured: the same as the core's :class:`Records` keep them
            (:meth:`Execution.measured <swarm_envs.envs.protocol.Execution.measured>`).
        effort: ``Σ_i |a_i|²`` of the clipped actions; ``None`` where ``reward`` is given.
        reward: the reward a fused kernel computed from the same declarations (float64;
            ``None``: the task layer computes it).
        over_cap: where a swarm needed more than ``max_substeps`` (``None``: nowhere).
        needed: the substeps each swarm needed at least (for the guard's message).
        suspect: whether a swarm may have gone unstable; if not, the guard checks only
            the energy bound (``False`` is a promise: finite and within the cap).
    """

    stats: Stats
    measured: Any
    effort: np.ndarray | None
    reward: np.ndarray | None
    over_cap: np.ndarray | None
    needed: np.ndarray
    suspect: bool = True


class Records(Protocol):
    """The previous and start statistics of ``B`` swarms, in a core's representation
    (what :meth:`Execution.measured <swarm_envs.envs.protocol.Execution.measured>`
    returns)."""

    prev: Any
    start: Any

    def take(self, measured: Any, idx: np.ndarray) -> None:
        """A new episode for the swarms ``idx``: ``measured`` is their previous and
        their start statistics."""
        ...

    def follow(self, measured: Any) -> None:
        """After a step: ``measured`` is every swarm's previous statistics."""
        ...

    def remeasured(self, measured: Any, before: Any, rows: np.ndarray, start: bool) -> None:
        """After new statuses: the swarms ``rows`` ``(B,)`` were measured again
        (``measured``; ``before``: the measure before); they compare from it
        (``start``: as their start too), the others keep what they had."""
        ...


class HostRecords:
    """:class:`Records` as ``{name: (B,)}`` numpy arrays (the numpy, cut-off and C cores)."""

    def __init__(self, prev: Stats, start: Stats) -> None:
        self.prev, self.start = prev, start

    def take(self, measured: Stats, idx: np.ndarray) -> None:
        for key, value in measured.items():
            self.prev[key][idx] = value[idx]
            self.start[key][idx] = value[idx]

    def keep(self, rows: np.ndarray) -> None:
        """Keep the swarms ``rows`` only (a core shrinking its batch)."""
        self.prev = {key: value[rows] for key, value in self.prev.items()}
        self.start = {key: value[rows] for key, value in self.start.items()}

    def follow(self, measured: Stats) -> None:
        # A copy: a reset writes the new episodes' rows into it.
        self.prev = {key: value.copy() for key, value in measured.items()}

    def remeasured(self, measured: Stats, before: Stats, rows: np.ndarray, start: bool) -> None:
        keep_measured(measured, before, self.prev, self.start, rows, start)


class _FirstSwarm(Mapping[str, float]):
    """The statistics of swarm 0 as floats, each read from its ``(B,)`` array when a
    reward term asks for it (a term reads a few of them)."""

    __slots__ = ("_stats",)

    def __init__(self, stats: Mapping[str, np.ndarray]) -> None:
        self._stats = stats

    def __getitem__(self, key: str) -> float:
        return float(self._stats[key][0])

    def __iter__(self) -> Iterator[str]:
        return iter(self._stats)

    def __len__(self) -> int:
        return len(self._stats)


class TaskLayer:
    """The task of ``batch`` SwarmNav swarms over their episodes (module docstring).

    Args:
        cfg: the :class:`~swarm_envs.config.SwarmConfig`.
        batch: number of swarms ``B``.
        records: the previous and start statistics, in the core's representation.

    Attributes:
        records: the :class:`Records`.
    """

    def __init__(self, cfg: SwarmConfig, batch: int, records: Records) -> None:
        self.cfg = cfg
        self.batch = batch
        self.records = records
        self._energy_bound = energy_bound(cfg)
        self._no_swarm = np.zeros(batch, dtype=bool)
        self._stiffness = StiffnessWatch(cfg, batch)

    def keep(self, rows: np.ndarray) -> None:
        """Keep the swarms ``rows`` only, in that order (a core shrinking its batch:
        :meth:`SwarmNavCore.keep <swarm_envs.envs.cores.numpy.SwarmNavCore.keep>`)."""
        if not isinstance(self.records, HostRecords):
            raise ValueError("keep: only a core whose records are host arrays can shrink")
        self.records.keep(rows)
        self._no_swarm = self._no_swarm[rows]
        self._stiffness.keep(rows)
        self.batch = len(rows)

    # ------------------------------------------------------------------ episodes
    def reset(
        self, core: Execution, rng: np.random.Generator, which: np.ndarray | None = None
    ) -> None:
        """New starts for the swarms in ``which`` (bool ``(B,)``; all if None): drawn
        from ``rng`` (:func:`~swarm_envs.envs.common.draw_starts`), placed and measured
        by ``core``, checked to be finite in its dtype, and taken as those swarms'
        previous and start statistics."""
        idx = np.arange(self.batch) if which is None else np.flatnonzero(which)
        if idx.size == 0:
            return
        x, v, goal = draw_starts(self.cfg, rng, idx.size)
        core.t[idx] = 0
        stats = core.begin(idx, x, v, goal, rng)
        check_start(self.cfg, stats, idx, core.dtype)
        self.records.take(core.measured(), idx)

    def step(self, core: Execution, actions: Any) -> StepResult:
        """One step of every swarm: ``core`` advances and measures them; then the
        guard, the reward, the episode end (module docstring).

        Returns:
            ``(reward (B,) float64, terminated (B,), truncated (B,), stats)``.

        Raises:
            SwarmUnstableError: a swarm went unstable under ``on_unstable="raise"``
                (``core`` is back at the last sound state).
        """
        out = core.advance(actions)
        core.t += 1
        stats, measured, bad = out.stats, out.measured, None
        if out.suspect or beyond_bound(stats, self._energy_bound):
            over = self._no_swarm if out.over_cap is None else out.over_cap
            found = unstable_swarms(stats, over, self._energy_bound)
            if found.any():
                bad = found
                stats = self._unstable(core, found, stats, out.needed)
                measured = core.measured()
        r = self._reward(stats, out.effort) if out.reward is None else out.reward
        self.records.follow(measured)
        terminated, truncated = episode_end(self.cfg, stats["success"], core.t)
        if bad is not None:
            r[bad], terminated[bad], truncated[bad] = 0.0, False, True
        self._stiffness.observe(stats)
        return r, terminated, truncated, stats

    def _unstable(
        self, core: Execution, bad: np.ndarray, stats: Stats, needed: np.ndarray
    ) -> Stats:
        """The swarms ``bad`` back at their state before the step; then raise, or
        (``on_unstable="truncate"``) their statistics with ``unstable`` 1."""
        cfg = self.cfg
        message = unstable_message(cfg, stats, bad, needed, core.t)
        truncate = cfg.on_unstable != "raise"
        stats = core.undo(np.flatnonzero(bad), truncate)
        if not truncate:
            raise SwarmUnstableError(message)
        return stats

    def _reward(self, stats: Stats, effort: Any) -> np.ndarray:
        """The reward ``(B,)`` float64 of :func:`~swarm_envs.envs.task.reward.reward`
        (for one swarm on plain floats: the same definitions, no array overhead)."""
        records, n = self.records, self.cfg.n_agents
        if self.batch == 1:
            first = _FirstSwarm(stats), _FirstSwarm(records.prev), _FirstSwarm(records.start)
            inputs = RewardInputs(*first, float(effort[0]), n, SCALAR)
            return np.array([reward(self.cfg.reward, inputs)], dtype=np.float64)
        inputs = RewardInputs(stats, records.prev, records.start, effort, n, NUMPY)
        return np.asarray(reward(self.cfg.reward, inputs), dtype=np.float64)

    # ------------------------------------------------------------------ statuses
    def set_status(
        self,
        core: Execution,
        status: Any,
        place: Any = None,
        at: Any = None,
        *,
        rows: Any = None,
        start: bool = False,
    ) -> None:
        """New agent statuses for ``core`` (the contract of
        :meth:`StatusCore.set_status <swarm_envs.envs.protocol.StatusCore.set_status>`):
        checked, given to the core, and the swarms whose statuses or places changed
        (or in ``rows``) measured again and compared from there."""
        cfg = self.cfg
        shape = (self.batch, cfg.n_agents, cfg.dim)
        update = status_update(core.status, status, place, at, rows, shape)
        core.take_statuses(update.status, update.place, at)
        if not update.rows.any():
            return
        before = core.measured()
        core.remeasure(np.flatnonzero(update.rows))
        self.records.remeasured(core.measured(), before, update.rows, start)


class TaskCore:
    """The :class:`~swarm_envs.envs.protocol.StatusCore` methods a core gets from its
    :class:`TaskLayer` (the attribute ``task``): each calls the layer with the core."""

    task: TaskLayer

    def reset(self, rng: np.random.Generator, which: np.ndarray | None = None) -> None:
        """New starts for the swarms in ``which`` (bool ``(B,)``; all if None), drawn
        from ``rng`` (:meth:`TaskLayer.reset`)."""
        self.task.reset(self, rng, which)  # type: ignore[arg-type]

    def step(self, actions: Any) -> StepResult:
        """Advance every swarm by one step with actions ``(B, N, d)`` in [−1, 1]
        (:meth:`TaskLayer.step`): ``(reward, terminated, truncated, stats)``."""
        return self.task.step(self, actions)  # type: ignore[arg-type]

    def set_status(
        self,
        status: np.ndarray,
        place: np.ndarray | None = None,
        at: np.ndarray | None = None,
        *,
        rows: np.ndarray | None = None,
        start: bool = False,
    ) -> None:
        """Give the agents new statuses ``(B, N)`` between steps
        (:meth:`StatusCore.set_status <swarm_envs.envs.protocol.StatusCore.set_status>`)."""
        self.task.set_status(self, status, place, at, rows=rows, start=start)  # type: ignore[arg-type]
