"""SwarmNav for large swarms: the batched core with a cut-off and an O(N) neighbour search.

:class:`SparseSwarmNavCore` has exactly the public interface and semantics of
:class:`~swarm_envs.envs.core.SwarmNavCore` (``reset``, ``step``, ``observe``,
``stats``; attributes ``x, v, goal, t, batch, obs_dim, cfg``) for
``cfg.dynamics == "social_potential"`` (either integrator), without any ``(B, N, N)``
array. One step:

1. the action becomes the control force ``u = u_max · a``, added to the passive force
   carried from the previous step (the passive force at the current state, or for
   velocity Verlet at its extrapolated velocity, exactly as the dense core);
2. the integrator advances ``(x, v)`` by ``dt`` (semi-implicit Euler or velocity
   Verlet, the formulas of :mod:`swarm_envs.physics.integrators`);
3. one cell-list search (:class:`swarm_envs.physics.neighbors.CellList`) finds every
   pair within ``max(r_c, collision_radius)`` of the new positions, chunk by chunk, and
   the same pass over those pairs gives the next passive force, the pair potential of
   the ``energy`` statistic and the collision count (the agents are taken in cell
   order, so the pairs' memory accesses stay local). Where numba imports, that pass is
   one compiled loop over the cell pairs
   (:func:`swarm_envs.physics.compiled_pairs.cell_pair_sums`, each candidate visited
   once); otherwise numpy sums chunks of candidates
   (:class:`swarm_envs.physics.cutoff.PairAccumulator`). Both apply the one pair law,
   :func:`swarm_envs.physics.social_potential.pair_law` (``docs/models.md`` §1), and
   give the same sums to round-off; ``SWARM_ENVS_NUMBA=0`` picks numpy;
4. the k nearest neighbours (observations, nearest-neighbour distance) come from the
   same cell-list structure (:func:`swarm_envs.physics.neighbors.knn`), on demand and
   cached per state; the search starts at the previous step's neighbour distances
   (each round compiled with numba where it imports).
   From :data:`KNN_AHEAD_MIN_AGENTS` agents it starts in a worker thread as soon as
   the positions are known, and runs while step 3 does.

What differs from the dense core is the cut-off only: pair terms (Morse cohesion,
alignment; docs/models.md §1 eqs. 9–11) of agents farther apart than
``r_c = cutoff_radius(cfg.physics, cutoff_tol, speed=cutoff_speed)`` are dropped, each
smaller than ``cutoff_tol`` (force units) for relative speeds up to ``cutoff_speed``.
The per-agent bound is :func:`swarm_envs.physics.cutoff.force_error_bound`:
``(N − 1) g(r_c; w)`` always, ``n Σ_t A_t Φ_d(r_c, l_t)`` at density ``n``. The
``energy`` statistic drops the same pairs
(:func:`~swarm_envs.physics.cutoff.energy_error_bound`). Observations, collisions and
the nearest-neighbour distance are exact. A state that is no longer finite raises
:class:`ValueError` in :meth:`~SparseSwarmNavCore.step` (the dense core would carry NaN).

The defaults, ``cutoff_tol = 0.03`` (1 % of the default action bound ``u_max = 3``) and
``cutoff_speed = 1``, give ``r_c ≈ 5.08`` with the navigation parameters. What they cost
in accuracy, measured at 2,000 agents at the default start density
(``benchmarks/large_swarms.py --accuracy 2000``): per-agent force errors of median
0.1–0.3 and maximum 0.6–1.3 in the first 20 steps, mostly the alignment drag of agents
beyond ``r_c`` (:mod:`swarm_envs.physics.cutoff`); the bound holds with a factor of
about 10 to spare. ``cutoff_tol = 0.01`` (``r_c ≈ 6.59``) divides the errors by about
2.5, ``0.003`` (``r_c ≈ 8.31``) by about 7.

Cost is ``O(N)`` per step at bounded density: the cell list and the pair pass visit,
per agent, a number of candidates proportional to its pairs within ``r_c``, about
``n ω_d r_c^d`` at density ``n`` (``ω_2 = π``, ``ω_3 = 4π/3``), so a larger ``r_c``
costs as ``r_c^d``. The paper's parameters are in the collapsing regime (``C l² < 1``,
``SocialPotentialParams.h_stability``): a swarm left to itself contracts, its density
and the number of pairs within ``r_c`` grow over an episode, and the stiffening
repulsion eventually makes the explicit integration unstable (agents at speeds of
20–50): with 2,000 agents at rest after about 50 steps of ``dt = 0.1`` (about 700 of
``dt = 0.02``), in both cores.
Large-N scenarios should start at the density of the default ``N = 10`` case:
:func:`density_preserving_radius` scales ``init_radius`` with ``N^{1/d}`` (``√N`` in
2-D, ``∛N`` in 3-D); with the default radius, 100,000 agents would start ``10^4``
times denser.

Below :data:`SPARSE_MIN_AGENTS` agents per swarm the dense core (``O(N²)`` per step) is
as fast or faster (and exact); above it this one is faster, increasingly so
(``benchmarks/large_swarms.py`` measures the crossover on a given machine, with the
compiled or the numpy pair pass). :func:`use_sparse_core` is the selection rule.
"""

from __future__ import annotations

import os
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

import numpy as np

from swarm_envs.config import SwarmConfig
from swarm_envs.envs.core import SwarmNavCore
from swarm_envs.physics import compiled_pairs, goal_force, goal_potential, kinetic_energy
from swarm_envs.physics._validation import check_real
from swarm_envs.physics.cutoff import PairAccumulator, cutoff_radius
from swarm_envs.physics.integrators import euler_update
from swarm_envs.physics.neighbors import CELL_MARGIN, REACH, CellList, knn

#: Agents per swarm from which to use :class:`SparseSwarmNavCore`: above the crossover
#: with the dense cores that ``benchmarks/large_swarms.py`` measures (default config at
#: the start density of N = 10), with a margin.
SPARSE_MIN_AGENTS = 500

#: From this many agents in a core (B·N), the k-nearest-neighbour search of a new state
#: runs in a worker thread while the pair pass runs in the caller's (numpy releases the
#: GIL in its array loops), on machines with more than one core.
KNN_AHEAD_MIN_AGENTS = 4000

_KNN_WORKERS: list[ThreadPoolExecutor] = []  # one pool, made on first use


def _knn_workers() -> ThreadPoolExecutor:
    """The process's pool for the look-ahead neighbour searches (one thread per CPU)."""
    if not _KNN_WORKERS:
        workers = max(1, os.cpu_count() or 1)
        _KNN_WORKERS.append(ThreadPoolExecutor(workers, thread_name_prefix="swarm_envs-knn"))
    return _KNN_WORKERS[0]


#: Default tolerance per dropped pair force (force units): 1 % of the default ``u_max``.
DEFAULT_CUTOFF_TOL = 0.03

#: Default relative speed up to which the alignment term's tolerance holds.
DEFAULT_CUTOFF_SPEED = 1.0

__all__ = [
    "DEFAULT_CUTOFF_SPEED",
    "DEFAULT_CUTOFF_TOL",
    "KNN_AHEAD_MIN_AGENTS",
    "SPARSE_MIN_AGENTS",
    "SparseSwarmNavCore",
    "density_preserving_radius",
    "use_sparse_core",
]


def use_sparse_core(cfg: SwarmConfig) -> bool:
    """Whether ``cfg`` should run on :class:`SparseSwarmNavCore` rather than the dense core.

    True for the social potential model with at least :data:`SPARSE_MIN_AGENTS` agents.

    >>> use_sparse_core(SwarmConfig()), use_sparse_core(SwarmConfig(n_agents=100_000))
    (False, True)
    """
    dynamics = getattr(cfg, "dynamics", "social_potential")
    return dynamics == "social_potential" and cfg.n_agents >= SPARSE_MIN_AGENTS


def density_preserving_radius(
    n_agents: int, dim: int = 2, *, radius: float = 1.5, agents: int = 10
) -> float:
    """``init_radius`` that starts ``n_agents`` at the density of ``agents`` in ``radius``.

    ``R = radius · (n_agents / agents)^{1/d}``: the default start (10 agents in a disc of
    radius 1.5, 1.41 agents per unit area) scaled to ``N`` agents. With the default
    radius, 100,000 agents would start ``10^4`` times denser, with thousands of
    neighbours within the cut-off each.

    >>> round(density_preserving_radius(100_000), 1)
    150.0
    >>> round(density_preserving_radius(1000, dim=3), 3)
    6.962
    """
    if isinstance(n_agents, bool) or not isinstance(n_agents, (int, np.integer)) or n_agents < 1:
        raise ValueError(f"n_agents must be an integer >= 1, got {n_agents!r}")
    if dim not in (2, 3) or isinstance(dim, bool):
        raise ValueError(f"dim must be 2 or 3, got {dim!r}")
    if isinstance(agents, bool) or not isinstance(agents, (int, np.integer)) or agents < 1:
        raise ValueError(f"agents must be an integer >= 1, got {agents!r}")
    radius = check_real("density_preserving_radius", "radius", radius, low=0.0)
    return radius * (n_agents / agents) ** (1.0 / dim)


class SparseSwarmNavCore(SwarmNavCore):
    """State and dynamics of ``batch`` independent SwarmNav swarms, for large ``N``.

    A drop-in for :class:`~swarm_envs.envs.core.SwarmNavCore` (same methods, same
    random draws, same results up to the cut-off; see the module docstring). It
    overrides only the physics hooks (``_after_reset``, ``_advance`` and
    ``_pair_measures``); the reset draws, the reward, the statistics and the
    observations are the dense core's.

    Args:
        cfg: the scenario; ``cfg.dynamics`` must be ``"social_potential"``.
        batch: number of swarms ``B ≥ 1``.
        dtype: the state's precision (``np.float64`` or ``np.float32``).
        cutoff_tol: tolerance per dropped pair force, ``> 0`` (force units).
        cutoff_speed: relative speed up to which ``cutoff_tol`` covers the alignment
            term, ``≥ 0``.

    Attributes:
        cutoff: the cut-off radius ``r_c`` (from ``cfg.physics``, ``cutoff_tol`` and
            ``cutoff_speed``; recomputed if ``cfg`` is replaced).

    >>> from swarm_envs.config import SwarmConfig
    >>> from swarm_envs.envs.core import STAT_KEYS
    >>> core = SparseSwarmNavCore(SwarmConfig(n_agents=4), batch=2)
    >>> core.reset(np.random.default_rng(0))
    >>> reward, terminated, truncated, stats = core.step(np.zeros((2, 4, 2)))
    >>> core.observe().shape, reward.shape, sorted(stats) == sorted(STAT_KEYS)
    ((2, 4, 34), (2,), True)
    """

    backend = "sparse"

    def __init__(
        self,
        cfg: SwarmConfig,
        batch: int = 1,
        dtype: type = np.float64,
        cutoff_tol: float = DEFAULT_CUTOFF_TOL,
        cutoff_speed: float = DEFAULT_CUTOFF_SPEED,
    ) -> None:
        reason = self.unsupported(cfg)
        if reason is not None:
            raise ValueError(f"SparseSwarmNavCore: {reason}")
        super().__init__(cfg, batch, dtype)
        self.cutoff_tol = check_real(
            "SparseSwarmNavCore", "cutoff_tol", cutoff_tol, low=0.0, low_inclusive=False
        )
        self.cutoff_speed = check_real("SparseSwarmNavCore", "cutoff_speed", cutoff_speed, low=0.0)
        B = self.batch
        self._cutoff_key: tuple[Any, ...] | None = None
        self._cutoff = 0.0
        self._f_passive: np.ndarray | None = None  # passive force carried to the next step
        self._potential = np.zeros(B)  # Σ U over the pairs within the cut-off, per swarm
        self._collisions = np.zeros(B)
        self._state = 0  # bumped whenever x, v change; keys the neighbour cache
        self._knn_cache: tuple[int, np.ndarray, np.ndarray] | None = None
        self._knn_radius: float | None = None
        self._knn_pending: tuple[int, Future] | None = None

    @staticmethod
    def unsupported(cfg: SwarmConfig) -> str | None:
        """Why this core cannot run ``cfg`` (``None`` if it can): the social potential
        model only, either integrator."""
        if cfg.dynamics != "social_potential":
            return f"supports dynamics='social_potential' only, got {cfg.dynamics!r}"
        return None

    def __getstate__(self) -> dict[str, Any]:
        """The core without its look-ahead search in flight (a thread's future)."""
        state = self.__dict__.copy()
        state["_knn_pending"] = None  # searched again on demand
        return state

    def _start_knn(self) -> None:
        """Search the k nearest neighbours of ``self.x`` in a worker thread, meanwhile."""
        k = max(self.cfg.n_neighbors, 1)
        future = _knn_workers().submit(knn, self.x, k, radius=self._knn_radius)
        self._knn_pending = (self._state, future)

    # ------------------------------------------------------------------ cut-off
    @property
    def cutoff(self) -> float:
        """The cut-off radius ``r_c`` of the pair terms (see the module docstring)."""
        key = (self.cfg.physics, self.cutoff_tol, self.cutoff_speed)
        if key != self._cutoff_key:
            self._cutoff = cutoff_radius(self.cfg.physics, self.cutoff_tol, speed=self.cutoff_speed)
            self._cutoff_key = key
        return self._cutoff

    def _physics_goal(self) -> np.ndarray | None:
        cfg = self.cfg
        return self.goal if cfg.goal_in_physics and cfg.physics.C_g > 0 else None

    def _passive(self, velocity: np.ndarray) -> np.ndarray:
        """Passive force at ``self.x`` with ``velocity``; refreshes the pair statistics.

        One cell-list search within ``max(r_c, collision_radius)`` and one pass over
        its pairs (agents in cell order): the pair forces (eqs. 10–11), the pair
        potential (eq. 9) and the collision count; then ``−β v`` (eq. 12) and the goal
        sink (eqs. 19–21) when it acts passively.
        """
        cfg, p = self.cfg, self.cfg.physics
        B, N, d = self.x.shape
        radius = max(self.cutoff, cfg.collision_radius)
        force = np.zeros((B * N, d), self.dtype)
        self._potential = np.zeros(B)
        self._collisions = np.zeros(B)
        if B * N >= KNN_AHEAD_MIN_AGENTS:
            self._start_knn()  # the observation's search, while the pairs are summed
        if radius > 0 and N > 1:
            cells = CellList.build(self.x, radius * (1.0 + CELL_MARGIN) / REACH, REACH)
            order = cells.order
            vel = velocity.reshape(B * N, d)[order]
            groups = order // N if B > 1 else None
            if compiled_pairs.numba_enabled():  # one compiled loop over the cell pairs
                sums = compiled_pairs.cell_pair_sums(
                    cells,
                    radius,
                    p,
                    vel,
                    groups=groups,
                    n_groups=B,
                    close_radius=cfg.collision_radius,
                )
            else:
                acc = PairAccumulator(
                    p,
                    B * N,
                    vel,
                    groups=groups,
                    n_groups=B,
                    potential=True,
                    close_radius=cfg.collision_radius,
                )
                for chunk in cells.iter_pairs(radius):
                    acc.add(*chunk)
                sums = acc.result(d, self.dtype)
            force[order] = sums.force
            self._potential = sums.potential
            self._collisions = sums.close.astype(np.float64)
        force = force.reshape(B, N, d)
        if p.beta > 0:
            force -= p.beta * velocity
        goal = self._physics_goal()
        if goal is not None:
            force += goal_force(self.x, p, goal)
        return force

    # ------------------------------------------------------------------ physics hooks
    def _after_reset(self, idx: np.ndarray, rng: np.random.Generator) -> None:
        self._state += 1
        f = self._passive(self.v)
        if self._f_passive is None or self.cfg.integrator != "velocity_verlet":
            self._f_passive = f
        else:  # Verlet keeps the other swarms' carried force (as the dense core does)
            self._f_passive[idx] = f[idx]

    def _advance(self, control: np.ndarray | None) -> None:
        cfg = self.cfg
        if self._f_passive is None:
            raise ValueError("SparseSwarmNavCore.step called before reset")
        m, dt = cfg.physics.m, cfg.dt
        accel = self._f_passive if control is None else self._f_passive + control
        if cfg.integrator == "velocity_verlet":
            # Kick–drift–kick with the force at the extrapolated velocity 2v_{n+½} − v_n
            # (swarm_envs.physics.integrators.verlet_step).
            v_half = self.v + (0.5 * dt / m) * accel
            self.x = self.x + dt * v_half
            self._state += 1
            self._f_passive = self._passive(2.0 * v_half - self.v)
            accel = self._f_passive if control is None else self._f_passive + control
            self.v = v_half + (0.5 * dt / m) * accel
        else:
            # Semi-implicit Euler (swarm_envs.physics.integrators.euler_update).
            self.x, self.v = euler_update(self.x, self.v, accel, dt, m)
            self._state += 1
            self._f_passive = self._passive(self.v)
        if not (np.isfinite(self.x).all() and np.isfinite(self.v).all()):
            raise ValueError(
                "SparseSwarmNavCore: the state is no longer finite (the explicit "
                "integration diverged); use a smaller dt or stable parameters"
            )

    def _knn(self) -> tuple[np.ndarray, np.ndarray]:
        """Indices and distances ``(B, N, k)`` of each agent's nearest others, nearest first.

        ``k = min(max(n_neighbors, 1), N − 1)``: the observation's neighbours and, in
        column 0, the nearest neighbour for the NND statistic. Cached per state; the
        search starts from the previous state's 90th percentile of the k-th distance.
        """
        if self._knn_cache is not None and self._knn_cache[0] == self._state:
            return self._knn_cache[1], self._knn_cache[2]
        k = max(self.cfg.n_neighbors, 1)
        pending, self._knn_pending = self._knn_pending, None
        if pending is not None and pending[0] == self._state:
            idx, dist = pending[1].result()
        else:
            idx, dist = knn(self.x, k, radius=self._knn_radius)
        if dist.size:
            hint = float(np.quantile(dist[..., -1], 0.9))
            self._knn_radius = hint if hint > 0 else None
        self._knn_cache = (self._state, idx, dist)
        return idx, dist

    def _pair_measures(self) -> tuple[np.ndarray | None, np.ndarray, np.ndarray, np.ndarray]:
        """As the dense core's; the energy sums the pair potential over the pairs within
        the cut-off, the collisions and the neighbours are exact."""
        p = self.cfg.physics
        if self.cfg.n_agents > 1:
            near, dist = self._knn()
            nearest = dist[..., 0]
        else:
            near, nearest = None, np.zeros((self.batch, 1), self.dtype)
        energy = kinetic_energy(self.v, p) + self._potential
        if p.C_g > 0:
            energy = energy + goal_potential(self.x, p, self.goal).sum(axis=-1)
        return near, nearest, self._collisions.copy(), energy.astype(self.dtype, copy=False)
