"""The batched SwarmNav core in numpy: B swarms of N agents stepped in one array call.

:class:`SwarmNavCore` implements :class:`~swarm_envs.envs.protocol.Core` with dense
``(B, N, N)`` pair arrays, for every model and integrator; it is the reference the other
backends are tested against. It holds state arrays and returns arrays; the PettingZoo,
Gymnasium and SB3 adapters sit on top of it.

One step, for all swarms at once:

1. the action ``a ∈ [−1, 1]^{B×N×d}`` becomes the control ``u = u_max · a``;
2. the model chosen by ``cfg.dynamics`` advances ``(x, v)`` by ``dt`` with its passive
   physics biased by ``u`` (:mod:`swarm_envs.envs.dynamics`); zero action is exactly
   the passive model, and the goal acts passively only if ``goal_in_physics``;
3. the pairwise distances of the new positions are computed once and shared by the
   neighbour ranking, the collision count and the model's next force evaluation;
4. the statistics and the observations follow from the shared definitions of
   :mod:`swarm_envs.envs.task`, as on every backend; the reward, the episode end and the
   unstable guard are the task layer's (:mod:`swarm_envs.envs.task.layer`).
"""

from __future__ import annotations

from typing import Any, TypeGuard

import numpy as np

from swarm_envs._array import NUMPY
from swarm_envs.config import SwarmConfig
from swarm_envs.envs.common import (
    check_actions,
    check_batch,
    check_dtype,
    placed_at_rest,
    wide_dtypes,
)
from swarm_envs.envs.dynamics import make_dynamics
from swarm_envs.envs.task import (
    Frame,
    observation,
    observation_size,
    ranked_neighbors,
    statistics,
)
from swarm_envs.envs.task.agent_status import AgentMasks, masks
from swarm_envs.envs.task.informed import draw_informed
from swarm_envs.envs.task.layer import Advance, HostRecords, TaskCore, TaskLayer
from swarm_envs.physics import PairGeometry, pair_geometry
from swarm_envs.physics.social_potential import present_geometry

__all__ = ["SwarmNavCore", "keeps_rows", "shrink_due"]


def keeps_rows(core: object) -> TypeGuard[SwarmNavCore]:
    """Whether :meth:`SwarmNavCore.keep` can shrink ``core`` to some of its swarms: a
    plain numpy core (not a subclass, which keeps its state otherwise, nor a wrapper)
    whose model steps each swarm on its own state alone (:attr:`Dynamics.KEEPS_ROWS
    <swarm_envs.envs.dynamics.Dynamics.KEEPS_ROWS>`)."""
    return type(core) is SwarmNavCore and bool(core.dynamics.KEEPS_ROWS)


def shrink_due(live: int, rows: int) -> bool:
    """Whether a caller stepping ``rows`` swarms of which ``live`` still matter should
    shrink the core to them with :meth:`SwarmNavCore.keep`: once at most a quarter are
    live. Each shrink copies the state once; waiting for a quarter keeps the copies few
    (at most about a third of the batch's rows in all) while a stalled episode no longer
    keeps every swarm stepping.

    >>> shrink_due(64, 256), shrink_due(65, 256), shrink_due(0, 256)
    (True, False, False)
    """
    return 0 < live and 4 * live <= rows


class SwarmNavCore(TaskCore):
    """State and dynamics of ``batch`` independent SwarmNav swarms (numpy, dense).

    Arrays: positions ``x`` and velocities ``v`` ``(B, N, d)``, goals ``(B, d)``,
    step counters ``(B,)``. All randomness comes from the generator passed to
    :meth:`reset`. An :class:`~swarm_envs.envs.protocol.Execution` under its
    :class:`~swarm_envs.envs.task.layer.TaskLayer` ``task``, which gives it ``reset``,
    ``step`` and ``set_status``.

    >>> from swarm_envs.envs.task import STAT_KEYS
    >>> core = SwarmNavCore(SwarmConfig(n_agents=4), batch=2)
    >>> core.reset(np.random.default_rng(0))
    >>> reward, terminated, truncated, stats = core.step(np.zeros((2, 4, 2)))
    >>> core.observe().shape, reward.shape, list(stats) == list(STAT_KEYS)
    ((2, 4, 34), (2,), True)
    """

    backend = "numpy"

    def __init__(self, cfg: SwarmConfig, batch: int = 1, dtype: Any = np.float64) -> None:
        self.cfg = cfg
        self.batch = check_batch(batch)
        self.dtype = check_dtype(dtype)
        B, N, d = self.batch, cfg.n_agents, cfg.dim
        self.obs_dim = observation_size(cfg)
        self.x = np.zeros((B, N, d), self.dtype)
        self.v = np.zeros((B, N, d), self.dtype)
        self.goal = np.zeros((B, d), self.dtype)
        self.t = np.zeros(B, np.int64)
        self.dynamics = make_dynamics(cfg, self.batch, self.dtype)
        self._wide = wide_dtypes(self.dtype, cfg)
        self._stats = self._empty_stats()
        #: The task above this core: reward, episode end, previous and start statistics.
        self.task = TaskLayer(
            cfg, self.batch, HostRecords(self._empty_stats(), self._empty_stats())
        )
        self._before = (self.x, self.v)  # the state before the last step (for undo)
        self._geometry: PairGeometry | None = None
        self._near: np.ndarray | None = None  # ranked neighbours of the current state
        #: Each agent's status ``(B, N)`` int8 (:mod:`~swarm_envs.envs.task.agent_status`),
        #: ``None`` while every agent is active and always will be.
        self.status: np.ndarray | None = None
        self._members: np.ndarray | None = None
        #: Which agents observe the goal ``(B, N)`` bool (``task="informed"``), else None.
        self.informed: np.ndarray | None = (
            np.ones((B, N), dtype=bool) if cfg.informs_agents else None
        )

    def _empty_stats(self) -> dict[str, np.ndarray]:
        return {key: np.zeros(self.batch, dt) for key, dt in self._wide.items()}

    # ------------------------------------------------------------------ execution
    def begin(
        self,
        idx: np.ndarray,
        x: np.ndarray,
        v: np.ndarray,
        goal: np.ndarray,
        rng: np.random.Generator,
    ) -> dict[str, np.ndarray]:
        """New starts for the swarms ``idx`` (:meth:`Execution.begin
        <swarm_envs.envs.protocol.Execution.begin>`): their informed agents
        (``task="informed"``), then the model's own per-swarm state
        (:mod:`swarm_envs.envs.dynamics`), then the start's statistics."""
        self.x[idx], self.v[idx], self.goal[idx] = x, v, goal
        if self.informed is not None:
            self.informed[idx] = draw_informed(self.cfg, rng, idx.size)
        substeps = self._stats["substeps"].copy()
        substeps[idx] = 0.0  # no step yet; the other swarms keep their last step's
        with np.errstate(over="ignore", invalid="ignore"):
            self._after_reset(idx, rng)
            self._measure(substeps=substeps)
        return self._stats

    def advance(self, actions: Any) -> Advance:
        """One step of every swarm (:meth:`Execution.advance
        <swarm_envs.envs.protocol.Execution.advance>`); ``actions`` ``(B, N, d)`` in
        [−1, 1], validated by :func:`check_actions`."""
        # In the core's dtype, so that every adapter gives bit-identical results.
        a = check_actions(actions, self.x.shape).astype(self.dtype, copy=False)
        self._before = (self.x, self.v)  # a step makes new arrays: these stay the old state
        # Overflow on the way is not reported as it happens: the task layer's guard
        # raises (or truncates) for every swarm whose state stopped being finite.
        with np.errstate(over="ignore", invalid="ignore"):
            self._advance(self.cfg.u_max * a if a.any() else None)
            self._measure(substeps=self.dynamics.substeps)
        effort = np.einsum("bik,bik->b", a, a)
        dynamics = self.dynamics
        return Advance(self.stats(), self._stats, effort, None, dynamics.over_cap, dynamics.needed)

    def undo(self, idx: np.ndarray, mark: bool) -> dict[str, np.ndarray]:
        """The swarms ``idx`` back at their state before the step (:meth:`Execution.undo
        <swarm_envs.envs.protocol.Execution.undo>`)."""
        before = self._before
        self.x[idx], self.v[idx] = before[0][idx], before[1][idx]
        self._restored(idx)
        substeps = self.dynamics.substeps.copy()
        substeps[idx] = 0.0  # the step was undone
        with np.errstate(over="ignore", invalid="ignore"):
            self._measure(substeps=substeps)
        if mark:
            self._stats["unstable"][idx] = 1.0
        return self.stats()

    def keep(self, rows: np.ndarray) -> None:
        """Shrink the batch to the swarms ``rows`` (indices, in their new order), each
        going on as it would have in the whole batch, bit for bit: for a caller that
        needs only some swarms' episodes to go on (evolution strategies' rollouts and
        batched evaluations, once most episodes have ended).

        Raises:
            ValueError: the model does not allow it (:attr:`Dynamics.KEEPS_ROWS
                <swarm_envs.envs.dynamics.Dynamics.KEEPS_ROWS>`), or this core keeps
                its state otherwise (a subclass).
        """
        if not keeps_rows(self):
            raise ValueError(
                f"keep: the {self.cfg.dynamics!r} model on {type(self).__name__} does not "
                "declare that it steps each swarm on its own state alone (Dynamics.KEEPS_ROWS)"
            )
        rows = np.asarray(rows, dtype=np.intp)

        def sub(a: Any) -> Any:
            return None if a is None else a[rows]

        self.x, self.v = self.x[rows], self.v[rows]
        self.goal, self.t = self.goal[rows], self.t[rows]
        self.informed, self.status, self._members = (
            sub(self.informed),
            sub(self.status),
            sub(self._members),
        )
        self._stats = {key: value[rows] for key, value in self._stats.items()}
        self._before = (self._before[0][rows], self._before[1][rows])
        g = self._geometry
        if g is not None:
            self._geometry = PairGeometry([d[rows] for d in g.dx], g.rho[rows])
        self._near = sub(self._near)
        self.dynamics.keep(rows)
        self.task.keep(rows)
        self.batch = len(rows)

    def measured(self) -> dict[str, np.ndarray]:
        """The current statistics ``{name: (B,)}`` (the core's own; a measure replaces them)."""
        return self._stats

    # ------------------------------------------------------------------ physics hooks
    # A subclass with another state representation (the cut-off core for large swarms)
    # overrides these three; the statistics, observations and reward stay shared.
    def _after_reset(self, idx: np.ndarray, rng: np.random.Generator) -> None:
        """Model state for the swarms ``idx`` after their starts were drawn."""
        self.dynamics.reset(self.x, self.v, self.goal, idx, rng)
        self._geometry = self._pair_geometry(self.x)

    def _advance(self, control: np.ndarray | None) -> None:
        """Advance ``x, v`` by one step with the control ``u_max · a`` (None: zero)."""
        goal = self.goal if self.cfg.goal_in_physics else None
        self.x, self.v, geometry = self.dynamics.step(self.x, self.v, goal, control)
        self._geometry = self._pair_geometry(self.x) if geometry is None else geometry

    def _pair_geometry(self, x: np.ndarray) -> PairGeometry:
        """The pair geometry of ``x``, pairs with an agent not present at infinity."""
        return present_geometry(pair_geometry(x), self.dynamics.present)

    # ------------------------------------------------------------------ agents
    def take_statuses(
        self, status: np.ndarray, place: np.ndarray | None, at: np.ndarray | None
    ) -> None:
        """Checked statuses ``(B, N)`` (:meth:`Execution.take_statuses
        <swarm_envs.envs.protocol.Execution.take_statuses>`): the statistics count the
        mobile agents; where ``perturbations.needs_masks``, the physics leaves out the
        agents not present and holds those that do not move."""
        mask = masks(status)
        self.status = status
        self.x, self.v = placed_at_rest(self.x, self.v, mask.mobile, place, at, NUMPY)
        self._members = mask.mobile
        self._take_masks(mask)

    def _take_masks(self, mask: AgentMasks) -> None:
        """The statuses' masks in the physics (``perturbations.needs_masks``)."""
        if self.cfg.perturbations.needs_masks:
            self.dynamics.present, self.dynamics.mobile = mask.present, mask.mobile

    def remeasure(self, idx: np.ndarray) -> None:
        """Measure the swarms ``idx`` again, the others keeping their statistics
        (:meth:`Execution.remeasure <swarm_envs.envs.protocol.Execution.remeasure>`)."""
        self._restored(idx)
        with np.errstate(over="ignore", invalid="ignore"):
            self._measure(substeps=self._stats["substeps"])

    def _restored(self, idx: np.ndarray) -> None:
        """The model's state for the swarms ``idx`` whose ``x, v`` were set."""
        self.dynamics.restore(self.x, self.v, self.goal, idx)
        self._geometry = self._pair_geometry(self.x)

    def _pair_measures(self) -> tuple[np.ndarray | None, np.ndarray, np.ndarray, np.ndarray]:
        """``(ranked neighbours (B, N, k') or None, nearest distance (B, N), close
        pairs (B,), model energy (B,))`` of the current state."""
        cfg = self.cfg
        assert self._geometry is not None
        rho = self._geometry.rho.copy()
        diag = np.arange(cfg.n_agents)
        rho[:, diag, diag] = np.inf
        close_pairs = rho < cfg.collision_radius
        if self._members is not None:  # a pair of agents at rest does not collide
            close_pairs &= self._members[..., :, None] | self._members[..., None, :]
        close = np.count_nonzero(close_pairs, axis=(-2, -1)) // 2
        energy = self.dynamics.measure(self.x, self.v, self.goal, self._geometry)
        if cfg.n_agents == 1:
            return None, np.zeros((self.batch, 1), self.dtype), close, energy
        near = _rank_neighbors(rho, ranked_neighbors(cfg))
        nearest = np.take_along_axis(rho, near[..., :1], axis=-1)[..., 0]
        if self.dynamics.present is not None:  # an agent alone in the physics: 0
            nearest = np.where(np.isfinite(nearest), nearest, 0.0).astype(self.dtype)
        return near, nearest, close, energy

    # ------------------------------------------------------------------ measures
    def _measure(self, substeps: np.ndarray | None = None) -> None:
        """The statistics of the current state (shared definitions); ``substeps`` the
        step's per swarm (``None``: none, after a reset)."""
        near, nearest, close, energy = self._pair_measures()
        self._near = near
        goal_offset = self.goal[:, None, :] - self.x
        frame = Frame(
            self.x,
            self.v,
            self.goal,
            np.sqrt(np.einsum("bik,bik->bi", goal_offset, goal_offset)),
            nearest,
            close,
            energy,
            np.zeros(self.batch) if substeps is None else substeps,
            self._members,
        )
        self._stats = {
            key: np.asarray(value, dtype=self._wide[key]).reshape(self.batch)
            for key, value in statistics(frame, self.cfg, NUMPY).items()
        }

    def stats(self) -> dict[str, np.ndarray]:
        """Group statistics and task measures per swarm, each ``(B,)`` (fresh arrays)."""
        return {key: value.copy() for key, value in self._stats.items()}

    def observe(self, which: np.ndarray | None = None) -> np.ndarray:
        """Local observations ``(B, N, obs_dim)``, float32, inside ``[−OBS_BOUND, OBS_BOUND]``.

        The layout of :mod:`swarm_envs.envs.task.observation`. ``which`` (bool mask
        ``(B,)``): those swarms' observations only, ``(n, N, obs_dim)``. Every call
        returns a new array.
        """
        status, told = self.status, self.informed
        if which is None:
            return observation(self.x, self.v, self.goal, self._near, self.cfg, NUMPY, status, told)
        idx = np.flatnonzero(which)
        near = None if self._near is None else self._near[idx]
        status = None if status is None else status[idx]
        told = None if told is None else told[idx]
        return observation(
            self.x[idx], self.v[idx], self.goal[idx], near, self.cfg, NUMPY, status, told
        )


def _rank_neighbors(rho: np.ndarray, k: int) -> np.ndarray:
    """Indices ``(B, N, k)`` of each agent's ``k`` nearest others, nearest first.

    ``rho`` holds the distances with ``inf`` on the diagonal. The order is ``(ρ_ij, j)``:
    equal distances by the lower index. A full sort of each row is cheaper than a
    partition and a sort for N ≲ 64; above that, partition first. The fast sorts are
    not stable, so the rows with a tie among their first k + 1 are sorted again stably
    (ties are rare: symmetric or coincident agents).
    """
    n = rho.shape[-1]
    m = min(k + 1, n)  # one more, to see a tie at the k-th place
    if n <= 64 or m >= n:
        near = np.argsort(rho, axis=-1)[..., :m]
    else:
        cand = np.argpartition(rho, m - 1, axis=-1)[..., :m]
        order = np.argsort(np.take_along_axis(rho, cand, axis=-1), axis=-1)
        near = np.take_along_axis(cand, order, axis=-1)
    ranked = np.take_along_axis(rho, near, axis=-1)
    tied = (ranked[..., 1:] == ranked[..., :-1]).any(axis=-1)
    if tied.any():
        near = near.copy()
        near[tied] = np.argsort(rho[tied], axis=-1, kind="stable")[..., :m]
    return near[..., :k]
