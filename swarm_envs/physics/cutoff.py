"""A cut-off radius for the social potential's pair terms, its error bound, and the
forces and energy summed over a list of pairs (for large swarms).

Every pair term of the social potential model (``docs/models.md`` §1; Mabrouk & McInnes
eqs. 9–11) decays exponentially with the distance ``ρ = ρ_ij``. The force on ``i`` from
``j`` is ``f_ij u_ij`` with

``f_ij = (C_a/l_a) e^{−ρ/l_a} − (C_r/l_r) e^{−ρ/l_r} − C_o ((v_i − v_j)·u_ij) e^{−ρ/l_o}``

(cohesion, eq. 10; alignment, eq. 11), and the pair potential is
``U(ρ) = C_r e^{−ρ/l_r} − C_a e^{−ρ/l_a}`` (eq. 9). Dissipation (eq. 12) and the goal
sink (eqs. 19–21) act per agent and are not truncated.

**Per pair.** For ``a, b ≥ 0``, ``|a − b| ≤ max(a, b) ≤ a + b``, and
``|(v_i − v_j)·u_ij| ≤ |v_i − v_j| ≤ w``; so every pair at distance ``ρ`` whose
relative speed is at most ``w`` has

``|f_ij| ≤ g(ρ; w) = (C_a/l_a) e^{−ρ/l_a} + (C_r/l_r) e^{−ρ/l_r} + C_o w e^{−ρ/l_o}``
(:func:`pair_force_bound`), ``|U(ρ)| ≤ u(ρ) = C_r e^{−ρ/l_r} + C_a e^{−ρ/l_a}``.

``g`` decreases in ``ρ``. :func:`cutoff_radius` returns the smallest ``r_c`` with
``g(r_c; w) ≤ tol``: every pair term dropped by the cut-off (``ρ > r_c``) is then
below ``tol``, in force units, for relative speeds up to ``w``. Because the terms
are independent exponentials the alignment term sets ``r_c`` whenever ``C_o w`` is
comparable to ``C_a / l_a`` and ``l_o > l_a`` (the paper's parameters).

**Per agent** (:func:`force_error_bound`). The force error on agent ``i`` is
``|F_i − F_i^{cut}| ≤ Σ_{j: ρ_ij > r_c} g(ρ_ij; w)``, bounded two ways:

* by the number of agents, with no assumption: ``≤ (N − 1) g(r_c; w)``;
* by a density ``n``: if every ball of radius ``ρ ≥ r_c`` centred on an agent holds at
  most ``n ω_d ρ^d`` other agents (``ω_2 = π``, ``ω_3 = 4π/3``), then, writing the sum
  as a Stieltjes integral over the neighbour count and integrating by parts,
  ``≤ n Σ_t A_t Φ_d(r_c, l_t)`` over the terms ``(A_t, l_t) = (C_a/l_a, l_a),
  (C_r/l_r, l_r), (C_o w, l_o)``, with
  ``Φ_2(r, l) = π e^{−r/l} (r² + 2lr + 2l²)`` and
  ``Φ_3(r, l) = (4π/3) e^{−r/l} (r³ + 3lr² + 6l²r + 6l³)``.

Both hold for every agent; the smaller one is returned. The density form is the useful
one for large swarms: it does not grow with ``N``. The same argument bounds the
potential energy error of a swarm by ``(N(N − 1)/2) u(r_c)`` or
``(N/2) n Σ_{t ∈ {a, r}} C_t Φ_d(r_c, l_t)`` (:func:`energy_error_bound`).

The paper's navigation set (``C_a = C_r = 1, l_a = 1, l_r = 0.2, C_o = 0.7,
l_o = 1.5``): ``tol = 0.03, w = 1`` gives ``r_c ≈ 5.08``; ``tol = 10⁻², w = 1`` gives
``r_c ≈ 6.59``; ``tol = 10⁻², w = 0.1`` gives ``r_c ≈ 4.91``.

The per-agent bounds are worst cases (every dropped pair force aligned). What they
leave out in practice: dropped Morse terms nearly cancel inside a uniform swarm and
leave ``≈ 2 n C_a (r_c + l_a) e^{−r_c/l_a}`` at its edge (2-D); dropped alignment
terms do *not* cancel against agents that move relative to the swarm: summed over a
uniform neighbourhood they act as a drag ``≈ C_o n π l_o e^{−r_c/l_o} (r_c + l_o)
(v_i − v̄)`` (2-D), the part of the alignment drag ``C_o n π l_o² (v_i − v̄)`` beyond
``r_c``: 15 % of it at ``r_c = 5.08``, 7 % at ``r_c = 6.59``. Measured at the
navigation parameters, density 1.41 (``benchmarks/large_swarms.py --accuracy``),
these dominate the error; the bounds hold with a margin of about 10.

:func:`sparse_forces` and :func:`sparse_energy` evaluate the model's force (eq. 14 with
eq. 20's sink) and energy (eq. 16) with the pair sums restricted to a given list of
pairs (each unordered pair once, e.g. from
:func:`swarm_envs.physics.neighbors.radius_pairs` at ``r_c``), through
:class:`PairAccumulator`, which applies the one pair law
(:func:`~swarm_envs.physics.social_potential.pair_law`) to chunks of pairs; the
compiled pass of :mod:`swarm_envs.physics.compiled_pairs` applies the same function to
one pair at a time. Cost is ``O(P)`` in the number ``P`` of listed pairs (``O(N)`` at
bounded density with the pairs within ``r_c``). With all pairs listed
they equal :func:`~swarm_envs.physics.social_potential.forces` and
:func:`~swarm_envs.physics.social_potential.energy` to rounding; with the pairs within
``r_c`` they differ by at most the bounds above. Coincident agents follow the dense
convention (``u_ij = 0``: no force, pair energy ``U(0)``); nothing returns NaN.

>>> p = SocialPotentialParams.navigation()
>>> r_c = cutoff_radius(p, 1e-2, speed=1.0)
>>> round(r_c, 2)
6.59
>>> bool(pair_force_bound(r_c, p, speed=1.0) <= 1e-2)
True
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from swarm_envs.physics._validation import check_goal, check_real, check_state
from swarm_envs.physics.pair_sums import (
    PAIR_CHUNK,
    PairAccumulator,
    PairSums,
    _check_pairs,
    _check_params,
    pair_sums,
    swarm_rates,
)
from swarm_envs.physics.social_potential import (
    SocialPotentialParams,
    components,
    goal_potential,
    goal_terms,
    kinetic_energy,
    passive_components,
)

_BALL_VOLUME = {2: math.pi, 3: 4.0 * math.pi / 3.0}


def _terms(params: SocialPotentialParams, speed: float) -> list[tuple[float, float]]:
    """``(A_t, l_t)`` of the force bound's active terms (``A_t > 0``)."""
    p = params
    out = [(p.C_a / p.l_a, p.l_a), (p.C_r / p.l_r, p.l_r), (p.C_o * speed, p.l_o)]
    return [(a, length) for a, length in out if a > 0]


def pair_force_bound(rho: Any, params: SocialPotentialParams, *, speed: float = 1.0) -> Any:
    """``g(ρ; w)``: a bound on ``|f_ij|`` for a pair at distance ``ρ``, ``|v_i − v_j| ≤ w``.

    ``g(ρ; w) = (C_a/l_a) e^{−ρ/l_a} + (C_r/l_r) e^{−ρ/l_r} + C_o w e^{−ρ/l_o}``.

    >>> round(pair_force_bound(0.0, SocialPotentialParams(C_o=0.0)), 12)  # 1 + 1.2/0.2
    7.0
    """
    p = _check_params("pair_force_bound", params)
    w = check_real("pair_force_bound", "speed", speed, low=0.0)
    rho = np.asarray(rho, dtype=np.float64)
    out = np.zeros_like(rho)
    for a, length in _terms(p, w):
        out += a * np.exp(-rho / length)
    return out if out.ndim else float(out)


def cutoff_radius(params: SocialPotentialParams, tol: float, *, speed: float = 1.0) -> float:
    """The smallest ``r_c ≥ 0`` with ``g(r_c; w) ≤ tol`` (see the module docstring).

    Every pair term that the cut-off drops is then at most ``tol`` (force units) for
    pairs with relative speed ``|v_i − v_j| ≤ speed``.

    Args:
        params: model parameters.
        tol: tolerance per dropped pair, ``> 0``.
        speed: relative speed ``w`` up to which the alignment term is covered, ``≥ 0``.

    Returns:
        ``r_c`` (0 when ``g(0; w) ≤ tol``: no pair term reaches ``tol``). Accurate to
        ``10⁻¹²`` relative, rounded up (so ``g(r_c; w) ≤ tol`` holds).

    >>> r = cutoff_radius(SocialPotentialParams(C_r=0.0, C_o=0.0), 1e-3)
    >>> bool(abs(r - math.log(1e3)) < 1e-9)  # l_a ln(C_a / (l_a tol))
    True
    """
    p = _check_params("cutoff_radius", params)
    tol = check_real("cutoff_radius", "tol", tol, low=0.0, low_inclusive=False)
    w = check_real("cutoff_radius", "speed", speed, low=0.0)
    terms = _terms(p, w)

    def g(r: float) -> float:
        return sum(a * math.exp(-r / length) for a, length in terms)

    if g(0.0) <= tol:
        return 0.0
    # Each term is ≤ tol/len(terms) at its own l ln(len·A/tol), so g(hi) ≤ tol.
    k = len(terms)
    hi = max(length * math.log(k * a / tol) for a, length in terms if k * a > tol)
    lo = 0.0
    while hi - lo > 1e-12 * hi:
        mid = 0.5 * (lo + hi)
        if g(mid) <= tol:
            hi = mid
        else:
            lo = mid
    return hi


def _phi(d: int, r: float, length: float) -> float:
    """``Φ_d(r, l)``: ``Σ_{ρ_j > r} e^{−ρ_j/l} ≤ n Φ_d(r, l)`` at density ``n``."""
    e = math.exp(-r / length)
    if d == 2:
        return math.pi * e * (r * r + 2 * length * r + 2 * length * length)
    return (
        (4.0 * math.pi / 3.0) * e * (r**3 + 3 * length * r * r + 6 * length**2 * r + 6 * length**3)
    )


def _check_counts(
    owner: str, n_agents: Any, density: Any, dim: Any
) -> tuple[int | None, float | None, int]:
    if dim not in _BALL_VOLUME or isinstance(dim, bool):
        raise ValueError(f"{owner}: dim must be 2 or 3, got {dim!r}")
    if n_agents is None and density is None:
        raise ValueError(f"{owner}: give n_agents, density or both")
    if n_agents is not None and (
        isinstance(n_agents, bool) or not isinstance(n_agents, (int, np.integer)) or n_agents < 1
    ):
        raise ValueError(f"{owner}: n_agents must be an integer >= 1, got {n_agents!r}")
    if density is not None:
        density = check_real(owner, "density", density, low=0.0)
    return (None if n_agents is None else int(n_agents)), density, int(dim)


def force_error_bound(
    params: SocialPotentialParams,
    cutoff: float,
    *,
    speed: float = 1.0,
    n_agents: int | None = None,
    density: float | None = None,
    dim: int = 2,
) -> float:
    """A bound on ``|F_i − F_i^{cut}|`` for every agent (see the module docstring).

    ``min((N − 1) g(r_c; w), n Σ_t A_t Φ_d(r_c, l_t))`` over the bounds whose input is
    given.

    Args:
        params: model parameters.
        cutoff: ``r_c ≥ 0``; pairs farther apart than this are dropped.
        speed: bound ``w`` on every pair's relative speed ``|v_i − v_j|``, ``≥ 0``.
        n_agents: ``N`` (agents per swarm), for the bound with no assumption.
        density: ``n`` such that every ball of radius ``ρ ≥ r_c`` around an agent holds
            at most ``n ω_d ρ^d`` other agents.
        dim: spatial dimension, 2 or 3.

    >>> p = SocialPotentialParams.navigation()
    >>> force_error_bound(p, 6.0, speed=1.0, n_agents=2) == pair_force_bound(6.0, p)
    True
    """
    p = _check_params("force_error_bound", params)
    r = check_real("force_error_bound", "cutoff", cutoff, low=0.0)
    w = check_real("force_error_bound", "speed", speed, low=0.0)
    n, dens, d = _check_counts("force_error_bound", n_agents, density, dim)
    bounds = []
    if n is not None:
        bounds.append((n - 1) * pair_force_bound(r, p, speed=w))
    if dens is not None:
        bounds.append(dens * sum(a * _phi(d, r, length) for a, length in _terms(p, w)))
    return float(min(bounds))


def energy_error_bound(
    params: SocialPotentialParams,
    cutoff: float,
    *,
    n_agents: int,
    density: float | None = None,
    dim: int = 2,
) -> float:
    """A bound on a swarm's potential-energy error ``|Σ_{ρ_ij > r_c} U(ρ_ij)|``.

    ``min(N(N − 1)/2 · u(r_c), (N/2) n Σ_{t ∈ {a, r}} C_t Φ_d(r_c, l_t))`` with
    ``u(ρ) = C_r e^{−ρ/l_r} + C_a e^{−ρ/l_a}``; the density hypothesis is that of
    :func:`force_error_bound`.
    """
    p = _check_params("energy_error_bound", params)
    r = check_real("energy_error_bound", "cutoff", cutoff, low=0.0)
    n, dens, d = _check_counts("energy_error_bound", n_agents, density, dim)
    if n is None:
        raise ValueError("energy_error_bound: n_agents is required")
    terms = [(c, length) for c, length in ((p.C_a, p.l_a), (p.C_r, p.l_r)) if c > 0]
    bounds = [0.5 * n * (n - 1) * sum(c * math.exp(-r / length) for c, length in terms)]
    if dens is not None:
        bounds.append(0.5 * n * dens * sum(c * _phi(d, r, length) for c, length in terms))
    return float(min(bounds))


def _flat_pairs(
    x: Any, v: Any, i: Any, j: Any
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Validated ``x, v`` ``(..., N, d)``, their flat ``(M, d)`` views and the pairs."""
    x, v = check_state(x, v)
    xf = x.reshape(-1, x.shape[-1])
    i, j = _check_pairs(i, j, xf.shape[0])
    return x, v, xf, i, j


def sparse_forces(
    x: np.ndarray,
    v: np.ndarray,
    params: SocialPotentialParams,
    i: np.ndarray,
    j: np.ndarray,
    goal: np.ndarray | None = None,
) -> np.ndarray:
    """The force of :func:`~swarm_envs.physics.social_potential.forces` over listed pairs.

    ``F_i = Σ_{j listed with i} f_ij u_ij − β v_i + F_goal_i`` (eqs. 10–12, 14, and the
    sink of eqs. 19–21 when ``goal`` is given and ``C_g > 0``).

    Args:
        x, v: positions and velocities ``(..., N, d)``.
        params: model parameters.
        i, j: flat indices into ``x.reshape(-1, d)`` of the pairs, each unordered pair
            once (as :func:`swarm_envs.physics.neighbors.radius_pairs` returns them);
            pairs of different swarms are the caller's responsibility.
        goal: goal broadcastable to ``(..., d)``, or ``None``.

    Returns:
        Forces shaped like ``x``; differs from the dense force by at most
        :func:`force_error_bound` when the list holds every pair within ``r_c``.

    >>> from swarm_envs.physics import forces
    >>> x = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 2.0]]); v = 0.1 * x[::-1]
    >>> p = SocialPotentialParams()
    >>> f = sparse_forces(x, v, p, np.array([0, 0, 1]), np.array([1, 2, 2]))
    >>> bool(np.allclose(f, forces(x, v, p)))
    True
    """
    x, v, xf, i, j = _flat_pairs(x, v, i, j)
    assert v is not None
    out = pair_sums(xf, v.reshape(xf.shape), params, i, j).force.reshape(x.shape)
    sink = None
    if goal is not None:
        goal = check_goal(goal, x)
        if params.C_g > 0:
            sink = goal_terms(x, params, goal)[0]
    out[...] = np.stack(passive_components(components(out), components(v), params, sink), axis=-1)
    return out


def sparse_energy(
    x: np.ndarray,
    v: np.ndarray,
    params: SocialPotentialParams,
    i: np.ndarray,
    j: np.ndarray,
    goal: np.ndarray | None = None,
) -> np.ndarray:
    """Total energy φ (eq. 16) with the pair potential summed over the listed pairs.

    ``φ = Σ_i ½ m |v_i|² + Σ_{listed (i, j)} U(ρ_ij) + Σ_i V_goal(r_i)``, shaped
    ``(...)`` (one value per swarm); pairs as in :func:`sparse_forces`. Differs from
    :func:`~swarm_envs.physics.social_potential.energy` by at most
    :func:`energy_error_bound` when the list holds every pair within ``r_c``.
    """
    x, v, xf, i, j = _flat_pairs(x, v, i, j)
    n = x.shape[-2]
    batch = x.shape[:-2]
    groups = (np.arange(xf.shape[0]) // n) if batch else None
    n_groups = int(np.prod(batch)) if batch else 1
    pot = pair_sums(
        xf, None, params, i, j, groups=groups, n_groups=n_groups, potential=True
    ).potential
    out = kinetic_energy(v, params) + pot.reshape(batch).astype(x.dtype)
    if goal is not None:
        goal = check_goal(goal, x)
        if params.C_g > 0:
            out = out + goal_potential(x, params, goal).sum(axis=-1)
    return out


__all__ = [
    "PAIR_CHUNK",
    "PairAccumulator",
    "PairSums",
    "cutoff_radius",
    "energy_error_bound",
    "force_error_bound",
    "pair_force_bound",
    "pair_sums",
    "sparse_energy",
    "sparse_forces",
    "swarm_rates",
]
