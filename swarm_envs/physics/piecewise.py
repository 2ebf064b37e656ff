"""Piecewise force model with the λ nearest neighbours (Viscido et al., as in Naterop §4.2).

Reference: Naterop, Petrides & Prasad, *Implementing two mathematical swarm models…*
(seed ``003``), §4.2 (eqs. 15–18, table 2), after Viscido, Parrish & Grünbaum. The reading
is the consistent one documented in ``docs/models.md`` §4; the equation of motion is

``m r̈_i = Σ_{j ∈ λ nearest of i} F(ρ_ij) u_ij + ξ_i − β v_i``

(eq. 15 with eq. 17's sum over the ``λ`` closest neighbours, eq. 18's random force
``ξ_i ~ N(0, σ²)`` per component with ``σ = noise · F_max / 6``, and a linear drag
``−β v_i`` that the report does not have but names as its fix, §5.1 and §6). The pair
force along ``u_ij`` (eq. 16, positive = pulled toward j) is

===========================  ==================================
``ρ < r_r``                  ``−F_max (1 − ρ/r_r)``  (repulsion)
``r_r ≤ ρ < r_0``            ``0``                   (equilibrium band)
``r_0 ≤ ρ < r_a``            ``F_max (ρ − r_0)/(r_a − r_0)``
``r_a ≤ ρ < R``              ``F_max``
``R ≤ ρ``                    ``0``
===========================  ==================================

It is continuous except at ``ρ = R`` (a jump from ``F_max`` to 0) and, when
``r_0 = r_a``, at ``r_0`` (a jump from 0 to ``F_max``). Departures from the printed
text (``docs/models.md`` §4): eq. 16 prints the repulsion as ``g_r ρ − F_max`` with
``g_r = F_max / r_a`` (which does not reach 0 at ``r_r``) and the attraction ramp as
``g_a (ρ − r_a)`` (negative on its own interval); table 2 lists ``g_r = 1``,
``g_a = 5 s⁻²``, consistent with neither. We use the slopes that make the curve of the
report's Fig. 2 (and its own prose: "increases linearly … until it reaches zero",
"… until it reaches +F_max at r_a"): ``g_r = F_max / r_r`` and
``g_a = F_max / (r_a − r_0)`` (properties of :class:`PiecewiseParams`).

Notation as in :mod:`swarm_envs.physics.social_potential`: ``r_ij = r_j − r_i``,
``ρ_ij = |r_ij|``, ``u_ij = r_ij / ρ_ij``. Arrays are ``(..., N, d)``, ``d`` in {2, 3};
nothing loops over agents or pairs in Python: the ``λ`` nearest are found with
:func:`numpy.argpartition` on the ``(..., N, N)`` distance array.

Conventions:

- **Neighbours.** The ``λ`` nearest *other* agents, whatever their distance (those
  beyond ``R`` then exert nothing); with ``N − 1 ≤ λ`` every other agent counts.
  Ties at exactly equal distances are broken by ``argpartition`` (deterministically
  for a given input). The relation is not symmetric, so the pair forces are not
  antisymmetric: neither momentum nor energy is conserved, even with ``β = 0`` and
  no noise.
- **Coincident agents** (``ρ_ij = 0``): ``u_ij`` is undefined and taken as ``0``
  (the distance is floored at :data:`~swarm_envs.physics.social_potential.RHO_FLOOR`
  and ``r_ij = 0`` makes the product zero), so a coincident neighbour exerts no force,
  although it still takes one of the ``λ`` slots. Nothing returns NaN.
- **Random force.** ``ξ`` is drawn once per call of :func:`piecewise_forces` (once per
  step in :func:`simulate_piecewise`) from the :class:`numpy.random.Generator` passed
  in, and held over the step, as the report does. Its effect on the velocity is
  therefore ``dt ξ`` per step: the velocity variance it injects per unit time is
  ``σ² dt / m²``, so a smaller step also means weaker effective noise (it is not a
  Wiener-process / Langevin scaling).
- **Goal.** The passive model has no goal force; :func:`simulate_piecewise` accepts
  ``goal`` (validated) for a uniform signature and ignores it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from swarm_envs.physics._validation import check_goal, check_real, check_run, check_state
from swarm_envs.physics.social_potential import RHO_FLOOR, pair_geometry

__all__ = [
    "PiecewiseParams",
    "force_law",
    "interaction_forces",
    "nearest_neighbors",
    "piecewise_forces",
    "piecewise_rates",
    "random_force",
    "simulate_piecewise",
]

#: A control is a fixed array broadcastable to ``(..., N, d)`` or a function
#: ``control(t, x, v) -> array`` evaluated once per step (zero-order hold).
Control = np.ndarray | Callable[[float, np.ndarray, np.ndarray], np.ndarray] | None


@dataclass(frozen=True)
class PiecewiseParams:
    """Parameters of the piecewise force model (Naterop §4.2, eqs. 15–18, table 2).

    All fields are validated on construction: a non-finite or out-of-range value raises
    :class:`ValueError` naming the field and the allowed range; the radii must satisfy
    ``0 < r_r ≤ r_0 ≤ r_a ≤ R``.

    Defaults are table 2 (``N = 100`` is the caller's), with ``r_0 = 5`` picked inside
    the report's range 1–15, and ``β = 0`` (the report's model, which disperses).

    >>> PiecewiseParams().sigma  # F_max / 6
    16.666666666666668
    >>> PiecewiseParams(n_neighbors=0)
    Traceback (most recent call last):
    ...
    ValueError: PiecewiseParams.n_neighbors must be an integer in [1, inf), got 0
    """

    F_max: float = 100.0
    """Maximum force magnitude ``F_max`` (eq. 16, table 2: 100), ``≥ 0``."""
    r_r: float = 1.0
    """Repulsion distance ``r_r`` (eq. 16, table 2: 1 m), ``> 0``."""
    r_0: float = 5.0
    """Equilibrium distance ``r_0``: the zero-force band is ``[r_r, r_0)`` (eq. 16;
    table 2 sweeps 1–15 m), in ``[r_r, r_a]``."""
    r_a: float = 20.0
    """Attraction distance ``r_a``: the force reaches ``F_max`` here (eq. 16, table 2:
    20 m), in ``[r_0, R]``."""
    R: float = 30.0
    """Maximum distance of influence ``R`` (eq. 16, table 2: 30 m), ``≥ r_a``."""
    n_neighbors: int = 8
    """Number ``λ`` of nearest neighbours that act on an agent (eq. 17, table 2: 8),
    an integer ``≥ 1``."""
    noise: float = 1.0
    """Scale of the random force (eq. 18) relative to the report's ``σ = F_max / 6``:
    ``ξ_i ~ N(0, (noise · F_max / 6)²)`` per component; 0 switches it off, ``≥ 0``."""
    beta: float = 0.0
    """Linear drag coefficient ``β`` of the force ``−β v_i`` (not in the report, which
    names it as the fix, §5.1); 0 is the report's model, ``≥ 0``."""
    m: float = 1.0
    """Mass of every agent (the report's ``F_max`` is in m s⁻², i.e. unit mass), ``> 0``."""

    def __post_init__(self) -> None:
        owner = type(self).__name__
        for name in ("F_max", "noise", "beta"):
            object.__setattr__(self, name, check_real(owner, name, getattr(self, name), low=0.0))
        for name in ("r_r", "m"):
            value = check_real(owner, name, getattr(self, name), low=0.0, low_inclusive=False)
            object.__setattr__(self, name, value)
        for name in ("r_0", "r_a", "R"):
            object.__setattr__(self, name, check_real(owner, name, getattr(self, name), low=0.0))
        order = "(0 < r_r <= r_0 <= r_a <= R)"
        if not self.r_0 >= self.r_r or not self.r_0 <= self.r_a:
            raise ValueError(
                f"{owner}.r_0 must be in [r_r, r_a] = [{self.r_r:g}, {self.r_a:g}] {order}, "
                f"got {self.r_0!r}"
            )
        if not self.r_a <= self.R:
            raise ValueError(
                f"{owner}.r_a must be in [r_0, R] = [{self.r_0:g}, {self.R:g}] {order}, "
                f"got {self.r_a!r}"
            )
        k = self.n_neighbors
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
            raise ValueError(f"{owner}.n_neighbors must be an integer in [1, inf), got {k!r}")
        object.__setattr__(self, "n_neighbors", int(k))

    @classmethod
    def navigation(cls, **overrides: Any) -> PiecewiseParams:
        """The SwarmNav default (``dynamics="piecewise"``): table 2 scaled to the task.

        Lengths shrink about 1:7 (``r_r = 0.6, r_0 = 1, r_a = 2, R = 4`` m), the force to
        ``F_max = 3`` (the action bound, so that repulsion holds against a full push),
        the noise to a fifth of the report's ``σ`` and ``λ = 6``; the drag ``β = 1.5`` is
        the report's proposed fix (§5.1), which keeps the group bounded.
        """
        values: dict[str, Any] = {
            "F_max": 3.0,
            "r_r": 0.6,
            "r_0": 1.0,
            "r_a": 2.0,
            "R": 4.0,
            "n_neighbors": 6,
            "noise": 0.2,
            "beta": 1.5,
        }
        return cls(**{**values, **overrides})

    @property
    def sigma(self) -> float:
        """Standard deviation of each component of the random force, ``noise · F_max / 6``."""
        return self.noise * self.F_max / 6.0

    @property
    def g_r(self) -> float:
        """Repulsion slope ``F_max / r_r`` (the consistent reading of eq. 16)."""
        return self.F_max / self.r_r

    @property
    def g_a(self) -> float:
        """Attraction slope ``F_max / (r_a − r_0)`` (``inf`` when ``r_0 = r_a``: a step)."""
        return self.F_max / (self.r_a - self.r_0) if self.r_a > self.r_0 else math.inf

    @property
    def lam(self) -> int:
        """``λ``, the paper's name for :attr:`n_neighbors`."""
        return self.n_neighbors


def force_law(rho: Any, params: PiecewiseParams) -> np.ndarray:
    """The scalar pair force ``F(ρ)`` of eq. 16 (``docs/models.md`` §4), elementwise.

    Positive values attract (toward the neighbour), negative values repel. ``rho`` is
    a distance (``≥ 0``) of any shape; a floating array keeps its dtype.

    >>> p = PiecewiseParams(F_max=100.0, r_r=1.0, r_0=5.0, r_a=20.0, R=30.0)
    >>> force_law(np.array([0.0, 0.5, 1.0, 3.0, 5.0, 12.5, 20.0, 29.0, 30.0]), p).tolist()
    [-100.0, -50.0, 0.0, 0.0, 0.0, 50.0, 100.0, 100.0, 0.0]
    """
    rho = np.asarray(rho)
    if not np.issubdtype(rho.dtype, np.floating):
        rho = rho.astype(np.float64)
    p = params
    # −F_max (1 − ρ/r_r) below r_r, 0 above (continuous at r_r).
    repulsion = np.minimum(rho * (1.0 / p.r_r) - 1.0, 0.0)
    # F_max · clip((ρ − r_0)/(r_a − r_0), 0, 1): the ramp and the plateau.
    if p.r_a > p.r_0:
        attraction = np.clip((rho - p.r_0) * (1.0 / (p.r_a - p.r_0)), 0.0, 1.0)
    else:  # r_0 = r_a: a step from 0 to F_max
        attraction = (rho >= p.r_a).astype(rho.dtype)
    out = np.where(rho < p.R, repulsion + attraction, 0.0).astype(rho.dtype, copy=False)
    out *= p.F_max
    return out


def nearest_neighbors(rho: np.ndarray, n_neighbors: int) -> np.ndarray:
    """Indices of the ``λ`` nearest other agents, shaped ``(..., N, min(λ, N − 1))``.

    ``rho`` is the ``(..., N, N)`` distance array. An agent is never its own neighbour;
    the order within the last axis is unspecified. Uses :func:`numpy.argpartition`
    (``O(N²)`` per swarm), no Python loop.

    >>> rho = np.array([[0.0, 1.0, 5.0], [1.0, 0.0, 2.0], [5.0, 2.0, 0.0]])
    >>> nearest_neighbors(rho, 1)[:, 0].tolist()
    [1, 0, 1]
    """
    n = rho.shape[-1]
    k = min(int(n_neighbors), n - 1)
    if k <= 0:
        return np.zeros((*rho.shape[:-1], 0), dtype=np.intp)
    masked = rho.copy()
    idx = np.arange(n)
    masked[..., idx, idx] = np.inf
    if k == n - 1:
        # Every other agent: the self entry (inf) sorts last.
        return np.argsort(masked, axis=-1, kind="stable")[..., :k]
    return np.argpartition(masked, k - 1, axis=-1)[..., :k]


def interaction_forces(x: Any, params: PiecewiseParams) -> np.ndarray:
    """Member–member force ``Σ_{λ nearest j} F(ρ_ij) u_ij`` (eqs. 16–17), shaped like ``x``.

    Args:
        x: positions ``(..., N, d)``, ``d`` in {2, 3}; float32 stays float32.
        params: model parameters.

    >>> x = np.array([[0.0, 0.0], [10.0, 0.0]])
    >>> interaction_forces(x, PiecewiseParams(r_0=5.0, r_a=15.0)).tolist()  # F(10) = 50
    [[50.0, 0.0], [-50.0, 0.0]]
    """
    x, _ = check_state(x)
    d = x.shape[-1]
    if x.shape[-2] < 2:
        return np.zeros_like(x)
    geo = pair_geometry(x)
    nb = nearest_neighbors(geo.rho, params.n_neighbors)
    rho_nb = np.take_along_axis(geo.rho, nb, axis=-1)
    scalar = force_law(rho_nb, params)
    scalar /= np.maximum(rho_nb, RHO_FLOOR)  # F(ρ)/ρ, times r_ij gives F(ρ) u_ij
    comps = [
        np.einsum("...ij,...ij->...i", scalar, np.take_along_axis(geo.dx[k], nb, axis=-1))
        for k in range(d)
    ]
    return np.stack(comps, axis=-1).astype(x.dtype, copy=False)


def _check_rng(rng: Any, where: str) -> np.random.Generator:
    if not isinstance(rng, np.random.Generator):
        raise ValueError(
            f"{where}: rng must be a numpy.random.Generator when the random force is on "
            f"(PiecewiseParams.noise > 0 and F_max > 0), got {rng!r}"
        )
    return rng


def random_force(
    rng: np.random.Generator, shape: tuple[int, ...], params: PiecewiseParams, dtype: Any
) -> np.ndarray:
    """The random force ``ξ ~ N(0, σ²)`` per component (eq. 18), ``σ = noise · F_max / 6``.

    Drawn from ``rng`` with the given ``shape`` (``(..., N, d)``) and dtype.
    """
    xi = rng.standard_normal(shape, dtype=np.dtype(dtype))
    xi *= params.sigma
    return xi


def piecewise_forces(
    x: Any,
    v: Any,
    params: PiecewiseParams,
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """Total force on every agent: ``Σ_{λ nearest j} F(ρ_ij) u_ij + ξ_i − β v_i``.

    Naterop §4.2, eq. 15 (with eqs. 16–18) plus the drag ``−β v_i`` (``docs/models.md`` §4).

    Args:
        x: positions ``(..., N, d)``, ``d`` in {2, 3}; float32 stays float32.
        v: velocities, same shape.
        params: model parameters.
        rng: the generator the random force ``ξ`` is drawn from (one draw of shape
            ``x.shape``); required when ``params.sigma > 0``, ignored otherwise.

    Returns:
        Forces shaped like ``x`` (not divided by the mass).

    Raises:
        ValueError: if the random force is on and ``rng`` is not a Generator.

    >>> x = np.array([[0.0, 0.0], [0.5, 0.0]])
    >>> piecewise_forces(x, np.zeros_like(x), PiecewiseParams(noise=0.0)).tolist()
    [[-50.0, 0.0], [50.0, 0.0]]
    """
    x, v = check_state(x, v)
    noise_rng = _check_rng(rng, "piecewise_forces") if params.sigma > 0 else None
    total = interaction_forces(x, params)
    if noise_rng is not None:
        total += random_force(noise_rng, x.shape, params, x.dtype)
    if params.beta > 0:
        total -= params.beta * v
    return total


def piecewise_rates(params: PiecewiseParams) -> tuple[float, float]:
    """``(ω², γ)``: Gershgorin bounds of the model's stiffness and damping, per unit mass.

    Each of an agent's ``λ`` acting neighbours contributes at most the force law's
    steepest slope, ``F_max/r_r`` (repulsion) or ``F_max/(r_a − r_0)`` (the ramp), and,
    the relation being one-way, each pair enters one row twice at most:
    ``ω² = 2 λ max slope / m``; ``γ = β/m``. They do not depend on the state, so a
    step's substeps are fixed by the parameters
    (:func:`~swarm_envs.physics.integrators.stable_substep`).

    >>> piecewise_rates(PiecewiseParams(F_max=3.0, r_r=0.6, r_0=1.0, r_a=2.0, n_neighbors=6,
    ...                                 beta=1.5))
    (60.0, 1.5)
    """
    p = params
    slope = p.F_max / p.r_r
    if p.r_a > p.r_0:
        slope = max(slope, p.F_max / (p.r_a - p.r_0))
    return 2.0 * p.n_neighbors * slope / p.m, p.beta / p.m


def simulate_piecewise(
    params: PiecewiseParams,
    x0: Any,
    v0: Any,
    *,
    dt: float,
    steps: int,
    goal: Any | None = None,
    rng: np.random.Generator | None = None,
    control: Control = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Integrate the piecewise model with semi-implicit (symplectic) Euler.

    ``v_{n+1} = v_n + dt (F(x_n, v_n) + ξ_n + u_n)/m``, ``x_{n+1} = x_n + dt v_{n+1}``,
    with ``F`` from :func:`piecewise_forces` (interaction and drag) and a fresh random
    force ``ξ_n`` drawn from ``rng`` every step. The drag is explicit: keep
    ``β dt / m < 1`` (a larger value over-corrects the velocity each step).

    Args:
        params: model parameters.
        x0, v0: initial positions and velocities ``(..., N, d)``; float32 stays float32.
        dt: time step, ``> 0``.
        steps: number of steps, ``≥ 0``.
        goal: accepted (and checked to broadcast to ``(..., d)``) for the uniform
            signature of :func:`swarm_envs.physics.simulate`; the passive model has no
            goal force and ignores it.
        rng: generator of the random force; required when ``params.sigma > 0``.
            Same generator state, same run (bit for bit).
        control: extra force ``u`` (array broadcastable to ``(..., N, d)``, or
            ``control(t, x, v)``), held over each step; ``None`` for the passive model.

    Returns:
        ``(xs, vs)``, each shaped ``(steps + 1, ..., N, d)``; index 0 is the start.

    >>> p = PiecewiseParams(noise=0.0, beta=1.0)
    >>> xs, vs = simulate_piecewise(p, np.zeros((3, 2)), np.zeros((3, 2)), dt=0.01, steps=4)
    >>> xs.shape
    (5, 3, 2)
    """
    if not isinstance(params, PiecewiseParams):
        raise ValueError(
            f"simulate_piecewise: unsupported parameter type {type(params).__name__}; "
            "expected PiecewiseParams"
        )
    dt, steps = check_run("simulate_piecewise", dt, steps)
    x, v = check_state(x0, v0)
    if goal is not None:
        check_goal(goal, x)  # validated only: the passive model has no goal force
    if params.sigma > 0:
        rng = _check_rng(rng, "simulate_piecewise")
    xs = np.empty((steps + 1, *x.shape), dtype=x.dtype)
    vs = np.empty_like(xs)
    xs[0], vs[0] = x, v
    inv_m = 1.0 / params.m
    for n in range(steps):
        accel = piecewise_forces(x, v, params, rng)
        if control is not None:
            u = control(n * dt, x, v) if callable(control) else control
            accel += np.asarray(u, dtype=x.dtype)
        if inv_m != 1.0:
            accel *= inv_m
        v = v + dt * accel
        x = x + dt * v
        xs[n + 1], vs[n + 1] = x, v
    return xs, vs
