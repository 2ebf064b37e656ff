"""The interface every SwarmNav core implements: :class:`Core`.

A core holds the state of ``batch`` independent swarms and steps them all at once; the
PettingZoo, Gymnasium and SB3 adapters are written against this protocol only, and
:func:`swarm_envs.envs.backends.make_core` returns one. Arrays in and out are numpy.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np

__all__ = ["Core", "StatusCore", "StepResult"]

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
        backend: the backend's name (``"numpy"``, ``"sparse"``, ``"torch"``, ``"native"``).
        t: steps since each swarm's reset, ``(B,)`` int64 (writable in place).
        x, v: positions and velocities ``(B, N, d)``; goal: ``(B, d)``.
    """

    cfg: Any
    batch: int
    dtype: np.dtype
    obs_dim: int
    backend: str
    t: np.ndarray

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
