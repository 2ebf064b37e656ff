"""The batched SwarmNav core: B swarms of N agents stepped in one array call.

Every API of the package is a thin adapter over :class:`SwarmNavCore`: the PettingZoo
``ParallelEnv`` (B = 1, a dict per agent), the Gymnasium env (B = 1, one flat vector)
and the SB3 ``VecEnv`` (B swarms, one slot per agent). The core knows nothing of
those APIs; it holds state arrays and returns arrays.

One step, for all swarms at once:

1. the action ``a ∈ [−1, 1]^{B×N×d}`` becomes the control ``u = u_max · a``;
2. the model chosen by ``cfg.dynamics`` advances ``(x, v)`` by ``dt`` with its passive
   physics biased by ``u`` (a force for the social potential and piecewise models, a
   bias of the desired direction for the zone model, a velocity for the Lagrangian
   model: :mod:`swarm_envs.envs.dynamics`); zero action is exactly the passive model,
   and the goal acts passively only if ``goal_in_physics``;
3. pairwise distances of the new positions are computed once and shared by the
   observations (k nearest neighbours), the collision count, the nearest-neighbour
   statistic and the next step's forces;
4. reward, termination and statistics are computed per swarm.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from swarm_envs import metrics
from swarm_envs._malloc import keep_freed_memory
from swarm_envs.config import SwarmConfig
from swarm_envs.envs.dynamics import make_dynamics
from swarm_envs.physics import PairGeometry, pair_geometry, uniform_ball

#: Every observation component is clipped into ``[−OBS_BOUND, OBS_BOUND]``.
OBS_BOUND = 10.0

#: Statistics reported per swarm in ``info`` (and by :meth:`SwarmNavCore.stats`).
STAT_KEYS = (
    "polarization",
    "angular_momentum",
    "expanse",
    "nearest_neighbor_distance",
    "energy",
    "fraction_arrived",
    "collisions",
    "centroid_distance",
    "mean_goal_distance",
    "success",
)


def success_count(n_agents: int, success_fraction: float) -> int:
    """Smallest count c of arrived agents with ``c/N ≥ success_fraction − 1e-9``.

    The success test of :meth:`SwarmNavCore.stats` as a count, for the batched cores
    that count arrivals (``N + 1`` if no count reaches it, which ``success_fraction ≤ 1``
    rules out).
    """
    for c in range(n_agents + 1):
        if c / n_agents >= success_fraction - 1e-9:
            return c
    return n_agents + 1  # pragma: no cover - success_fraction ≤ 1 always reaches c = N


def observation_size(cfg: SwarmConfig) -> int:
    """``2d + k (2d + 1)``: goal offset, own velocity, k × (offset, velocity, mask)."""
    d = cfg.dim
    return 2 * d + cfg.n_neighbors * (2 * d + 1)


#: The error message for NaN or infinite actions (every core and the C step raise it).
NON_FINITE_ACTIONS = "actions must be finite (got NaN or inf); allowed range [-1, 1]"


def check_action_shape(actions: Any, shape: tuple[int, ...]) -> np.ndarray:
    """Actions as a numeric array of exactly ``shape`` (a same-size array of another
    rank is reshaped); a non-numeric dtype or another size → :class:`ValueError`."""
    a = np.asarray(actions)
    if a.dtype == object or not (
        np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)
    ):
        raise ValueError(f"actions must be a numeric array of shape {shape}, got dtype {a.dtype}")
    if a.shape != shape:
        if a.size == int(np.prod(shape)) and a.ndim != len(shape):
            a = a.reshape(shape)
        else:
            raise ValueError(f"actions must have shape {shape}, got {a.shape}")
    return a


def check_actions(actions: Any, shape: tuple[int, ...]) -> np.ndarray:
    """Actions as a float array of exactly ``shape``; NaN/inf or wrong shape → ValueError.

    Finite values outside [−1, 1] are clipped (the Box convention of SB3 and RLlib).
    """
    a = check_action_shape(actions, shape)
    if not np.isfinite(a).all():
        raise ValueError(NON_FINITE_ACTIONS)
    return np.clip(a, -1.0, 1.0)


def check_batch(batch: Any) -> int:
    """The number of swarms of a core: an integer ``≥ 1``, else :class:`ValueError`."""
    if isinstance(batch, bool) or not isinstance(batch, (int, np.integer)) or batch < 1:
        raise ValueError(f"batch must be an integer >= 1, got {batch!r}")
    return int(batch)


def require_social_potential(cfg: SwarmConfig, owner: str) -> None:
    """Raise :class:`ValueError` unless ``cfg`` runs the social potential model."""
    if cfg.dynamics != "social_potential":
        raise ValueError(
            f"{owner} supports dynamics='social_potential' only, got {cfg.dynamics!r} "
            "(use SwarmNavCore, the numpy core, for the other models)"
        )


def draw_starts(
    cfg: SwarmConfig, rng: np.random.Generator, n: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` new starts ``(x (n, N, d), v (n, N, d), goal (n, d))``, float64.

    Agents uniform in a disc (ball) of ``init_radius`` around the origin, velocities
    uniform in a disc of ``init_speed``; the goal at a uniform random bearing and a
    distance uniform in ``[goal_distance_min, goal_distance_max]``. Every core draws
    its starts here, so a seed gives the same starts on every backend.
    """
    N, d = cfg.n_agents, cfg.dim
    x = uniform_ball(rng, (n, N, d), cfg.init_radius)
    v = uniform_ball(rng, (n, N, d), cfg.init_speed)
    bearing = rng.standard_normal((n, d))
    bearing /= np.maximum(np.linalg.norm(bearing, axis=-1, keepdims=True), 1e-12)
    dist = rng.uniform(cfg.goal_distance_min, cfg.goal_distance_max, size=(n, 1))
    return x, v, bearing * dist


class SwarmNavCore:
    """State and dynamics of ``batch`` independent SwarmNav swarms.

    Arrays: positions ``x`` and velocities ``v`` ``(B, N, d)``, goals ``(B, d)``,
    step counters ``(B,)``. All randomness comes from the generator passed to
    :meth:`reset`.
    """

    def __init__(self, cfg: SwarmConfig, batch: int = 1, dtype: type = np.float64) -> None:
        keep_freed_memory()  # per-step temporaries stay in the heap (see swarm_envs._malloc)
        self.cfg = cfg
        self.batch = check_batch(batch)
        self.dtype = np.dtype(dtype)
        B, N, d = self.batch, cfg.n_agents, cfg.dim
        self.obs_dim = observation_size(cfg)
        self.x = np.zeros((B, N, d), self.dtype)
        self.v = np.zeros((B, N, d), self.dtype)
        self.goal = np.zeros((B, d), self.dtype)
        self.t = np.zeros(B, np.int64)
        self.start_distance = np.ones(B, self.dtype)
        self.prev_distance = np.ones(B, self.dtype)
        self.prev_arrived = np.zeros(B, self.dtype)
        self.dynamics = make_dynamics(cfg, self.batch, self.dtype)
        self._geometry: PairGeometry | None = None
        self._masked: tuple[Any, np.ndarray] | None = None
        self._nbr: tuple[Any, np.ndarray] | None = None
        self._neighbor_scale = np.array(
            [1.0 / cfg.obs_neighbor_scale] * d + [1.0 / cfg.obs_velocity_scale] * d, self.dtype
        )

    # ------------------------------------------------------------------ reset
    def reset(self, rng: np.random.Generator, which: np.ndarray | None = None) -> None:
        """Draw new starts for the swarms in ``which`` (bool mask ``(B,)``; all if None).

        Agents uniform in a disc (ball) of ``init_radius`` around the origin, velocities
        uniform in a disc of ``init_speed``; the goal at a uniform random bearing and a
        distance uniform in ``[goal_distance_min, goal_distance_max]``.
        """
        cfg = self.cfg
        idx = np.arange(self.batch) if which is None else np.flatnonzero(which)
        if idx.size == 0:
            return
        self.x[idx], self.v[idx], self.goal[idx] = draw_starts(cfg, rng, idx.size)
        self.t[idx] = 0
        self._after_reset(idx, rng)
        mean_dist = self._goal_distances().mean(axis=-1)
        self.start_distance[idx] = np.maximum(mean_dist[idx], 1e-6)
        self.prev_distance[idx] = mean_dist[idx]
        self.prev_arrived[idx] = self._arrived_fraction()[idx]

    # ------------------------------------------------------------------ step
    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
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
        self._advance(cfg.u_max * a if a.any() else None)
        self.t += 1

        stats = self.stats()
        distance = stats["mean_goal_distance"]
        arrived = stats["fraction_arrived"]
        success = stats["success"].astype(bool)
        w = cfg.reward
        reward = (
            w.progress * (self.prev_distance - distance) / self.start_distance
            + w.arrival * (arrived - self.prev_arrived)
            + w.success * success
            - w.collision * stats["collisions"] / cfg.n_agents
            - w.effort * np.einsum("bik,bik->b", a, a) / cfg.n_agents
            - w.time
        )
        # Copies: reset(which) writes into these in place, and the returned statistics
        # must keep this step's values.
        self.prev_distance = distance.copy()
        self.prev_arrived = arrived.copy()
        truncated = (self.t >= cfg.max_steps) & ~success
        return reward, success, truncated, stats

    # ------------------------------------------------------------------ physics hooks
    # A subclass with another state representation (the cut-off core for large swarms)
    # overrides these three and :meth:`_nearest`; reset draws, reward, statistics and
    # observations stay shared.
    def _after_reset(self, idx: np.ndarray, rng: np.random.Generator) -> None:
        """Model state for the swarms ``idx`` after their starts were drawn."""
        self.dynamics.reset(self.x, self.v, self.goal, idx, rng)
        self._geometry = pair_geometry(self.x)

    def _advance(self, control: np.ndarray | None) -> None:
        """Advance ``x, v`` by one step with the control ``u_max · a`` (None: zero)."""
        goal = self.goal if self.cfg.goal_in_physics else None
        self.x, self.v, geometry = self.dynamics.step(self.x, self.v, goal, control, self._geometry)
        self._geometry = pair_geometry(self.x) if geometry is None else geometry

    def _pair_stats(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(nearest-neighbour distance, colliding pairs, model energy)``, each ``(B,)``."""
        cfg = self.cfg
        rho = self._distances()
        if cfg.n_agents > 1:  # distance to the nearest neighbour, from the shared sort
            nnd = np.take_along_axis(rho, self._nearest()[..., :1], axis=-1)[..., 0].mean(axis=-1)
        else:
            nnd = np.zeros(self.batch)
        collisions = np.count_nonzero(rho < cfg.collision_radius, axis=(-2, -1)) // 2
        energy = self.dynamics.energy(self.x, self.v, self.goal, self._geometry)
        return nnd, collisions.astype(np.float64), energy

    # ------------------------------------------------------------------ views
    def _goal_distances(self) -> np.ndarray:
        return np.linalg.norm(self.goal[:, None, :] - self.x, axis=-1)

    def _arrived_fraction(self) -> np.ndarray:
        return (self._goal_distances() <= self.cfg.goal_radius).mean(axis=-1)

    def _distances(self) -> np.ndarray:
        """Pairwise distances ``(B, N, N)`` with ``inf`` on the diagonal (cached per state).

        Read-only for callers: it is shared by the observations and the statistics.
        """
        assert self._geometry is not None
        if self._masked is None or self._masked[0] is not self._geometry:
            rho = self._geometry.rho.copy()
            diag = np.arange(self.cfg.n_agents)
            rho[:, diag, diag] = np.inf
            self._masked = (self._geometry, rho)
        return self._masked[1]

    def stats(self) -> dict[str, np.ndarray]:
        """Group statistics and task measures per swarm, each ``(B,)``."""
        cfg = self.cfg
        goal_dist = self._goal_distances()
        arrived = (goal_dist <= cfg.goal_radius).mean(axis=-1)
        nnd, collisions, energy = self._pair_stats()
        centroid = self.x.mean(axis=-2)
        return {
            "polarization": metrics.polarization(self.v),
            "angular_momentum": metrics.angular_momentum(self.x, self.v),
            "expanse": metrics.expanse(self.x),
            "nearest_neighbor_distance": nnd,
            "energy": energy,
            "fraction_arrived": arrived,
            "collisions": collisions,
            "centroid_distance": np.linalg.norm(centroid - self.goal, axis=-1),
            "mean_goal_distance": goal_dist.mean(axis=-1),
            "success": (arrived >= cfg.success_fraction - 1e-9).astype(np.float64),
        }

    def observe(self, which: np.ndarray | None = None) -> np.ndarray:
        """Local observations ``(B, N, obs_dim)``, float32, inside ``[−OBS_BOUND, OBS_BOUND]``.

        Per agent i: ``(r_g − r_i)/obs_goal_scale`` (d), ``v_i/obs_velocity_scale`` (d),
        then for each of the k nearest neighbours j, nearest first:
        ``(r_j − r_i)/obs_neighbor_scale`` (d), ``(v_j − v_i)/obs_velocity_scale`` (d)
        and a mask (1 = real neighbour, 0 = padding when N − 1 < k; padded slots are 0).
        ``which`` (bool mask ``(B,)``): those swarms' observations only, ``(n, N,
        obs_dim)``. Every call returns a new array.
        """
        if which is not None:
            return self.observe()[np.flatnonzero(which)]
        cfg = self.cfg
        B, N, d = self.x.shape
        k = cfg.n_neighbors
        obs = np.empty((B, N, self.obs_dim), np.float32)
        obs[..., :d] = (self.goal[:, None, :] - self.x) / cfg.obs_goal_scale
        obs[..., d : 2 * d] = self.v / cfg.obs_velocity_scale
        if k > 0:
            nb = obs[..., 2 * d :].reshape(B, N, k, 2 * d + 1)  # a view into obs
            nb[...] = 0.0
            k_real = min(k, N - 1)
            if k_real > 0:
                nbr = self._nearest()[..., :k_real]  # (B, N, k_real), nearest first
                flat = (nbr + (np.arange(B) * N)[:, None, None]).reshape(-1)
                xv = np.concatenate([self.x, self.v], axis=-1).reshape(B * N, 2 * d)
                rel = np.take(xv, flat, axis=0).reshape(B, N, k_real, 2 * d)
                rel -= xv.reshape(B, N, 1, 2 * d)
                rel *= self._neighbor_scale  # 1/obs_neighbor_scale (d), 1/obs_velocity_scale (d)
                nb[:, :, :k_real, : 2 * d] = rel
                nb[:, :, :k_real, 2 * d] = 1.0
        np.clip(obs, -OBS_BOUND, OBS_BOUND, out=obs)
        return obs

    def _nearest(self) -> np.ndarray:
        """Indices ``(B, N, k)`` of each agent's nearest other agents, nearest first.

        ``k = min(max(n_neighbors, 1), N − 1)``: the observation's neighbours and, in
        column 0, the nearest neighbour for the NND statistic. Cached per state. A full
        argsort of each row is faster than ``argpartition`` + sort for N ≲ 64; above
        that, partition first. Ties break deterministically (same input, same order).
        """
        assert self._geometry is not None and self.cfg.n_agents > 1
        if self._nbr is not None and self._nbr[0] is self._geometry:
            return self._nbr[1]
        rho = self._distances()
        n = rho.shape[-1]
        k = min(max(self.cfg.n_neighbors, 1), n - 1)
        if n <= 64 or k >= n - 1:
            nbr = np.argsort(rho, axis=-1)[..., :k]
        else:
            cand = np.argpartition(rho, k - 1, axis=-1)[..., :k]
            order = np.argsort(np.take_along_axis(rho, cand, axis=-1), axis=-1)
            nbr = np.take_along_axis(cand, order, axis=-1)
        self._nbr = (self._geometry, nbr)
        return nbr
