"""SwarmNav for large swarms: the batched core with a cut-off and an O(N) neighbour search.

:class:`CutoffSwarmNavCore` has exactly the public interface and semantics of
:class:`~swarm_envs.envs.cores.numpy.SwarmNavCore` (``reset``, ``step``, ``observe``,
``stats``; attributes ``x, v, goal, t, batch, obs_dim, cfg``) for
``cfg.dynamics == "social_potential"`` (with either explicit integrator), without any ``(B, N, N)``
array. One step:

1. the action becomes the control force ``u = u_max · a``, added to the passive force
   carried from the previous substep (at the current state, or for velocity Verlet at
   its extrapolated velocity, exactly as the dense core);
2. step-size control, as in the dense core (``SocialPotentialDynamics.step``): each
   swarm carries, beside its force, the stable substep ``h*`` of its current state
   (:func:`~swarm_envs.physics.integrators.stable_substep`). The step of ``dt`` takes
   ``⌈τ/h*⌉`` equal substeps of the time ``τ`` left, re-planned after each
   (:func:`~swarm_envs.physics.integrators.substep_plan`), at most ``cfg.max_substeps``
   (a swarm that needs more takes the rest of ``dt`` in the substeps left and is
   marked over the cap). Only the swarms with time left are advanced and evaluated, so
   a swarm's trajectory never depends on the others of the batch;
3. after each substep, one cell-list search (:class:`swarm_envs.physics.neighbors.CellList`)
   finds every pair within ``max(r_c, collision_radius)`` of the new positions, and one
   pass over them, in cell order, gives the next passive force, the rate sums of the
   step-size rule (``Σ_j κ_ij``, ``Σ_j w_ij`` per agent of
   :func:`~swarm_envs.physics.social_potential.rate_law`, turned into ``(ω², γ)`` by
   :func:`~swarm_envs.physics.pair_sums.swarm_rates`), the pair potential of the
   ``energy`` statistic and the collision count. Where numba imports, that pass is one
   compiled loop (:func:`swarm_envs.physics.compiled_pairs.cell_pair_sums`); otherwise
   numpy sums chunks of candidates (:class:`swarm_envs.physics.pair_sums.PairAccumulator`).
   Both apply the one pair law and the one rate law and agree to round-off;
   ``SWARM_ENVS_NUMBA=0`` picks numpy;
4. the k nearest neighbours (observations, nearest-neighbour distance) come from the
   cell-list structure (:func:`swarm_envs.physics.neighbors.knn`), on demand, cached per
   state and started from the previous step's distances; from
   :data:`KNN_AHEAD_MIN_AGENTS` agents the search starts in a worker thread as soon as
   the step's last positions are known, while the last pair pass runs
   (:mod:`swarm_envs.envs.cores.cutoff.neighbors`);
5. the dense core's guard: a swarm whose state is no longer finite, or that needed more
   substeps than ``max_substeps``, raises
   :class:`~swarm_envs.envs.common.SwarmUnstableError` (``on_unstable="raise"``) or is
   put back to its state before the step and truncated (``"truncate"``). A swarm that
   diverges (non-finite, or beyond :data:`MAX_SPAN` search radii) takes no further
   substeps, is never handed to the neighbour search, and its energy is NaN.

Agent statuses (removed, frozen, absent and joining agents, ``observe_status``) come
through ``set_status`` (the task layer's), with the dense core's rules
(:mod:`swarm_envs.envs.cores.cutoff.masks`): the agents not present are left out of the
pair passes and the neighbour search, the agents that do not move have zero total force
and stay put at rest.

What differs from the dense core is the cut-off only: the pair terms (and their rates)
of agents farther apart than ``r_c = cutoff_radius(cfg.physics, cutoff_tol,
speed=cutoff_speed)`` are dropped, each below ``cutoff_tol`` (force units) for relative
speeds up to ``cutoff_speed``; :func:`swarm_envs.physics.cutoff.force_error_bound` and
:func:`~swarm_envs.physics.cutoff.energy_error_bound` bound the per-agent force and the
energy statistic's errors. Observations, collisions and the nearest-neighbour distance
are exact; the substep counts equal the dense core's unless the dropped rates move
``τ/h*`` across an integer. The defaults (``cutoff_tol = 0.03``, 1 % of the default
``u_max``, and ``cutoff_speed = 1``) give ``r_c ≈ 5.08`` with the navigation set and
``≈ 3.30`` with the large-swarm preset; ``docs/large_swarms.md`` has the measured
errors, the cost (``O(N)`` per substep at bounded density, ``∝ r_c^d``) and the regimes
of both parameter sets from 10 to 100,000 agents. Large swarms need an H-stable
parameter set (``SocialPotentialParams.large_swarm()``, ``configs/env/large_swarm.yaml``)
and a bounded start density (``SwarmConfig.init_density``): the paper's sets collapse,
and the substeps a step needs grow with ``N`` until ``max_substeps``.

Below :data:`CUTOFF_MIN_AGENTS` agents per swarm the dense core (``O(N²)`` per step) is
as fast or faster (and exact); :func:`use_cutoff_core` is the selection rule
(``benchmarks/large_swarms.py`` measures the crossover).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from swarm_envs.config import SwarmConfig
from swarm_envs.envs.cores.cutoff.masks import PhysicsMasks
from swarm_envs.envs.cores.cutoff.neighbors import (
    KNN_AHEAD_MIN_AGENTS,
    MAX_SPAN,
    NeighborSearch,
    sound_swarms,
)
from swarm_envs.envs.cores.numpy import SwarmNavCore
from swarm_envs.envs.task.agent_status import AgentMasks
from swarm_envs.physics import compiled_pairs, goal_potential, kinetic_energy
from swarm_envs.physics._validation import check_real
from swarm_envs.physics.cutoff import cutoff_radius
from swarm_envs.physics.integrators import SubstepBudget, euler_update, stable_substep
from swarm_envs.physics.pair_sums import swarm_rates
from swarm_envs.physics.present_neighbors import close_pairs_among
from swarm_envs.physics.social_potential import (
    components,
    dissipation_rate,
    goal_terms,
    passive_components,
)

#: Agents per swarm from which to use :class:`CutoffSwarmNavCore`: above the crossover
#: with the dense cores that ``benchmarks/large_swarms.py`` measures (default config at
#: the start density of N = 10), with a margin.
CUTOFF_MIN_AGENTS = 500

#: Default tolerance per dropped pair force (force units): 1 % of the default ``u_max``.
DEFAULT_CUTOFF_TOL = 0.03

#: Default relative speed up to which the alignment term's tolerance holds.
DEFAULT_CUTOFF_SPEED = 1.0

#: The smallest pair-search radius: a swarm within ``MAX_SPAN`` of the origin then spans
#: fewer cells than a cell list holds.
MIN_SEARCH_RADIUS = 0.25

__all__ = [
    "CUTOFF_MIN_AGENTS",
    "DEFAULT_CUTOFF_SPEED",
    "DEFAULT_CUTOFF_TOL",
    "KNN_AHEAD_MIN_AGENTS",
    "MAX_SPAN",
    "CutoffSwarmNavCore",
    "density_preserving_radius",
    "use_cutoff_core",
]


def use_cutoff_core(cfg: SwarmConfig) -> bool:
    """Whether ``cfg`` should run on :class:`CutoffSwarmNavCore` rather than the dense core.

    True for the social potential model with at least :data:`CUTOFF_MIN_AGENTS` agents.

    >>> use_cutoff_core(SwarmConfig()), use_cutoff_core(SwarmConfig(n_agents=100_000))
    (False, True)
    """
    dynamics = getattr(cfg, "dynamics", "social_potential")
    return dynamics == "social_potential" and cfg.n_agents >= CUTOFF_MIN_AGENTS


def density_preserving_radius(
    n_agents: int, dim: int = 2, *, radius: float = 1.5, agents: int = 10
) -> float:
    """``init_radius`` that starts ``n_agents`` at the density of ``agents`` in ``radius``.

    ``R = radius · (n_agents / agents)^{1/d}``: the default start (10 agents in a disc of
    radius 1.5, 1.41 agents per unit area) scaled to ``N`` agents. With the default
    radius, 100,000 agents would start ``10^4`` times denser, with thousands of
    neighbours within the cut-off each. ``SwarmConfig.init_density`` gives the same law
    from a density.

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


class _Pass(NamedTuple):
    """What one pair pass gives for the swarms it covered."""

    force: np.ndarray  # (b, N, d) passive force
    h_stable: np.ndarray  # (b,) stable substep of the state
    potential: np.ndarray  # (b,) Σ U over the pairs within the cut-off
    collisions: np.ndarray  # (b,) pairs closer than collision_radius
    finite: np.ndarray  # (b,) bool: the state was sound (else NaN force, not searched)
    omega2: np.ndarray | None = None  # (b,) the stiffness rate ω² of the step-size rule
    pair_damping: np.ndarray | None = None  # (b,) the damping rate's pair part, times m


class CutoffSwarmNavCore(SwarmNavCore):
    """State and dynamics of ``batch`` independent SwarmNav swarms, for large ``N``.

    A drop-in for :class:`~swarm_envs.envs.cores.numpy.SwarmNavCore` (same methods, same
    random draws, same step-size control and guard, same results up to the cut-off; see
    the module docstring). It overrides only the physics hooks (``_after_reset``,
    ``_advance``, ``_restored``, ``_pair_measures``) and how the statuses' masks enter
    its physics (:class:`~swarm_envs.envs.cores.cutoff.masks.PhysicsMasks`); the
    statistics and the observations are the dense core's, the reset draws, the reward
    and the guard its task layer's.

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
        dynamics: the model's adapter
            (:class:`~swarm_envs.envs.dynamics.SocialPotentialDynamics`), which this
            core does not step (it advances the physics itself); it holds the step-size
            control's account of the last step, as the dense core reads it
            (``substeps``, ``over_cap``, ``needed``).

    >>> from swarm_envs.config import SwarmConfig
    >>> from swarm_envs.envs.task import STAT_KEYS
    >>> core = CutoffSwarmNavCore(SwarmConfig(n_agents=4), batch=2)
    >>> core.reset(np.random.default_rng(0))
    >>> reward, terminated, truncated, stats = core.step(np.zeros((2, 4, 2)))
    >>> core.observe().shape, reward.shape, sorted(stats) == sorted(STAT_KEYS)
    ((2, 4, 34), (2,), True)
    >>> stats["substeps"].tolist()
    [1.0, 1.0]
    """

    backend = "cutoff"

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
            raise ValueError(f"CutoffSwarmNavCore: {reason}")
        super().__init__(cfg, batch, dtype)
        self.cutoff_tol = check_real(
            "CutoffSwarmNavCore", "cutoff_tol", cutoff_tol, low=0.0, low_inclusive=False
        )
        self.cutoff_speed = check_real("CutoffSwarmNavCore", "cutoff_speed", cutoff_speed, low=0.0)
        B = self.batch
        self._cutoff_key: tuple[Any, ...] | None = None
        self._cutoff = 0.0
        self._f_passive: np.ndarray | None = None  # passive force carried to the next substep
        self._h_stable = np.full(B, np.inf)  # stable substep of the current state
        self._potential = np.zeros(B)  # Σ U over the pairs within the cut-off, per swarm
        self._collisions = np.zeros(B)
        self._state = 0  # bumped whenever x, v change; keys the neighbour cache
        self._neighbors = NeighborSearch()
        self._masks = PhysicsMasks()

    @staticmethod
    def unsupported(cfg: SwarmConfig) -> str | None:
        """Why this core cannot run ``cfg`` (``None`` if it can): the social potential
        model only, with the two explicit integrators (the pair passes do not sum the
        block bound and the implicit damping of ``"implicit_damping_euler"``)."""
        if cfg.dynamics != "social_potential":
            return f"supports dynamics='social_potential' only, got {cfg.dynamics!r}"
        if cfg.integrator not in ("semi_implicit_euler", "velocity_verlet"):
            return (
                "supports integrator='semi_implicit_euler' or 'velocity_verlet' only, "
                f"got {cfg.integrator!r}"
            )
        return None

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
        return self.goal if cfg.passive_sink else None

    def _pair_pass(
        self,
        x: np.ndarray,
        velocity: np.ndarray,
        goal: np.ndarray | None,
        rows: np.ndarray | None = None,
    ) -> _Pass:
        """The passive force at ``x`` ``(b, N, d)`` with ``velocity``, and what the same
        pass over the pairs gives: the stable substep, the pair potential, the collisions.
        ``rows``: the swarms ``x`` holds (``None``: all), for the statuses' masks.

        One cell-list search within ``max(r_c, collision_radius)`` and one pass over
        its pairs (:func:`~swarm_envs.physics.compiled_pairs.swarm_pair_sums`): the pair
        forces (eqs. 10–11), the rate sums of the step-size rule, the pair potential
        (eq. 9) and the collision count; then
        ``−β v`` (eq. 12) and the goal sink (eqs. 19–21) when it acts passively
        (``goal`` ``(b, d)``, else ``None``). Diverged swarms (a non-finite position or
        velocity, or beyond :data:`MAX_SPAN`) are left out: NaN force and potential,
        ``h* = inf``. With the statuses' masks, the agents not present are left out of
        the pass (no force, rate, potential or collision), and the close pairs of two
        present agents that do not move are no collision.
        """
        ok = sound_swarms(x, velocity, self._span)
        if not ok.all():
            b, N, d = x.shape
            out = _Pass(
                np.full((b, N, d), np.nan, self.dtype),
                np.full(b, np.inf),
                np.full(b, np.nan),
                np.zeros(b),
                ok,
            )
            if ok.any():
                sound = (np.arange(b) if rows is None else rows)[ok]
                part = self._pair_pass(
                    x[ok], velocity[ok], None if goal is None else goal[ok], sound
                )
                out.force[ok], out.h_stable[ok] = part.force, part.h_stable
                out.potential[ok], out.collisions[ok] = part.potential, part.collisions
                assert part.omega2 is not None and part.pair_damping is not None
                omega2, pair_damping = np.zeros(b), np.zeros(b)
                omega2[ok], pair_damping[ok] = part.omega2, part.pair_damping
                out = out._replace(omega2=omega2, pair_damping=pair_damping)
            return out
        cfg, p = self.cfg, self.cfg.physics
        b, N, d = x.shape
        # The search radius is at least MIN_SEARCH_RADIUS: a tinier cut-off (physics with
        # no interaction, no collision radius) would ask for more cells than a grid holds;
        # the pairs it adds beyond r_c only make the sums more exact.
        radius = max(self.cutoff, cfg.collision_radius, MIN_SEARCH_RADIUS)
        where = slice(None) if rows is None else rows
        present = None if self._masks.present is None else self._masks.present[where]
        sums = compiled_pairs.swarm_pair_sums(x, velocity, p, radius, cfg.collision_radius, present)
        assert sums.kappa is not None and sums.damping is not None
        force = sums.force.astype(self.dtype, copy=False)
        kappa, damping = sums.kappa, sums.damping
        potential, collisions = sums.potential, sums.close.astype(np.float64)
        if self._masks.still is not None:  # a pair at rest does not collide
            still = self._masks.still[where]
            collisions -= close_pairs_among(x, still, cfg.collision_radius, radius)
        force = force.reshape(b, N, d)
        sink = None if goal is None else goal_terms(x, p, goal)[0]
        passive = passive_components(components(force), components(velocity), p, sink)
        force[...] = np.stack(passive, axis=-1)
        omega2, gamma = swarm_rates(
            kappa.reshape(b, N), damping.reshape(b, N), p, sink=goal is not None, v=velocity
        )
        pair_damping = gamma * p.m - dissipation_rate(components(velocity), p)
        return _Pass(
            force,
            stable_substep(omega2, gamma, integrator=cfg.integrator),
            potential,
            collisions,
            ok,
            omega2,
            pair_damping,
        )

    def _rates_at(self, res: _Pass, v: np.ndarray) -> _Pass:
        """``res`` with its stable substep at the velocities ``v`` (with self-propulsion
        the damping rate depends on them): Verlet's state after the second kick, whose
        velocities are not the pass's (the dense core's rule)."""
        p = self.cfg.physics
        if p.alpha <= 0 or res.omega2 is None or res.pair_damping is None:
            return res
        gamma = (dissipation_rate(components(v), p) + res.pair_damping) / p.m
        h = stable_substep(res.omega2, gamma, integrator=self.cfg.integrator)
        h = np.where(res.finite, h, res.h_stable)
        return res._replace(h_stable=h)

    def _keep(self, rows: np.ndarray | None, res: _Pass) -> None:
        """Store a pass's rates, potential and collisions for ``rows`` (``None``: all)."""
        where = slice(None) if rows is None else rows
        self._h_stable[where] = res.h_stable
        self._potential[where] = res.potential
        self._collisions[where] = res.collisions

    # ------------------------------------------------------------------ physics hooks
    def _after_reset(self, idx: np.ndarray, rng: np.random.Generator) -> None:
        self._state += 1
        if self.batch * self.cfg.n_agents >= KNN_AHEAD_MIN_AGENTS:
            self._start_knn()  # the observation's search, while the pairs are summed
        res = self._pair_pass(self.x, self.v, self._physics_goal())
        if self._f_passive is None or self.cfg.integrator != "velocity_verlet":
            self._f_passive = res.force
        else:  # Verlet keeps the other swarms' carried force (as the dense core does)
            self._f_passive[idx] = res.force[idx]
        self._keep(None, res)

    def _advance(self, control: np.ndarray | None) -> None:
        """One step of ``dt`` in the substeps of the step-size control (module docstring)."""
        cfg = self.cfg
        if self._f_passive is None:
            raise ValueError("CutoffSwarmNavCore.step called before reset")
        B, cap, m = self.batch, cfg.max_substeps, cfg.physics.m
        verlet = cfg.integrator == "velocity_verlet"
        goal = self._physics_goal()
        ahead = B * cfg.n_agents >= KNN_AHEAD_MIN_AGENTS
        budget = SubstepBudget(B, cfg.dt, cap)
        rows = np.arange(B)
        x, v, f = self.x, self.v, self._f_passive
        moved = False  # self.x holds the step's final positions
        while True:
            every = rows.size == B  # no gather while every swarm is still stepping
            n, h = budget.plan(rows, self._h_stable[rows])
            hb = h[:, None, None].astype(self.dtype)
            xr, vr, fr = (x, v, f) if every else (x[rows], v[rows], f[rows])
            ur = control if control is None or every else control[rows]
            gr = goal if goal is None or every else goal[rows]
            accel = fr if ur is None else fr + ur
            accel = self._masks.hold(accel, None if every else rows)
            if verlet:
                # Kick–drift–kick with the force at the extrapolated velocity
                # 2v_{n+½} − v_n (swarm_envs.physics.integrators.verlet_step).
                v_half = vr + (0.5 / m) * hb * accel
                xr = xr + hb * v_half
                probe = 2.0 * v_half - vr
            else:  # semi-implicit Euler (swarm_envs.physics.integrators.euler_update)
                xr, vr = euler_update(xr, vr, accel, hb, m)
                probe = vr
            if every:
                x = xr  # a new array: the caller's state before the step stays intact
            else:
                x[rows] = xr
            if (n <= 1).all():  # the last substep of every swarm: x is final
                self.x, moved = x, True
                self._state += 1
                if ahead:
                    self._start_knn()
            res = self._pair_pass(xr, probe, gr, None if every else rows)
            if verlet:
                accel = res.force if ur is None else res.force + ur
                vr = v_half + (0.5 / m) * hb * accel
                res = self._rates_at(res, vr)
            if every:
                v, f = vr, res.force
            else:
                v[rows], f[rows] = vr, res.force
            self._keep(rows, res)
            done = budget.spend(rows, n, h, stop=~res.finite)
            if done.all():
                break
            rows = rows[~done]
        self.x, self.v, self._f_passive = x, v, f
        if not moved:
            self._state += 1
        counts = self.dynamics
        counts.substeps, counts.over_cap, counts.needed = budget.used, budget.over, budget.needed

    def _restored(self, idx: np.ndarray) -> None:
        """The carried force, rates and measures of the swarms ``idx`` whose ``x, v`` were
        set (one pair pass over them); a new state for the neighbour search."""
        assert self._f_passive is not None
        self._state += 1
        goal = self._physics_goal()
        res = self._pair_pass(self.x[idx], self.v[idx], None if goal is None else goal[idx], idx)
        self._f_passive[idx] = res.force
        self._keep(idx, res)

    # ------------------------------------------------------------------ statuses
    def _take_masks(self, mask: AgentMasks) -> None:
        """The statuses' masks in the pair passes and the neighbour search
        (:class:`~swarm_envs.envs.cores.cutoff.masks.PhysicsMasks`)."""
        self._state += 1  # a new state: the neighbours are searched again
        self._masks.take(mask, self.cfg)

    def remeasure(self, idx: np.ndarray) -> None:
        """As the dense core's: a pair pass over the swarms ``idx``, then their measure
        (nothing before the first reset)."""
        if self._f_passive is not None:
            super().remeasure(idx)

    # ------------------------------------------------------------------ neighbours
    @property
    def _span(self) -> float:
        """The widest sound swarm, in length units (:data:`MAX_SPAN`)."""
        return MAX_SPAN * max(self.cutoff, self.cfg.collision_radius, 1.0)

    def _start_knn(self) -> None:
        """Search the neighbours of ``self.x`` in a worker thread, meanwhile."""
        k = max(self.cfg.n_neighbors, 1)
        self._neighbors.start(self.x, self._state, k, self._masks.present, self._span)

    def _knn(self) -> tuple[np.ndarray, np.ndarray]:
        """Indices and distances ``(B, N, k)`` of each agent's nearest others, nearest
        first (:meth:`~swarm_envs.envs.cores.cutoff.neighbors.NeighborSearch.search`)."""
        k = max(self.cfg.n_neighbors, 1)
        return self._neighbors.search(self.x, self._state, k, self._masks.present, self._span)

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
            sink = goal_potential(self.x, p, self.goal)
            if self._masks.present is not None:  # over the agents present
                sink = np.where(self._masks.present, sink, 0.0)
            energy = energy + sink.sum(axis=-1)
        if self._masks.present is not None:  # an agent alone in the physics: 0
            nearest = np.where(np.isfinite(nearest), nearest, 0.0).astype(self.dtype)
        return near, nearest, self._collisions.copy(), energy.astype(self.dtype, copy=False)
