"""The interface every SwarmNav core implements: :class:`Core`, and under it :class:`Execution`.

A core holds the state of ``batch`` independent swarms and steps them all at once; the
PettingZoo, Gymnasium and SB3 adapters are written against :class:`Core` only, and
:func:`swarm_envs.envs.backends.make_core` returns one. Arrays in and out are numpy.

Each backend implements :class:`Execution`: how the physics advances and is measured.
The task (reward, episode end, previous and start statistics, the unstable guard, the
starts and the statuses' bookkeeping) is the one
:class:`~swarm_envs.envs.task.layer.TaskLayer` a core holds, which gives it ``reset``,
``step`` and ``set_status`` (:class:`~swarm_envs.envs.task.layer.TaskCore`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

if TYPE_CHECKING:
    from swarm_envs.config import SwarmConfig
    from swarm_envs.envs.task.layer import Advance, TaskLayer

__all__ = ["Core", "Execution", "StatusCore", "StepResult"]

#: ``(reward (B,) float64, terminated (B,) bool, truncated (B,) bool, stats)``, with
#: ``stats`` mapping each of ``STAT_KEYS`` to a ``(B,)`` array.
StepResult = tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, np.ndarray]]


@runtime_checkable
class Core(Protocol):
    """State and dynamics of ``batch`` SwarmNav swarms (see ``docs/design.md``).

    Attributes:
        cfg: the :class:`~swarm_envs.config.SwarmConfig`.
        batch: number of swarms ``B``.
        dtype: the state's numpy dtype (float32 or float64).
        obs_dim: observation size per agent.
        backend: the backend's name (``"numpy"``, ``"cutoff"``, ``"torch"``, ``"native"``).
        t: steps since each swarm's reset, ``(B,)`` int64 (writable in place).
        x, v: positions and velocities ``(B, N, d)``; goal: ``(B, d)``.
    """

    cfg: SwarmConfig
    batch: int
    dtype: np.dtype
    obs_dim: int

    @property
    def backend(self) -> str: ...

    @property
    def t(self) -> np.ndarray: ...

    @property
    def x(self) -> np.ndarray: ...

    @property
    def v(self) -> np.ndarray: ...

    @property
    def goal(self) -> np.ndarray: ...

    def reset(self, rng: np.random.Generator, which: np.ndarray | None = None) -> None:
        """New starts for the swarms in ``which`` (bool ``(B,)``; all if None), drawn
        from ``rng`` by :func:`~swarm_envs.envs.common.draw_starts`."""
        ...

    def step(self, actions: Any) -> StepResult:
        """Advance every swarm by one step with actions ``(B, N, d)`` in [−1, 1]."""
        ...

    def observe(self, which: np.ndarray | None = None) -> np.ndarray:
        """Observations ``(B, N, obs_dim)`` float32, an array of the caller's own;
        ``which`` (bool ``(B,)``): those swarms' rows only."""
        ...

    def stats(self) -> dict[str, np.ndarray]:
        """The statistics of the current state, ``{name: (B,)}`` (fresh arrays)."""
        ...


@runtime_checkable
class StatusCore(Core, Protocol):
    """A core that takes agent statuses (``backends.STATUS_BACKENDS``): removed, frozen,
    absent and joining agents, and observations with status flags.

    Attributes:
        status: each agent's status ``(B, N)`` int8 (``None`` until first given;
            :mod:`swarm_envs.envs.task.agent_status`).
    """

    status: np.ndarray | None

    def set_status(
        self,
        status: np.ndarray,
        place: np.ndarray | None = None,
        at: np.ndarray | None = None,
        *,
        rows: np.ndarray | None = None,
        start: bool = False,
    ) -> None:
        """Give the agents new statuses ``(B, N)`` between steps.

        ``place`` ``(B, N)`` bool: agents put at ``at`` ``(B, N, d)`` (joining agents).
        Agents that no longer move and placed agents are at rest. The swarms whose
        statuses or places changed, and those in ``rows`` ``(B,)``, are measured again
        with the masks of their new statuses, and their previous statistics become these
        (``start=True``: their episode's start too), so that the next reward compares
        like with like; the other swarms keep theirs.
        """
        ...


class Execution(StatusCore, Protocol):
    """How a backend advances and measures ``batch`` swarms, under its task layer.

    The :class:`~swarm_envs.envs.task.layer.TaskLayer` ``task`` calls these; every
    method leaves the core's observations and statistics describing its current state.
    """

    task: TaskLayer
    t: np.ndarray  # the task layer counts the steps

    def begin(
        self,
        idx: np.ndarray,
        x: np.ndarray,
        v: np.ndarray,
        goal: np.ndarray,
        rng: np.random.Generator,
    ) -> dict[str, np.ndarray]:
        """New starts for the swarms ``idx``: positions and velocities ``(n, N, d)``,
        goals ``(n, d)`` (float64), then the model's own per-swarm state (drawn from
        ``rng`` where it has one); measured, no step taken (``substeps`` 0, no
        ``unstable`` mark). Returns the statistics (the caller only reads them)."""
        ...

    def advance(self, actions: Any) -> Advance:
        """Check ``actions`` ``(B, N, d)`` (``docs/inputs.md``; NaN or inf:
        :class:`ValueError` before anything changes), advance every swarm by ``dt`` and
        measure the new state; the state before the step is kept for :meth:`undo`."""
        ...

    def undo(self, idx: np.ndarray, mark: bool) -> dict[str, np.ndarray]:
        """Put the swarms ``idx`` back to their state before the last step, measured
        with ``substeps`` 0 (``mark``: ``unstable`` 1, kept until their next step or
        reset); returns the statistics, arrays of the caller's own."""
        ...

    def take_statuses(
        self, status: np.ndarray, place: np.ndarray | None, at: np.ndarray | None
    ) -> None:
        """Checked statuses ``(B, N)`` int8 (``status_update``): the agents ``place``
        put at ``at`` ``(B, N, d)``, every agent that does not move or was placed at
        rest, and the statuses' masks applied from now on (no measure yet)."""
        ...

    def remeasure(self, idx: np.ndarray) -> None:
        """Measure the swarms ``idx`` again (their last step's ``substeps`` kept)."""
        ...

    def measured(self) -> Any:
        """The current statistics as the task's records keep them (a core that measures
        replaces this object rather than writing into it)."""
        ...
