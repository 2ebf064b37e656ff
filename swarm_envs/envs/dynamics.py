"""The physics behind SwarmNav, one adapter per model: how an action biases each model.

:class:`~swarm_envs.envs.core.SwarmNavCore` owns the batched state ``x, v`` ``(B, N, d)``
and the goals ``(B, d)``; the adapter selected by ``SwarmConfig.dynamics`` advances it
by one step with the control ``u = u_max · a`` (``a ∈ [−1, 1]^d`` per agent) and draws
whatever per-swarm state its model needs at reset. The actions follow ``docs/models.md`` §6;
with ``a = 0`` every model runs exactly its passive physics:

============================  =====================================================
``dynamics``                  what the control ``u_i = u_max · a_i`` does
============================  =====================================================
``"social_potential"``        a force added to ``F_i`` (Mabrouk & McInnes eq. 13)
``"zone"``                    a bias added to the unit desired direction before the
                              turn, ``d̂_i + u_i`` (Naterop eqs. 3–6; ``u_i = ω ĝ_i``
                              is the informed-individual rule)
``"piecewise"``               a force added to Viscido's ``Σ F(ρ_ij) u_ij + ξ_i − β v_i``
                              (Naterop eq. 15)
``"lagrangian"``              a velocity added to ``−α_i ∂L/∂x_i`` (Vanualailai &
                              Sharma eq. 7); the safe substep keeps every bin pair
                              apart (``R_ij > 0``) whatever the action
============================  =====================================================

The goal acts passively only with ``goal_in_physics``: the social potential's sink
(eq. 19), the zone model's informed individuals (Naterop eq. 6, a fraction
``informed_fraction`` of each swarm drawn at reset), the same sink force on top of the
piecewise model, and the Lagrangian's centre ``x_c`` replaced by the goal.

The ``energy`` statistic is each model's own: the total energy ``φ`` (social
potential), ``L`` (Lagrangian; ``+inf`` never occurs, as bins never overlap), and the
kinetic energy ``½ m Σ|v_i|²`` for the zone and piecewise models, which have no
potential (the piecewise neighbour relation is one-way).
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np

from swarm_envs.config import DYNAMICS, SwarmConfig
from swarm_envs.physics import (
    PairGeometry,
    energy,
    forces,
    goal_force,
    kinetic_energy,
    uniform_ball,
    verlet_step,
)
from swarm_envs.physics.integrators import euler_update
from swarm_envs.physics.lagrangian import (
    lagrangian_step,
    lagrangian_value,
    lagrangian_velocity,
    pair_clearance,
)
from swarm_envs.physics.piecewise import piecewise_forces
from swarm_envs.physics.social_potential import goal_terms, pair_terms
from swarm_envs.physics.zone import (
    ZoneAgentParams,
    draw_agent_params,
    draw_informed,
    uniform_agent_params,
    zone_step,
)

#: Redraws of a swarm's start before a Lagrangian reset gives up (bins overlapping).
MAX_START_DRAWS = 1000


class Dynamics(ABC):
    """One model's step on a batch of swarms (see the module docstring)."""

    def __init__(self, cfg: SwarmConfig, batch: int, dtype: np.dtype) -> None:
        self.cfg = cfg
        self.batch = batch
        self.dtype = dtype

    def reset(
        self,
        x: np.ndarray,
        v: np.ndarray,
        goal: np.ndarray,
        idx: np.ndarray,
        rng: np.random.Generator,
    ) -> None:
        """Model state for the swarms ``idx`` (already drawn ``x, v, goal``), in place.

        The default has none.
        """
        return None

    @abstractmethod
    def step(
        self,
        x: np.ndarray,
        v: np.ndarray,
        goal: np.ndarray | None,
        control: np.ndarray | None,
    ) -> tuple[np.ndarray, np.ndarray, PairGeometry | None]:
        """``(x', v', geometry of x' or None)`` after one step of ``cfg.dt``.

        ``goal`` is ``None`` unless the goal acts passively; ``control`` is
        ``u_max · a`` or ``None`` for zero actions.
        """

    def measure(
        self, x: np.ndarray, v: np.ndarray, goal: np.ndarray, geometry: PairGeometry
    ) -> np.ndarray:
        """The model's energy statistic per swarm, ``(B,)``, at a new state (after every
        reset and step; a model may keep what it computes for its next step). Kinetic
        by default."""
        return 0.5 * np.einsum("bik,bik->b", v, v)


class SocialPotentialDynamics(Dynamics):
    """Mabrouk & McInnes: ``m v̇ = F_i + u_i`` (eq. 13), Euler or velocity Verlet.

    Both integrators carry the passive force from one step to the next: semi-implicit
    Euler the force ``F(x, v)`` of the current state, computed in :meth:`measure` in the
    same pass over the pairs as the energy; velocity Verlet the force at the
    extrapolated velocity (:func:`~swarm_envs.physics.integrators.verlet_step`).
    """

    def __init__(self, cfg: SwarmConfig, batch: int, dtype: np.dtype) -> None:
        super().__init__(cfg, batch, dtype)
        self._force: np.ndarray | None = None  # the passive force carried to the next step
        self._verlet = cfg.integrator == "velocity_verlet"

    def _physics_goal(self, goal: np.ndarray) -> np.ndarray | None:
        cfg = self.cfg
        return goal if cfg.goal_in_physics and cfg.physics.C_g > 0 else None

    def reset(self, x, v, goal, idx, rng) -> None:
        if self._verlet:
            f = forces(x, v, self.cfg.physics, self._physics_goal(goal))
            if self._force is None:
                self._force = f
            else:
                self._force[idx] = f[idx]

    def step(self, x, v, goal, control):
        cfg = self.cfg
        assert self._force is not None
        goal = goal if cfg.physics.C_g > 0 else None
        if self._verlet:
            x, v, self._force, geometry = verlet_step(
                x, v, self._force, cfg.physics, dt=cfg.dt, goal=goal, control=control
            )
            return x, v, geometry
        accel = self._force if control is None else self._force + control
        x, v = euler_update(x, v, accel, cfg.dt, cfg.physics.m)
        return x, v, None

    def measure(self, x, v, goal, geometry):
        p = self.cfg.physics
        if self._verlet:
            return energy(x, v, p, goal if p.C_g > 0 else None, geometry=geometry)
        fs, pairs = pair_terms(geometry, v, p)
        if p.beta > 0:
            fs = [fc - p.beta * v[..., k] for k, fc in enumerate(fs)]
        phi = kinetic_energy(v, p) + pairs
        if p.C_g > 0:
            sink, potential, _ = goal_terms(x, p, goal)
            phi = phi + potential.sum(axis=-1)
            if self.cfg.goal_in_physics:
                fs = [fc + gc for fc, gc in zip(fs, sink, strict=True)]
        self._force = np.stack(fs, axis=-1)
        return phi


class ZoneDynamics(Dynamics):
    """Couzin's zone model (Naterop §4.1): constant speed, heading turned by ``≤ φ̄``.

    Per-agent parameters (eq. 7, ``param_spread``) and, with ``goal_in_physics``, the
    informed subset (eq. 6) are drawn per swarm at reset; velocities are ``s_i η̂_i``.
    """

    def __init__(self, cfg: SwarmConfig, batch: int, dtype: np.dtype) -> None:
        super().__init__(cfg, batch, dtype)
        shape = (batch, cfg.n_agents)
        self.agent_params = ZoneAgentParams(
            *(np.full(shape, float(a)) for a in uniform_agent_params(cfg.zone))
        )
        self.informed = np.zeros(shape, dtype=bool)

    def reset(self, x, v, goal, idx, rng) -> None:
        cfg, p = self.cfg, self.cfg.zone
        shape = (idx.size, cfg.n_agents)
        if p.param_spread > 0:
            drawn = draw_agent_params(p, rng, shape)
            for mine, new in zip(self.agent_params, drawn, strict=True):
                mine[idx] = new
        if cfg.goal_in_physics and p.informed_fraction > 0:
            self.informed[idx] = draw_informed(p, rng, shape)
        speed = v[idx]
        norm = np.linalg.norm(speed, axis=-1, keepdims=True)
        random = rng.standard_normal(speed.shape)  # headings for agents at rest
        random /= np.maximum(np.linalg.norm(random, axis=-1, keepdims=True), 1e-12)
        moving = norm > 1e-12
        heading = np.where(moving, speed / np.where(moving, norm, 1.0), random)
        v[idx] = self.agent_params.speed[idx][..., None] * heading

    def step(self, x, v, goal, control):
        speed = self.agent_params.speed[..., None]
        heading = v / speed
        x, heading = zone_step(
            x,
            heading,
            self.cfg.zone,
            dt=self.cfg.dt,
            goal=goal,
            informed=self.informed if goal is not None else None,
            agent_params=self.agent_params,
            bias=control,
        )
        dt = self.dtype
        return x.astype(dt, copy=False), (speed * heading).astype(dt, copy=False), None


class PiecewiseDynamics(Dynamics):
    """Viscido's piecewise force model (Naterop §4.2), semi-implicit Euler.

    ``m v' = m v + dt (Σ_{λ nearest} F(ρ_ij) u_ij + ξ_i − β v_i + F_goal_i + u_i)``,
    ``x' = x + dt v'``; ``F_goal`` (the social potential's sink, ``cfg.physics.C_g,
    l_g``) only with ``goal_in_physics``. The random force ``ξ`` comes from a generator
    seeded from the reset's at every full reset, so a seed fixes the whole rollout.
    """

    def __init__(self, cfg: SwarmConfig, batch: int, dtype: np.dtype) -> None:
        super().__init__(cfg, batch, dtype)
        self._noise_rng: np.random.Generator | None = None

    def reset(self, x, v, goal, idx, rng) -> None:
        if self.cfg.piecewise.sigma > 0 and (self._noise_rng is None or idx.size == self.batch):
            self._noise_rng = np.random.default_rng(rng.integers(2**63))

    def step(self, x, v, goal, control):
        cfg, p = self.cfg, self.cfg.piecewise
        f = piecewise_forces(x, v, p, self._noise_rng)
        if goal is not None and cfg.physics.C_g > 0:
            f += goal_force(x, cfg.physics, goal)
        if control is not None:
            f += control
        v = v + (cfg.dt / p.m) * f
        return x + cfg.dt * v, v, None

    def measure(self, x, v, goal, geometry):
        return 0.5 * self.cfg.piecewise.m * np.einsum("bik,bik->b", v, v)


class LagrangianDynamics(Dynamics):
    """Vanualailai & Sharma's first-order model ``ẋ = −α ∂L/∂x + u`` (eq. 7).

    Starts are redrawn until no two bins overlap (all ``R_ij > 0``); the velocity is
    the model's ``ẋ``. The substep length is carried per swarm between steps.
    """

    def __init__(self, cfg: SwarmConfig, batch: int, dtype: np.dtype) -> None:
        super().__init__(cfg, batch, dtype)
        self._substep = np.full(batch, cfg.dt)

    def _centre(self, goal: np.ndarray) -> np.ndarray | None:
        return goal if self.cfg.goal_in_physics else None

    def reset(self, x, v, goal, idx, rng) -> None:
        cfg, p = self.cfg, self.cfg.lagrangian
        if cfg.n_agents > 1:
            bad = idx[~(pair_clearance(x[idx], p) > 0).all(axis=(-2, -1))]
            draws = 0
            while bad.size:
                if draws == MAX_START_DRAWS:
                    raise ValueError(
                        f"could not place {cfg.n_agents} agents with non-overlapping bins "
                        f"(lagrangian.r) in a disc of init_radius={cfg.init_radius} after "
                        f"{MAX_START_DRAWS} draws; increase init_radius or reduce lagrangian.r"
                    )
                x[bad] = uniform_ball(rng, (bad.size, cfg.n_agents, cfg.dim), cfg.init_radius)
                bad = bad[~(pair_clearance(x[bad], p) > 0).all(axis=(-2, -1))]
                draws += 1
        v[idx] = lagrangian_velocity(x[idx], p, self._centre(goal[idx]))
        self._substep[idx] = cfg.dt

    def step(self, x, v, goal, control):
        x, v, self._substep = lagrangian_step(
            x,
            self.cfg.lagrangian,
            dt=self.cfg.dt,
            goal=goal,
            control=control,
            substep=self._substep,
        )
        return x, v.astype(self.dtype, copy=False), None

    def measure(self, x, v, goal, geometry):
        return lagrangian_value(x, self.cfg.lagrangian, self._centre(goal))


_ADAPTERS: dict[str, type[Dynamics]] = {
    "social_potential": SocialPotentialDynamics,
    "zone": ZoneDynamics,
    "piecewise": PiecewiseDynamics,
    "lagrangian": LagrangianDynamics,
}


def make_dynamics(cfg: SwarmConfig, batch: int, dtype: np.dtype) -> Dynamics:
    """The adapter for ``cfg.dynamics`` (one of :data:`DYNAMICS`)."""
    if cfg.dynamics not in _ADAPTERS:
        raise ValueError(f"dynamics must be one of {DYNAMICS}, got {cfg.dynamics!r}")
    return _ADAPTERS[cfg.dynamics](cfg, batch, dtype)


__all__ = ["DYNAMICS", "Dynamics", "make_dynamics"]
