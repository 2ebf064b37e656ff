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
4. the statistics, the observations and the reward follow from the shared definitions
   of :mod:`swarm_envs.envs.task`, as on every backend.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from swarm_envs._array import NUMPY
from swarm_envs.config import SwarmConfig
from swarm_envs.envs.common import (
    NON_FINITE_ACTIONS,
    SwarmUnstableError,
    check_action_shape,
    check_actions,
    check_batch,
    check_dtype,
    check_start,
    draw_starts,
    energy_bound,
    unstable_message,
    unstable_swarms,
    wide_dtypes,
)
from swarm_envs.envs.dynamics import make_dynamics
from swarm_envs.envs.stiffness import StiffnessWatch
from swarm_envs.envs.task import (
    OBS_BOUND,
    STAT_KEYS,
    Frame,
    RewardInputs,
    observation,
    observation_size,
    ranked_neighbors,
    reward,
    statistics,
    success_count,
)
from swarm_envs.envs.task.agent_status import keep_measured, masks, status_update
from swarm_envs.envs.task.episode import episode_end
from swarm_envs.envs.task.informed import draw_informed
from swarm_envs.physics import PairGeometry, pair_geometry
from swarm_envs.physics.social_potential import present_geometry

__all__ = [
    "NON_FINITE_ACTIONS",
    "OBS_BOUND",
    "STAT_KEYS",
    "SwarmNavCore",
    "check_action_shape",
    "check_actions",
    "check_batch",
    "draw_starts",
    "observation_size",
    "success_count",
]


class SwarmNavCore:
    """State and dynamics of ``batch`` independent SwarmNav swarms (numpy, dense).

    Arrays: positions ``x`` and velocities ``v`` ``(B, N, d)``, goals ``(B, d)``,
    step counters ``(B,)``. All randomness comes from the generator passed to
    :meth:`reset`.

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
        self._stiffness = StiffnessWatch(cfg, self.batch)
        self._energy_bound = energy_bound(cfg)  # the unstable guard's (common.energy_bound)
        self._wide = wide_dtypes(self.dtype, cfg)
        self._stats = self._empty_stats()
        self._prev = self._empty_stats()  # the previous step's statistics
        self._start = self._empty_stats()  # each episode's first statistics
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

    # ------------------------------------------------------------------ reset
    def reset(self, rng: np.random.Generator, which: np.ndarray | None = None) -> None:
        """Draw new starts for the swarms in ``which`` (bool mask ``(B,)``; all if None).

        The starts of :func:`~swarm_envs.envs.common.draw_starts`; then the model's own
        per-swarm state (:mod:`swarm_envs.envs.dynamics`) and the start's statistics.
        """
        idx = np.arange(self.batch) if which is None else np.flatnonzero(which)
        if idx.size == 0:
            return
        self.x[idx], self.v[idx], self.goal[idx] = draw_starts(self.cfg, rng, idx.size)
        if self.informed is not None:
            self.informed[idx] = draw_informed(self.cfg, rng, idx.size)
        self.t[idx] = 0
        substeps = self._stats["substeps"].copy()
        substeps[idx] = 0.0  # no step yet; the other swarms keep their last step's
        with np.errstate(over="ignore", invalid="ignore"):
            self._after_reset(idx, rng)
            self._measure(substeps=substeps)
        check_start(self.cfg, self._stats, idx, self.dtype)
        for key, value in self._stats.items():
            self._prev[key][idx] = value[idx]
            self._start[key][idx] = value[idx]

    # ------------------------------------------------------------------ step
    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
        """Advance every swarm by one step.

        Args:
            actions: ``(B, N, d)`` in [−1, 1] (validated by :func:`check_actions`).

        Returns:
            ``(reward (B,), terminated (B,), truncated (B,), stats)`` where ``stats``
            maps each of :data:`STAT_KEYS` to a ``(B,)`` array.
        """
        cfg = self.cfg
        # In the core's dtype, so that every adapter gives bit-identical results.
        a = check_actions(actions, self.x.shape).astype(self.dtype, copy=False)
        before = (self.x, self.v)  # a step makes new arrays: these stay the old state
        # Overflow on the way is not reported as it happens: the unstable check below
        # raises (or truncates) for every swarm whose state stopped being finite.
        with np.errstate(over="ignore", invalid="ignore"):
            self._advance(cfg.u_max * a if a.any() else None)
            self.t += 1
            self._measure(substeps=self.dynamics.substeps)
        bad = unstable_swarms(self._stats, self.dynamics.over_cap, self._energy_bound)
        if bad.any():
            self._unstable(bad, before)
        stats = self._stats
        effort = np.einsum("bik,bik->b", a, a)
        inputs = RewardInputs(stats, self._prev, self._start, effort, cfg.n_agents, NUMPY)
        r = np.asarray(reward(cfg.reward, inputs), dtype=np.float64)
        self._prev = {key: value.copy() for key, value in stats.items()}
        terminated, truncated = episode_end(self.cfg, stats["success"], self.t)
        if bad.any():
            r[bad], terminated[bad], truncated[bad] = 0.0, False, True
        self._stiffness.observe(stats)
        return r, terminated, truncated, self.stats()

    def _unstable(self, bad: np.ndarray, before: tuple[np.ndarray, np.ndarray]) -> None:
        """Put the swarms ``bad`` back to their state before the step; then raise
        :class:`SwarmUnstableError` (the core stays at the last sound state, as before
        the step), or (``on_unstable="truncate"``) mark them ``unstable``."""
        cfg = self.cfg
        message = unstable_message(cfg, self._stats, bad, self.dynamics.needed, self.t)
        idx = np.flatnonzero(bad)
        self.x[idx], self.v[idx] = before[0][idx], before[1][idx]
        self.dynamics.restore(self.x, self.v, self.goal, idx)
        self._geometry = self._pair_geometry(self.x)
        substeps = self.dynamics.substeps.copy()
        substeps[idx] = 0.0  # the step was undone
        with np.errstate(over="ignore", invalid="ignore"):
            self._measure(substeps=substeps)
        if cfg.on_unstable == "raise":
            raise SwarmUnstableError(message)
        self._stats["unstable"][idx] = 1.0

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
        """
        shape = (self.batch, self.cfg.n_agents, self.cfg.dim)
        status, place, rows = status_update(self.status, status, place, at, rows, shape)
        if place is not None:
            self.x = np.where(place[..., None], at, self.x).astype(self.dtype, copy=False)
        self.status = status
        mask = masks(self.status)
        self.v = np.where(mask.mobile[..., None], self.v, 0.0).astype(self.dtype, copy=False)
        if place is not None:
            self.v[place] = 0.0
        self._members = mask.mobile
        if self.cfg.perturbations.needs_masks:
            self.dynamics.present, self.dynamics.mobile = mask.present, mask.mobile
        if not rows.any():
            return
        idx = np.flatnonzero(rows)
        self.dynamics.restore(self.x, self.v, self.goal, idx)
        self._geometry = self._pair_geometry(self.x)
        before = self._stats
        with np.errstate(over="ignore", invalid="ignore"):
            self._measure(substeps=before["substeps"])
        keep_measured(self._stats, before, self._prev, self._start, rows, start)

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
