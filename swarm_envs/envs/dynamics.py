"""The physics behind SwarmNav, one adapter per model: how an action biases each model.

:class:`~swarm_envs.envs.cores.numpy.SwarmNavCore` owns the batched state ``x, v`` ``(B, N, d)``
and the goals ``(B, d)``; the adapter of the model ``SwarmConfig.dynamics`` names (its
``ModelSpec.adapter`` in the registry, :mod:`swarm_envs.models`; :func:`make_dynamics`)
advances it by one step with the control ``u = u_max · a`` (``a ∈ [−1, 1]^d`` per agent)
and draws whatever per-swarm state its model needs at reset. The actions follow
``docs/models.md`` §6; with ``a = 0`` every model runs exactly its passive physics. The
shipped models (this table is generated from their registry entries):

<models table>

The goal acts passively only with ``goal_in_physics``: the social potential's sink
(eq. 19), the zone model's informed individuals (Naterop eq. 6, a fraction
``informed_fraction`` of each swarm drawn at reset), the same sink force on top of the
piecewise model, and the Lagrangian's centre ``x_c`` replaced by the goal.

The ``energy`` statistic is each model's own: the total energy ``φ`` (social
potential), ``L`` (Lagrangian; ``+inf`` never occurs, as bins never overlap), and the
kinetic energy ``½ m Σ|v_i|²`` for the zone and piecewise models, which have no
potential (the piecewise neighbour relation is one-way).

A user's model brings its own adapter, a subclass of :class:`Dynamics`
(``docs/design.md``, "Adding a model").
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np

from swarm_envs.config import DYNAMICS, SwarmConfig
from swarm_envs.envs.step_control import start_substeps
from swarm_envs.models import SHIPPED, model_spec, models_table
from swarm_envs.physics import (
    PairGeometry,
    energy,
    forces,
    goal_force,
    kinetic_energy,
    pair_geometry,
    uniform_ball,
    verlet_step,
)
from swarm_envs.physics.integrators import (
    SubstepBudget,
    euler_update,
    implicit_damping_update,
    stable_substep,
)
from swarm_envs.physics.lagrangian import (
    lagrangian_frame,
    lagrangian_value,
    lagrangian_velocity,
    well_separated,
)
from swarm_envs.physics.piecewise import interaction_forces, random_force
from swarm_envs.physics.social_potential import (
    components,
    damping_rates,
    goal_terms,
    pair_rates,
    pair_terms,
    passive_components,
    present_geometry,
    stiffness_rate,
)
from swarm_envs.physics.zone import (
    ZoneAgentParams,
    draw_agent_params,
    draw_informed,
    uniform_agent_params,
    zone_step,
)

if __doc__ is not None:  # the table of the module docstring, from the registry
    __doc__ = __doc__.replace("<models table>", models_table(SHIPPED))

#: Redraws of a swarm's start before a Lagrangian reset gives up (bins overlapping).
MAX_START_DRAWS = 1000


def _rows_of(value: Any, rows: np.ndarray, axis: int) -> Any:
    """``value``'s swarms ``rows`` on ``axis``: an array, a named tuple of arrays (0-d
    arrays, shared by every swarm, kept as they are) or None."""
    if value is None:
        return None
    if isinstance(value, tuple):
        return type(value)(*(_rows_of(v, rows, axis) for v in value))
    value = np.asarray(value)
    return value if value.ndim == 0 else np.take(value, rows, axis=axis)


class Dynamics(ABC):
    """One model's step on a batch of swarms (see the module docstring): a model's
    ``ModelSpec.adapter``.

    Built once per core as ``cls(cfg, batch, dtype)``; reads its parameters as
    ``cfg.dynamics_params``. A subclass implements :meth:`step` and, where its model
    needs them, :meth:`reset` (per-swarm model state), :meth:`measure` (its energy
    statistic; kinetic by default) and :meth:`restore`. The state arrays are ``(B, N,
    d)`` of ``dtype``; a step returns arrays of that dtype. A model that integrates in
    substeps reports them in :attr:`substeps`, :attr:`over_cap` and :attr:`needed`
    (:meth:`fixed_substeps` does it for a rule fixed by the parameters); the core turns
    a step over the cap into an unstable step. A model whose ``ModelSpec.applies_masks``
    is true honours :attr:`present` and :attr:`mobile`.
    """

    #: The per-swarm state :meth:`keep` keeps: attribute name → the axis that holds the
    #: swarm (arrays, named tuples of arrays, or None). A subclass adds its own.
    ROW_STATE: ClassVar[Mapping[str, int]] = {
        "substeps": 0,
        "over_cap": 0,
        "needed": 0,
        "present": 0,
        "mobile": 0,
    }
    #: Whether :meth:`keep` may shrink the batch: the model's step reads each swarm's
    #: own state alone and :attr:`ROW_STATE` names all of it, so that the kept swarms go
    #: on the same bit for bit. Off unless a model says so (a model drawing randomness
    #: for the whole batch at each step cannot).
    KEEPS_ROWS: bool = False

    def __init__(self, cfg: SwarmConfig, batch: int, dtype: np.dtype) -> None:
        self.cfg = cfg
        self.batch = batch
        self.dtype = dtype
        #: Substeps the last step took per swarm, and where it needed more than
        #: ``cfg.max_substeps`` (``needed``: how many, at least, for the message).
        self.substeps = np.ones(batch)
        self.over_cap = np.zeros(batch, dtype=bool)
        self.needed = np.ones(batch)
        #: Agents in the physics and agents that move, ``(B, N)`` bool, set by the core
        #: when agents can leave or stop (``None``: every agent; agent_status).
        self.present: np.ndarray | None = None
        self.mobile: np.ndarray | None = None

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

    def restore(self, x: np.ndarray, v: np.ndarray, goal: np.ndarray, idx: np.ndarray) -> None:
        """The swarms ``idx`` were put back to an earlier state ``x, v`` (an unstable step
        undone): recompute what the model carries for them. Nothing by default."""
        return None

    def keep(self, rows: np.ndarray) -> None:
        """Shrink the batch to the swarms ``rows`` (indices, in their new order): every
        attribute of :attr:`ROW_STATE` keeps those rows."""
        for name, axis in self.ROW_STATE.items():
            setattr(self, name, _rows_of(getattr(self, name), rows, axis))
        self.batch = len(rows)

    def _count(self, used: np.ndarray, over: np.ndarray, needed: np.ndarray) -> None:
        self.substeps, self.over_cap, self.needed = used, over, needed

    def fixed_substeps(self) -> int:
        """For a model whose step-size rule holds for every step
        (``ModelSpec.substeps_fixed``): the substeps each step takes, the rule's count
        capped at ``cfg.max_substeps``; the counts every step then reports are recorded
        (a count over the cap makes every step unstable)."""
        needed = start_substeps(self.cfg)
        n = min(needed, self.cfg.max_substeps)
        self._count(
            np.full(self.batch, float(n)),
            np.full(self.batch, needed > self.cfg.max_substeps),
            np.full(self.batch, float(needed)),
        )
        return n


class SocialPotentialDynamics(Dynamics):
    """Mabrouk & McInnes: ``m v̇ = F_i + u_i`` (eq. 13), by one of the integrators.

    Every integrator carries the passive force from one substep to the next: the two
    Euler schemes the force ``F(x, v)`` of the current state, computed in :meth:`measure`
    in the same pass over the pairs as the energy; velocity Verlet the force at the
    extrapolated velocity (:func:`~swarm_envs.physics.integrators.verlet_step`).
    ``"implicit_damping_euler"`` carries the agents' implicit damping ``(b_i, w_i)`` of
    the current state beside it
    (:func:`~swarm_envs.physics.social_potential.damping_rates`).

    Step-size control: the stable substep ``h*`` of the current state (its Gershgorin
    rates, :func:`~swarm_envs.physics.social_potential.pair_rates`, or for
    ``"implicit_damping_euler"`` the block bound
    :func:`~swarm_envs.physics.social_potential.stiffness_rate`, at the edge of the
    integrator's stability, :func:`~swarm_envs.physics.integrators.stable_substep`) is
    carried like the force. A step of ``dt`` takes ``⌈τ/h*⌉`` equal substeps of the time ``τ`` left,
    re-planned after each (:func:`~swarm_envs.physics.integrators.substep_plan`); every
    swarm plans its own, and only the swarms with time left are evaluated.
    """

    ROW_STATE: ClassVar[Mapping[str, int]] = {
        **Dynamics.ROW_STATE,
        "_force": 0,
        "_h_stable": 0,
        "_damping": 1,
    }
    KEEPS_ROWS = True

    def __init__(self, cfg: SwarmConfig, batch: int, dtype: np.dtype) -> None:
        super().__init__(cfg, batch, dtype)
        self._force: np.ndarray | None = None  # the passive force carried to the next step
        self._h_stable = np.full(batch, np.inf)  # the stable substep of the current state
        self._verlet = cfg.integrator == "velocity_verlet"
        self._implicit = cfg.integrator == "implicit_damping_euler"
        # the implicit damping (b_i, w_i) of the current state (implicit_damping_euler)
        self._damping = np.zeros((2, batch, cfg.n_agents))
        self._sink = cfg.passive_sink

    def _physics_goal(self, goal: np.ndarray) -> np.ndarray | None:
        return goal if self._sink else None

    def reset(
        self,
        x: np.ndarray,
        v: np.ndarray,
        goal: np.ndarray,
        idx: np.ndarray,
        rng: np.random.Generator,
    ) -> None:
        if self._verlet:
            f = forces(x, v, self.cfg.physics, self._physics_goal(goal))
            if self._force is None:
                self._force = f
            else:
                self._force[idx] = f[idx]

    def restore(self, x: np.ndarray, v: np.ndarray, goal: np.ndarray, idx: np.ndarray) -> None:
        if self._verlet:
            assert self._force is not None
            g = self._physics_goal(goal)
            self._force[idx] = forces(
                x[idx], v[idx], self.cfg.physics, None if g is None else g[idx]
            )

    def _mobile_force(self, f: np.ndarray, rows: np.ndarray | None) -> np.ndarray:
        """The total force with the agents that do not move held at rest (zero force:
        their velocity is zero, so they keep their position)."""
        if self.mobile is None:
            return f
        mobile = self.mobile if rows is None else self.mobile[rows]
        return np.where(mobile[..., None], f, 0.0).astype(f.dtype, copy=False)

    def _rates(
        self, geometry: PairGeometry, v: np.ndarray, rows: np.ndarray | None = None
    ) -> np.ndarray:
        """The stable substep of the swarms ``rows`` (all: ``None``) at ``(geometry, v)``;
        for ``"implicit_damping_euler"`` their implicit damping is stored too."""
        p = self.cfg.physics
        if self._implicit:
            damping = np.stack(damping_rates(geometry, v, p))
            if rows is None:
                self._damping = damping
            else:
                self._damping[:, rows] = damping
            omega2 = stiffness_rate(geometry, p, sink=self._sink)
            return stable_substep(omega2, 0.0 * omega2, integrator=self.cfg.integrator)
        omega2, gamma = pair_rates(geometry, p, sink=self._sink, v=v)
        return stable_substep(omega2, gamma, integrator=self.cfg.integrator)

    def _passive(
        self, x: np.ndarray, v: np.ndarray, goal: np.ndarray | None, geometry: PairGeometry
    ) -> np.ndarray:
        """The passive force at ``(x, v)`` (semi-implicit Euler's carried force)."""
        p = self.cfg.physics
        pair_forces, _ = pair_terms(geometry, v, p, energy=False)
        sink = None if goal is None else goal_terms(x, p, goal)[0]
        return np.stack(passive_components(pair_forces, components(v), p, sink), axis=-1)

    def step(
        self,
        x: np.ndarray,
        v: np.ndarray,
        goal: np.ndarray | None,
        control: np.ndarray | None,
    ) -> tuple[np.ndarray, np.ndarray, PairGeometry | None]:
        cfg = self.cfg
        assert self._force is not None
        goal = goal if self._sink else None
        B = self.batch
        budget = SubstepBudget(B, cfg.dt, cfg.max_substeps)
        rows = np.arange(B)
        geometry: PairGeometry | None = None
        while True:
            every = rows.size == B  # no gather while every swarm is still stepping
            n, h = budget.plan(rows, self._h_stable[rows])
            hb = h[:, None, None].astype(self.dtype)
            xr, vr = (x, v) if every else (x[rows], v[rows])
            fr = self._force if every else self._force[rows]
            ur = control if control is None or every else control[rows]
            gr = goal if goal is None or every else goal[rows]
            if self._verlet:
                xr, vr, fr, geometry = verlet_step(
                    xr, vr, fr, cfg.physics, dt=hb, goal=gr, control=ur
                )
            else:
                total = self._mobile_force(fr if ur is None else fr + ur, None if every else rows)
                if self._implicit:
                    own, align = self._damping if every else self._damping[:, rows]
                    if self.mobile is not None:  # an agent held at rest: no increment
                        align = np.where(self.mobile if every else self.mobile[rows], align, 0.0)
                    own = own[..., None].astype(self.dtype, copy=False)
                    align = align[..., None].astype(self.dtype, copy=False)
                    xr, vr = implicit_damping_update(xr, vr, total, hb, cfg.physics.m, own, align)
                else:
                    xr, vr = euler_update(xr, vr, total, hb, cfg.physics.m)
            if every:
                x, v = xr, vr  # new arrays: the caller's are never written
                if self._verlet:
                    self._force = fr
            else:
                x[rows], v[rows] = xr, vr
                if self._verlet:
                    self._force[rows] = fr
            done = budget.spend(rows, n, h)
            if done.all():
                self._count(budget.used, budget.over, budget.needed)
                return x, v, geometry if every else None
            rows = rows[~done]
            xr, vr = x[rows], v[rows]
            geo = present_geometry(
                pair_geometry(xr), None if self.present is None else self.present[rows]
            )
            if not self._verlet:
                self._force[rows] = self._passive(xr, vr, None if goal is None else goal[rows], geo)
            self._h_stable[rows] = self._rates(geo, vr, rows)

    def measure(
        self, x: np.ndarray, v: np.ndarray, goal: np.ndarray, geometry: PairGeometry
    ) -> np.ndarray:
        p = self.cfg.physics
        self._h_stable = self._rates(geometry, v)
        if self._verlet:
            return energy(x, v, p, goal if p.C_g > 0 else None, geometry=geometry)
        pair_forces, pairs = pair_terms(geometry, v, p)
        phi = kinetic_energy(v, p) + pairs
        sink = None
        if p.C_g > 0:
            sink, potential, _ = goal_terms(x, p, goal)
            if self.present is not None:
                potential = np.where(self.present, potential, 0.0)
            phi = phi + potential.sum(axis=-1)
        passive = passive_components(
            pair_forces, components(v), p, sink if self.cfg.goal_in_physics else None
        )
        self._force = np.stack(passive, axis=-1)
        return phi


class ZoneDynamics(Dynamics):
    """Couzin's zone model (Naterop §4.1): constant speed, heading turned by ``≤ φ̄``.

    Per-agent parameters (eq. 7, ``param_spread``) and, with ``goal_in_physics``, the
    informed subset (eq. 6) are drawn per swarm at reset; velocities are ``s_i η̂_i``.
    """

    ROW_STATE: ClassVar[Mapping[str, int]] = {
        **Dynamics.ROW_STATE,
        "agent_params": 0,
        "informed": 0,
    }
    KEEPS_ROWS = True

    def __init__(self, cfg: SwarmConfig, batch: int, dtype: np.dtype) -> None:
        super().__init__(cfg, batch, dtype)
        shape = (batch, cfg.n_agents)
        self.agent_params = ZoneAgentParams(
            *(np.full(shape, float(a)) for a in uniform_agent_params(cfg.zone))
        )
        self.informed = np.zeros(shape, dtype=bool)

    def reset(
        self,
        x: np.ndarray,
        v: np.ndarray,
        goal: np.ndarray,
        idx: np.ndarray,
        rng: np.random.Generator,
    ) -> None:
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

    def step(
        self,
        x: np.ndarray,
        v: np.ndarray,
        goal: np.ndarray | None,
        control: np.ndarray | None,
    ) -> tuple[np.ndarray, np.ndarray, PairGeometry | None]:
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

    # KEEPS_ROWS stays off: its random force is drawn for the whole batch at each step.

    def __init__(self, cfg: SwarmConfig, batch: int, dtype: np.dtype) -> None:
        super().__init__(cfg, batch, dtype)
        self._noise_rng: np.random.Generator | None = None
        self._n = self.fixed_substeps()  # piecewise_substeps, its step-size rule

    def reset(
        self,
        x: np.ndarray,
        v: np.ndarray,
        goal: np.ndarray,
        idx: np.ndarray,
        rng: np.random.Generator,
    ) -> None:
        if self.cfg.piecewise.sigma > 0 and (self._noise_rng is None or idx.size == self.batch):
            self._noise_rng = np.random.default_rng(rng.integers(2**63))

    def step(
        self,
        x: np.ndarray,
        v: np.ndarray,
        goal: np.ndarray | None,
        control: np.ndarray | None,
    ) -> tuple[np.ndarray, np.ndarray, PairGeometry | None]:
        cfg, p = self.cfg, self.cfg.piecewise
        h = cfg.dt / self._n
        noise = None  # the random force, drawn once per step and held over its substeps
        for _ in range(self._n):
            f = interaction_forces(x, p)
            if p.sigma > 0:
                if noise is None:
                    assert self._noise_rng is not None  # drawn at the first reset
                    noise = random_force(self._noise_rng, x.shape, p, f.dtype)
                f += noise
            if p.beta > 0:
                f -= p.beta * v
            if goal is not None and cfg.physics.C_g > 0:
                f += goal_force(x, cfg.physics, goal)
            if control is not None:
                f += control
            v = v + (h / p.m) * f
            x = x + h * v
        return x, v, None

    def measure(
        self, x: np.ndarray, v: np.ndarray, goal: np.ndarray, geometry: PairGeometry
    ) -> np.ndarray:
        return 0.5 * self.cfg.piecewise.m * np.einsum("bik,bik->b", v, v)


class LagrangianDynamics(Dynamics):
    """Vanualailai & Sharma's first-order model ``ẋ = −α ∂L/∂x + u`` (eq. 7).

    Starts are redrawn until every pair of bins is apart by a small gap
    (:func:`~swarm_envs.physics.lagrangian.well_separated`: 2 % of their radii's sum);
    the velocity is the model's ``ẋ``. The substep length is carried per swarm between steps.
    """

    ROW_STATE: ClassVar[Mapping[str, int]] = {**Dynamics.ROW_STATE, "_substep": 0}
    KEEPS_ROWS = True

    def __init__(self, cfg: SwarmConfig, batch: int, dtype: np.dtype) -> None:
        super().__init__(cfg, batch, dtype)
        self._substep = np.full(batch, cfg.dt)

    def _centre(self, goal: np.ndarray) -> np.ndarray | None:
        return goal if self.cfg.goal_in_physics else None

    def reset(
        self,
        x: np.ndarray,
        v: np.ndarray,
        goal: np.ndarray,
        idx: np.ndarray,
        rng: np.random.Generator,
    ) -> None:
        cfg, p = self.cfg, self.cfg.lagrangian
        if cfg.n_agents > 1:
            bad = idx[~well_separated(x[idx], p)]
            draws = 0
            while bad.size:
                if draws == MAX_START_DRAWS:
                    raise ValueError(
                        f"could not place {cfg.n_agents} agents with their bins (lagrangian.r) "
                        f"apart in a disc of init_radius={cfg.init_radius} after "
                        f"{MAX_START_DRAWS} draws; increase init_radius or reduce lagrangian.r"
                    )
                x[bad] = uniform_ball(rng, (bad.size, cfg.n_agents, cfg.dim), cfg.init_radius)
                bad = bad[~well_separated(x[bad], p)]
                draws += 1
        v[idx] = lagrangian_velocity(x[idx], p, self._centre(goal[idx]))
        self._substep[idx] = cfg.dt

    def step(
        self,
        x: np.ndarray,
        v: np.ndarray,
        goal: np.ndarray | None,
        control: np.ndarray | None,
    ) -> tuple[np.ndarray, np.ndarray, PairGeometry | None]:
        frame = lagrangian_frame(
            x,
            self.cfg.lagrangian,
            dt=self.cfg.dt,
            goal=goal,
            control=control,
            substep=self._substep,
            max_substeps=self.cfg.max_substeps,
        )
        self._substep = frame.substep
        needed = np.where(frame.over_cap, self.cfg.max_substeps + 1.0, frame.substeps)
        self._count(frame.substeps, frame.over_cap, needed)
        return frame.x, frame.v.astype(self.dtype, copy=False), None

    def measure(
        self, x: np.ndarray, v: np.ndarray, goal: np.ndarray, geometry: PairGeometry
    ) -> np.ndarray:
        return lagrangian_value(x, self.cfg.lagrangian, self._centre(goal))


def make_dynamics(cfg: SwarmConfig, batch: int, dtype: np.dtype) -> Dynamics:
    """The adapter of ``cfg.dynamics`` (its ``ModelSpec.adapter``) for ``batch`` swarms.

    Raises:
        ValueError: ``cfg.dynamics`` is not a registered model (the message lists them).
        TypeError: the registered adapter is not a :class:`Dynamics` subclass.
    """
    spec = model_spec(cfg.dynamics)
    cls = spec.adapter_class()
    if not (isinstance(cls, type) and issubclass(cls, Dynamics)):
        raise TypeError(
            f"ModelSpec({spec.name!r}).adapter must be a subclass of "
            f"swarm_envs.envs.dynamics.Dynamics, got {cls!r}"
        )
    return cls(cfg, batch, dtype)


__all__ = ["DYNAMICS", "Dynamics", "make_dynamics"]
