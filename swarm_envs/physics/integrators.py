"""Time stepping for the second-order force models: ``ṙ = v``, ``m v̇ = F(r, v) + u``.

Three schemes, each one force evaluation per step:

``"semi_implicit_euler"`` (symplectic Euler, the default)
    ``v_{n+1} = v_n + dt (F(r_n, v_n) + u)/m``, ``r_{n+1} = r_n + dt v_{n+1}``.
    Symplectic, global error of order 1 in ``dt``; its energy error stays bounded
    without dissipation instead of drifting.

``"velocity_verlet"``
    kick–drift–kick: ``v_{n+½} = v_n + ½dt a_n``, ``r_{n+1} = r_n + dt v_{n+½}``,
    ``a_{n+1} = a(r_{n+1}, 2v_{n+½} − v_n)``, ``v_{n+1} = v_{n+½} + ½dt a_{n+1}``.
    Symplectic and of order 2 for conservative forces. The velocity-dependent terms
    (alignment, dissipation) are evaluated at the extrapolated velocity
    ``2v_{n+½} − v_n = v_{n+1} + O(dt²)``, which keeps the scheme explicit and of
    order 2; the end-of-step passive force is reused for the next step's first kick.
    A control ``u`` is held constant over each step (zero-order hold).

``"implicit_damping_euler"`` (symplectic Euler with the damping implicit)
    ``v_{n+1} = v_n + dt (a_i + w_i s) / (m + dt c_i)``, ``r_{n+1} = r_n + dt v_{n+1}``,
    with ``a_i = F_i(r_n, v_n) + u_i`` and, per agent
    (:func:`~swarm_envs.physics.social_potential.damping_rates`), the implicit
    dissipation ``b_i`` (the positive part of its rate), the alignment's row sum
    ``w_i = Σ_j w(ρ_ij)`` and ``c_i = b_i + w_i``; per swarm the velocity
    ``s = dt Σ_i w_i a_i/(m + dt c_i) / Σ_i w_i (m + dt b_i)/(m + dt c_i)``, the weighted
    mean increment that the alignment leaves alone (:func:`implicit_damping_update`).
    Each agent's increment ``Δv_i`` solves ``m Δv_i = dt a_i − dt b_i Δv_i
    − dt w_i (Δv_i − s)`` with ``Σ_i w_i (Δv_i − s) = 0``: the damping's terms taken at
    the new velocity, the alignment's against the collective increment ``s``, so that
    a swarm driven as a whole (goal, control) accelerates as the force says and the
    pair forces keep the momentum (``Σ_i m Δv_i = dt Σ_i a_i`` without dissipation).
    Consistent, of order 1, and exactly the semi-implicit Euler step where
    ``b = w = 0``.

Damping is applied per unit of time (``−β v`` inside the force), so halving ``dt``
converges to the same trajectory. The measured orders are checked in the tests.

Step-size control (``docs/models.md`` §7). Linearised about a state, the model is
``q̈ = −K q − D q̇`` with ``K`` the Hessian of the potential and ``D`` the damping of
dissipation and alignment, per unit mass. On one mode, ``q̈ = −ω² q − γ q̇``, a step
``h`` of semi-implicit Euler maps ``(q, v)`` by a matrix of trace ``2 − h²ω² − hγ`` and
determinant ``1 − hγ``; it is stable (Jury's conditions) exactly when

    ``h²ω² + 2hγ < 4``,  i.e.  ``h < 4 / (γ + √(γ² + 4ω²))``

(``γ = 0`` gives the familiar ``hω < 2``, ``ω = 0`` gives ``hγ < 2``). Velocity Verlet
evaluates the damping at the extrapolated velocity and carries the force into the next
step, so a mode is a map of ``(q, v, f)`` whose characteristic polynomial is
``λ³ + (h²ω² + 3hγ/2 − 2) λ² + (1 − 2hγ) λ + hγ/2``; it leaves the unit disc through
``λ = −1``, exactly at ``h²ω² + 4hγ = 4``, so Verlet is stable when

    ``h²ω² + 4hγ < 4``,  i.e.  ``h < 4 / (2γ + √(4γ² + 4ω²))``

(the same ``hω < 2``, but half the damping rate: ``hγ < 1``). The rule takes
``h* = 0.9`` of the integrator's edge (:func:`stable_substep`, :data:`STEP_SAFETY`), with ``ω²`` and
``γ`` bounds on the largest eigenvalues of ``K`` and ``D``
(``swarm_envs.physics.social_potential.pair_rates``; they overestimate by at most a
factor 2, a further margin against the state changing within a substep). An environment
step of length ``dt`` is split into ``n = ⌈τ/h*⌉`` equal substeps of what remains of it
(:func:`substep_plan`), re-planned after every substep from the new state.

Implicit damping. Linearised, the velocity damping is ``D = B + D_w`` (unit mass),
``B = diag(b_i)`` the dissipation's and ``D_w = Σ_{pairs} (e_i − e_j)(e_i − e_j)ᵀ ⊗ w_ij
u uᵀ`` the alignment's. ``"implicit_damping_euler"`` maps an explicit increment ``e``
to ``Δv = T e`` with ``T = P⁻¹ + h P⁻¹ w wᵀ P⁻¹ / Z`` (per component), ``P = I + hC``,
``C = diag(c_i)``, ``Z = Σ_i w_i (1 + h b_i)/(1 + h c_i)``: symmetric positive
definite, with ``T⁻¹ = P − h w wᵀ / Σ_i w_i`` (Sherman–Morrison). Its damping alone maps
``v ↦ (I − hTD) v``, similar to ``I − h T^{½} D T^{½}``: real eigenvalues, at most 1,
above −1 exactly when ``hD < 2T⁻¹``. That holds at every ``h``: ``D_w ⪯ L_w ⊗ I`` (the
Laplacian of the weights ``w_ij``) and ``L_w ⪯ 2W − 2 w wᵀ/Σ_i w_i`` (``W = diag(w_i)``;
the difference is the signless Laplacian ``Σ_{pairs} w_ij (e_i + e_j)(e_i + e_j)ᵀ``
less ``2 w wᵀ/Σ w``, positive semi-definite by Cauchy–Schwarz, as
``w·q = Σ_{pairs} w_ij (q_i + q_j)``), so ``hD − 2T⁻¹ ⪯ −2I − hB ≺ 0``: the damping is
unconditionally stable. On one mode (stiffness ``ω²``, damping ``γ``, implicit
coefficient ``c`` with ``γ ≤ 2c``) the step is a map of trace
``2 − (h²ω² + hγ)/(1 + hc)`` and determinant ``1 − hγ/(1 + hc)``, stable (Jury) exactly
when ``h²ω² + 2hγ < 4(1 + hc)``: at least whenever ``hω < 2``, whatever the damping.
Its rule is ``h* = 0.9 · 2/ω`` (:func:`stable_substep` with ``c = 0``), with ``ω²`` the
block bound of
:func:`~swarm_envs.physics.social_potential.stiffness_rate` (the exact norms of the
pairs' Hessian blocks, block Gershgorin, and the largest eigenvalue of each agent's own
block bounded from its trace and Frobenius norm), tighter than the Gershgorin sum of
:func:`~swarm_envs.physics.social_potential.pair_rates` that the two explicit schemes
keep. A negative dissipation rate (self-propulsion below ``v₀/√3``) stays explicit: it
is a growth of the model itself, not of the scheme.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from swarm_envs._array import namespace
from swarm_envs.physics._validation import check_goal, check_run, check_state
from swarm_envs.physics.social_potential import (
    PairGeometry,
    SocialPotentialParams,
    damping_rates,
    forces,
    pair_geometry,
)

if TYPE_CHECKING:
    import torch

INTEGRATORS = ("semi_implicit_euler", "velocity_verlet", "implicit_damping_euler")

#: A control is a fixed array broadcastable to ``(..., N, d)`` or a function
#: ``control(t, x, v) -> array`` evaluated once per step (zero-order hold).
Control = np.ndarray | Callable[[float, np.ndarray, np.ndarray], np.ndarray] | None


def _check_integrator(integrator: str) -> None:
    if integrator not in INTEGRATORS:
        raise ValueError(f"integrator must be one of {INTEGRATORS}, got {integrator!r}")


#: The rule's substep is this fraction of the stability edge: on the edge itself a mode
#: neither grows nor decays (``hγ = 2`` flips the velocity's sign without damping it),
#: and round-off may tip it over.
STEP_SAFETY = 0.9

#: The weight ``c`` of the damping rate in each integrator's stability edge
#: ``h²ω² + 2c·hγ < 4`` (module docstring).
_DAMPING_WEIGHT = {
    "semi_implicit_euler": 1.0,
    "velocity_verlet": 2.0,
    "implicit_damping_euler": 0.0,
}


def stable_substep(
    omega2: Any, gamma: Any, xp: Any = np, integrator: str = "semi_implicit_euler"
) -> Any:
    """``h* = σ · 4 / (cγ + √(c²γ² + 4ω²))``, ``σ = STEP_SAFETY``: the substep the rule
    takes for the stiffness ``ω² ≥ 0`` and damping rate ``γ ≥ 0``, a fraction of the
    longest stable step of ``integrator`` (see the module docstring): ``c = 1`` for
    semi-implicit Euler, ``c = 2`` for velocity Verlet, whose explicit damping is stable
    only up to ``hγ < 1``.

    Elementwise on numpy arrays or torch tensors (``xp``: ``np`` or ``torch``). ``inf``
    where both rates are 0 (any step is stable) and, so that a non-finite state takes
    one substep and is caught by the caller's finiteness check, where a rate is NaN;
    0 where a rate is ``inf`` (no step is stable). ``c = 0`` for
    ``"implicit_damping_euler"``, whose damping is unconditionally stable:
    ``h* = σ · 2/ω``, and ``γ`` is not read.

    >>> round(float(stable_substep(np.float64(100.0), np.float64(0.0))), 6)  # hω < 2, ω = 10
    0.18
    >>> round(float(stable_substep(np.float64(0.0), np.float64(4.0))), 6)  # h·γ < 2
    0.45
    >>> verlet = stable_substep(np.float64(0.0), np.float64(4.0), integrator="velocity_verlet")
    >>> round(float(verlet), 6)  # h·γ < 1
    0.225
    """
    _check_integrator(integrator)
    c = _DAMPING_WEIGHT[integrator]
    if c == 0.0:
        den = 2.0 * xp.sqrt(omega2)
        ok = den > 0
        return xp.where(ok, (4.0 * STEP_SAFETY) / xp.where(ok, den, 1.0), math.inf)
    cg = gamma if c == 1.0 else c * gamma
    den = cg + xp.sqrt(cg * cg + 4.0 * omega2)
    ok = den > 0
    return xp.where(ok, (4.0 * STEP_SAFETY) / xp.where(ok, den, 1.0), math.inf)


def substep_plan(remaining: Any, h_stable: Any, xp: Any = np) -> tuple[Any, Any]:
    """``(n, h)``: the equal substeps ``n = ⌈τ/h*⌉`` still needed for the time ``τ ≥ 0``
    left of an environment step, and their length ``h = τ/n`` (both 0 where ``τ = 0``).

    ``n`` is a float array, ``inf`` where no step is stable (``h* = 0``; then ``h = 0``).
    The relative slack of ``1e-9`` keeps a ratio that is an integer up to round-off at
    that integer, so that every backend counts alike.

    >>> n, h = substep_plan(np.array([0.1, 0.1, 0.0]), np.array([0.2, 0.03, 0.01]))
    >>> n.tolist(), [round(float(t), 4) for t in h]
    ([1.0, 4.0, 0.0], [0.1, 0.025, 0.0])
    """
    ratio = xp.where(h_stable > 0, remaining / xp.where(h_stable > 0, h_stable, 1.0), math.inf)
    n = xp.where(remaining > 0, xp.ceil(ratio * (1.0 - 1e-9)), 0.0)
    n = xp.where(remaining > 0, xp.where(n < 1.0, 1.0, n), 0.0)
    finite = (n > 0) & (n < math.inf)
    h = xp.where(finite, remaining / xp.where(finite, n, 1.0), 0.0)
    return n, h


class SubstepBudget:
    """The substeps of one step of length ``dt`` for ``batch`` swarms, at most ``cap`` each.

    Per swarm: the time ``remaining``, the substeps ``used``, whether the step went
    ``over`` the cap, and the substeps it ``needed`` (at least). :meth:`plan` gives the
    next substep of the swarms ``rows`` (:func:`substep_plan`; a swarm that needs more than
    it has left is marked over the cap and takes its remaining time in the substeps left);
    :meth:`spend` books it and says which of them are done.

    >>> budget = SubstepBudget(2, 0.1, cap=3)
    >>> rows = np.arange(2)
    >>> n, h = budget.plan(rows, np.array([0.2, 0.01]))
    >>> n.tolist(), budget.over.tolist(), budget.needed.tolist()
    ([1.0, 3.0], [False, True], [1.0, 10.0])
    """

    def __init__(self, batch: int, dt: float, cap: int) -> None:
        self.cap = cap
        self.remaining = np.full(batch, dt)
        self.used = np.zeros(batch)
        self.over = np.zeros(batch, dtype=bool)
        self.needed = np.zeros(batch)

    def plan(self, rows: np.ndarray, h_stable: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(n, h)`` of the swarms ``rows`` given their stable substeps ``h_stable``."""
        remaining = self.remaining[rows]
        n, h = substep_plan(remaining, h_stable)
        self.needed[rows] = np.maximum(self.needed[rows], self.used[rows] + n)
        left = self.cap - self.used[rows]
        late = n > left
        if late.any():
            self.over[rows[late]] = True
            h = np.where(late, remaining / np.maximum(left, 1.0), h)
            n = np.where(late, np.maximum(left, 1.0), n)
        return n, h

    def spend(
        self, rows: np.ndarray, n: np.ndarray, h: np.ndarray, stop: np.ndarray | None = None
    ) -> np.ndarray:
        """Book one substep ``h`` of the swarms ``rows`` (``n``: what :meth:`plan` gave);
        ``stop`` ends a swarm's step early. Returns which of ``rows`` are done."""
        self.used[rows] += 1
        last = n <= 1 if stop is None else (n <= 1) | stop
        self.remaining[rows] = np.where(last, 0.0, self.remaining[rows] - h)
        return self.remaining[rows] == 0


def euler_update(
    x: Any, v: Any, accel: Any, dt: float | np.ndarray | torch.Tensor, m: float
) -> tuple[Any, Any]:
    """The semi-implicit Euler update with the force ``accel`` (passive + control):
    ``v' = v + dt · accel/m``, ``x' = x + dt v'``. numpy arrays or torch tensors; ``dt``
    one step length, or an array of them broadcastable to ``x`` (each swarm's own
    substep, ``(B, 1, 1)``)."""
    if m != 1.0:
        accel = accel / m
    v_new = v + dt * accel
    return x + dt * v_new, v_new


def implicit_damping_update(
    x: Any, v: Any, accel: Any, dt: Any, m: float, own: Any, align: Any, axis: int = -2
) -> tuple[Any, Any]:
    """The ``"implicit_damping_euler"`` update (the module docstring) with the force
    ``accel`` (passive + control) and the agents' implicit dissipation ``own`` (``b_i``)
    and alignment row sums ``align`` (``w_i``;
    :func:`~swarm_envs.physics.social_potential.damping_rates`; 0 for an agent held at
    rest, whose ``accel`` is 0 too):

    ``s = dt Σ_i w_i a_i/(m + dt c_i) / Σ_i w_i (m + dt b_i)/(m + dt c_i)`` (0 where no
    agent aligns), ``v' = v + dt (a_i + w_i s)/(m + dt c_i)``, ``x' = x + dt v'``.

    numpy arrays or torch tensors: ``x, v, accel`` ``(..., N, d)`` with ``own, align``
    ``(..., N, 1)`` and ``axis=-2`` (the agents' axis), or one component ``(..., N)``
    with ``own, align`` ``(..., N)`` and ``axis=-1``; ``dt`` as in
    :func:`euler_update`, broadcastable to ``x``.
    """
    xp = namespace(x)
    den = m + dt * (own + align)
    num = xp.sum(align * dt * accel / den, axis=axis)
    z = xp.sum(align * (m + dt * own) / den, axis=axis)
    s = xp.where(z > 0, num / xp.where(z > 0, z, 1.0), 0.0)
    s = s[..., None, :] if axis == -2 else s[..., None]
    v_new = v + dt * (accel + align * s) / den
    return x + dt * v_new, v_new


def implicit_damping_step(
    x: Any,
    v: Any,
    params: SocialPotentialParams,
    *,
    dt: float,
    goal: Any | None = None,
    control: Any | None = None,
    geometry: PairGeometry | None = None,
) -> tuple[Any, Any]:
    """One ``"implicit_damping_euler"`` step of the social potential model (the module
    docstring; :func:`implicit_damping_update` with
    :func:`~swarm_envs.physics.social_potential.damping_rates` of ``(x, v)``); the
    arguments as :func:`step`."""
    geo = pair_geometry(x) if geometry is None else geometry
    accel = forces(x, v, params, goal, geometry=geo)
    if control is not None:
        accel = accel + control
    own, align = damping_rates(geo, v, params)
    return implicit_damping_update(x, v, accel, dt, params.m, own[..., None], align[..., None])


def step(
    x: Any,
    v: Any,
    params: SocialPotentialParams,
    *,
    dt: float,
    goal: Any | None = None,
    control: Any | None = None,
    geometry: PairGeometry | None = None,
) -> tuple[Any, Any]:
    """One semi-implicit (symplectic) Euler step of the social potential model.

    ``v' = v + dt (F(x, v) + u)/m``, ``x' = x + dt v'`` (:func:`euler_update`).
    ``control`` is the force ``u`` added to the passive force (``None`` or zeros leave
    the passive physics untouched). ``geometry`` is ``pair_geometry(x)`` when the
    caller has it. numpy arrays or torch tensors; returns new arrays ``(x', v')``, the
    inputs are not modified.
    """
    accel = forces(x, v, params, goal, geometry=geometry)
    if control is not None:
        accel = accel + control
    return euler_update(x, v, accel, dt, params.m)


def verlet_step(
    x: np.ndarray,
    v: np.ndarray,
    f: np.ndarray,
    params: SocialPotentialParams,
    *,
    dt: float | np.ndarray,
    goal: np.ndarray | None = None,
    control: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, PairGeometry]:
    """One velocity-Verlet step; ``f`` is the passive force carried from the last step.

    ``dt`` is one step length, or an array of them broadcastable to ``x`` (each swarm's
    own substep, ``(B, 1, 1)``).

    The control ``u`` is held over the step (both half-kicks). Returns
    ``(x', v', f', geometry')`` where ``f'`` is the passive force at ``x'`` and the
    extrapolated velocity ``2v_{n+½} − v_n`` (carry it into the next call), and
    ``geometry' = pair_geometry(x')``. Start with ``f = forces(x0, v0, params, goal)``.
    """
    a = f if control is None else f + control
    v_half = v + (0.5 * dt / params.m) * a
    x_new = x + dt * v_half
    geometry = pair_geometry(x_new)
    f_new = forces(x_new, 2.0 * v_half - v, params, goal, geometry=geometry)
    a_new = f_new if control is None else f_new + control
    v_new = v_half + (0.5 * dt / params.m) * a_new
    return x_new, v_new, f_new, geometry


def simulate(
    params: SocialPotentialParams,
    x0: Any,
    v0: Any,
    *,
    dt: float,
    steps: int,
    goal: Any | None = None,
    control: Control = None,
    rng: np.random.Generator | None = None,
    integrator: str = "semi_implicit_euler",
) -> tuple[np.ndarray, np.ndarray]:
    """Integrate the model from ``(x0, v0)`` for ``steps`` steps of length ``dt``.

    The type of ``params`` selects the model: :class:`SocialPotentialParams` (this
    module), or the parameter class of another registered model, whose own simulator
    runs (``ModelSpec.simulate`` of :mod:`swarm_envs.models`: ``ZoneParams`` →
    :func:`~swarm_envs.physics.zone.simulate_zone`, ``PiecewiseParams`` →
    :func:`~swarm_envs.physics.piecewise.simulate_piecewise`, ``LagrangianParams`` →
    :func:`~swarm_envs.physics.lagrangian.simulate_lagrangian`, and a user's model).

    Args:
        params: model parameters (its type selects the model).
        x0, v0: initial positions and velocities ``(..., N, d)``.
        dt: time step, ``> 0``.
        steps: number of steps, ``≥ 0``.
        goal: goal-sink position broadcastable to ``(..., d)`` (used when ``C_g > 0``).
        control: extra force ``u`` (array, or ``control(t, x, v)``), held over each step.
        rng: randomness of the stochastic models (zone, piecewise); the social potential
            model is deterministic and ignores it.
        integrator: one of :data:`INTEGRATORS`.

    Returns:
        ``(xs, vs)``, each shaped ``(steps + 1, ..., N, d)``; index 0 is the start.

    >>> xs, vs = simulate(SocialPotentialParams(), np.zeros((3, 2)), np.zeros((3, 2)),
    ...                   dt=0.1, steps=4)
    >>> xs.shape
    (5, 3, 2)
    """
    if not isinstance(params, SocialPotentialParams):
        other = _model_simulator(params)
        if control is not None or integrator != "semi_implicit_euler":
            raise ValueError(
                f"simulate: control= and integrator= apply to SocialPotentialParams only, "
                f"not to {type(params).__name__}"
            )
        return other(params, x0, v0, dt=dt, steps=steps, goal=goal, rng=rng)
    del rng  # deterministic model
    dt, steps = check_run("simulate", dt, steps)
    _check_integrator(integrator)
    x, v = check_state(x0, v0)
    if goal is not None:
        goal = check_goal(goal, x)
    xs = np.empty((steps + 1, *x.shape), dtype=x.dtype)
    vs = np.empty_like(xs)
    xs[0], vs[0] = x, v

    def control_at(n: int, xn: np.ndarray, vn: np.ndarray) -> np.ndarray | None:
        if control is None:
            return None
        u = control(n * dt, xn, vn) if callable(control) else control
        return np.asarray(u, dtype=x.dtype)

    if integrator != "velocity_verlet":
        one = step if integrator == "semi_implicit_euler" else implicit_damping_step
        for n in range(steps):
            x, v = one(x, v, params, dt=dt, goal=goal, control=control_at(n, x, v))
            xs[n + 1], vs[n + 1] = x, v
        return xs, vs

    f = forces(x, v, params, goal)
    for n in range(steps):
        x, v, f, _ = verlet_step(x, v, f, params, dt=dt, goal=goal, control=control_at(n, x, v))
        xs[n + 1], vs[n + 1] = x, v
    return xs, vs


def _model_simulator(params: Any) -> Callable[..., tuple[np.ndarray, np.ndarray]]:
    """The simulator of the registered model whose parameter class ``params`` has.

    The registry (:mod:`swarm_envs.models`) imports the physics modules, so it is read
    here, at the call, not at import; it imports nothing above the physics."""
    from swarm_envs.models import model_names, model_spec, spec_for_params

    spec = spec_for_params(params)
    if spec is None:
        known = ", ".join(model_spec(name).params.__name__ for name in model_names())
        raise ValueError(
            f"simulate: unsupported parameter type {type(params).__name__}; expected one of {known}"
        )
    return spec.simulate
