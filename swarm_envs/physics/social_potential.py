"""Social potential model of Mabrouk & McInnes: forces and energy.

Reference: M. H. Mabrouk and C. R. McInnes, *Social potential model to simulate
emergent behaviour for swarm robots* (seeds ``000``/``001``). The reading below is the
consistent one fixed in ``MODELS.md`` §1; where it departs from the printed equations
it says so.

Notation: ``r_ij = r_j − r_i``, ``ρ_ij = |r_ij|``, ``u_ij = r_ij / ρ_ij`` (unit vector
from i toward j), ``v_ij = v_i − v_j``. Arrays are shaped ``(..., N, d)``: any leading
batch dimensions, ``N`` agents, ``d = 2`` or ``3``. Nothing here loops over agents or
pairs in Python; pairwise terms are ``(..., N, N)`` arrays.

Coincident agents (``ρ_ij = 0``): the direction ``u_ij`` is undefined; the convention
is ``u_ij = 0``, so a coincident pair exerts no force on each other (the distance is
floored at :data:`RHO_FLOOR` before dividing, and ``r_ij = 0`` makes the product zero).
Their pair energy is ``U(0) = C_r − C_a``, which is finite. Nothing returns NaN.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import NamedTuple

import numpy as np

from swarm_envs.physics._validation import check_goal, check_real, check_state

#: Distances are floored at this value before dividing (coincident-agent convention).
RHO_FLOOR = 1e-12


@dataclass(frozen=True)
class SocialPotentialParams:
    """Parameters of the social potential model (Mabrouk & McInnes, eqs. 9–21).

    All fields are validated on construction: a non-finite or out-of-range value
    raises :class:`ValueError` naming the field and the allowed range.

    Defaults are the paper's Fig. 1–10 set; :meth:`navigation` gives the Fig. 11 set.

    >>> SocialPotentialParams().C_r
    1.2
    >>> SocialPotentialParams(l_r=-1.0)
    Traceback (most recent call last):
    ...
    ValueError: SocialPotentialParams.l_r must be in (0, inf), got -1.0
    """

    C_a: float = 1.0
    """Attraction amplitude of the generalised Morse potential (eq. 9), ``≥ 0``."""
    C_r: float = 1.2
    """Repulsion amplitude (eq. 9), ``≥ 0``."""
    l_a: float = 1.0
    """Attraction range (eq. 9), ``> 0``."""
    l_r: float = 0.2
    """Repulsion range (eq. 9), ``> 0``."""
    C_o: float = 0.1
    """Alignment (orientation) strength (eq. 11), ``≥ 0``."""
    l_o: float = 1.5
    """Alignment range (eq. 11), ``> 0``."""
    beta: float = 0.1
    """Linear dissipation (friction) coefficient β (eq. 12), ``≥ 0``."""
    C_g: float = 0.0
    """Goal-sink amplitude (eq. 19); 0 switches the sink off, ``≥ 0``."""
    l_g: float = 5.0
    """Goal-sink range (eq. 19; printed as ``l_a`` in eqs. 21/23), ``> 0``."""
    m: float = 1.0
    """Mass of every agent (the paper takes unit mass), ``> 0``."""

    def __post_init__(self) -> None:
        positive = {"l_a", "l_r", "l_o", "l_g", "m"}
        for f in fields(self):
            value = check_real(
                type(self).__name__,
                f.name,
                getattr(self, f.name),
                low=0.0,
                low_inclusive=f.name not in positive,
            )
            object.__setattr__(self, f.name, value)

    @classmethod
    def navigation(cls) -> SocialPotentialParams:
        """The paper's Fig. 11 navigation set (``C_g = 15, l_g = 5, C_o = 0.7, β = 1``)."""
        return cls(
            C_a=1.0, C_r=1.0, l_a=1.0, l_r=0.2, C_o=0.7, l_o=1.5, beta=1.0, C_g=15.0, l_g=5.0, m=1.0
        )

    @property
    def range_ratio(self) -> float:
        """``l = l_r / l_a``, the abscissa of the paper's Fig. 9."""
        return self.l_r / self.l_a

    @property
    def amplitude_ratio(self) -> float:
        """``C = C_r / C_a``, the abscissa of Fig. 10 (``inf`` when ``C_a = 0``)."""
        return self.C_r / self.C_a if self.C_a > 0 else math.inf

    @property
    def h_stability(self) -> float:
        """``C·l²``; the Morse swarm is H-stable in 2-D only when this exceeds 1.

        D'Orsogna et al., PRL 96, 104302 (2006). The paper's defaults give 0.048:
        the collapsing regime, in which nearest-neighbour distances shrink as N grows.
        """
        return self.amplitude_ratio * self.range_ratio**2


def pair_potential(rho: np.ndarray, params: SocialPotentialParams) -> np.ndarray:
    """Generalised Morse pair potential ``U(ρ) = C_r e^{−ρ/l_r} − C_a e^{−ρ/l_a}`` (eq. 9).

    >>> float(pair_potential(np.array(0.0), SocialPotentialParams()))  # C_r − C_a
    0.19999999999999996
    """
    rho = np.asarray(rho)
    return params.C_r * np.exp(-rho / params.l_r) - params.C_a * np.exp(-rho / params.l_a)


def goal_potential(x: np.ndarray, params: SocialPotentialParams, goal: np.ndarray) -> np.ndarray:
    """Goal sink ``V_goal(r_i) = −C_g e^{−|r_i − r_g|/l_g}`` (eq. 19), shaped ``(..., N)``.

    ``goal`` broadcasts against ``(..., d)``.
    """
    x, _ = check_state(x)
    dist = np.linalg.norm(check_goal(goal, x)[..., None, :] - x, axis=-1)
    return -params.C_g * np.exp(-dist / params.l_g)


def goal_force(x: np.ndarray, params: SocialPotentialParams, goal: np.ndarray) -> np.ndarray:
    """Goal-sink force ``F_goal_i = (C_g/l_g) e^{−|r_g − r_i|/l_g} (r_g − r_i)/|r_g − r_i|``.

    The gradient of eq. 19; the printed eqs. 21/23 drop the unit vector and write ``l_a``
    for ``l_g`` (MODELS.md §1). An agent exactly on the goal feels no force.
    Shape ``(..., N, d)`` like ``x``.
    """
    x, _ = check_state(x)
    offset = check_goal(goal, x)[..., None, :] - x
    dist = np.sqrt(np.einsum("...k,...k->...", offset, offset))
    scale = (params.C_g / params.l_g) * np.exp(-dist / params.l_g) / np.maximum(dist, RHO_FLOOR)
    return offset * scale[..., None]


class PairGeometry(NamedTuple):
    """Pairwise offsets, distances and memoised decays of one set of positions.

    ``dx[k]`` is ``r_ij[..., k] = x_j[k] − x_i[k]`` and ``rho`` is ``ρ_ij``, each
    ``(..., N, N)`` (zeros on the diagonal); components are separate contiguous arrays,
    faster than one ``(..., N, N, d)`` array for the reductions in :func:`forces`.
    :meth:`decay` caches ``e^{−ρ/l}`` per length ``l``, so that the forces and the
    energy at the same positions compute each exponential once. Treat as read-only.
    """

    dx: list[np.ndarray]
    rho: np.ndarray
    decays: dict[float, np.ndarray]

    def decay(self, length: float) -> np.ndarray:
        """``e^{−ρ_ij / length}`` (cached; do not modify the returned array)."""
        out = self.decays.get(length)
        if out is None:
            out = np.exp(self.rho * (-1.0 / length))
            self.decays[length] = out
        return out


def pair_geometry(x: np.ndarray) -> PairGeometry:
    """The :class:`PairGeometry` of positions ``x`` shaped ``(..., N, d)``."""
    d = x.shape[-1]
    dx = [x[..., None, :, k] - x[..., :, None, k] for k in range(d)]
    rho2 = dx[0] * dx[0]
    for k in range(1, d):
        rho2 += dx[k] * dx[k]
    return PairGeometry(dx, np.sqrt(rho2, out=rho2), {})


def forces(
    x: np.ndarray,
    v: np.ndarray,
    params: SocialPotentialParams,
    goal: np.ndarray | None = None,
    *,
    geometry: PairGeometry | None = None,
) -> np.ndarray:
    """Total passive force on every agent (eq. 14, plus eq. 20's goal term).

    ``F_i = Σ_{j≠i} [ (C_a/l_a) e^{−ρ_ij/l_a} − (C_r/l_r) e^{−ρ_ij/l_r}
    − C_o ((v_i − v_j)·u_ij) e^{−ρ_ij/l_o} ] u_ij − β v_i + F_goal_i``

    cohesion (eq. 10, the negative gradient of eq. 9), alignment (eq. 11), dissipation
    (eq. 12) and, when ``goal`` is given and ``C_g > 0``, the goal sink (gradient of
    eq. 19). Positive cohesion pulls i toward j. The cohesion part equals
    ``−∇_i V`` with ``V = Σ_{i<j} U(ρ_ij)`` (tested by finite differences).

    Args:
        x: positions ``(..., N, d)``, ``d`` in {2, 3}; float32 stays float32.
        v: velocities, same shape.
        params: model parameters.
        goal: goal position broadcastable to ``(..., d)``, or ``None`` for no sink.
        geometry: ``pair_geometry(x)`` if the caller has it already (saves recomputing).

    Returns:
        Forces shaped like ``x`` (not divided by the mass).

    >>> x = np.array([[0.0, 0.0], [1.0, 0.0]])
    >>> f = forces(x, np.zeros_like(x), SocialPotentialParams())
    >>> bool(np.allclose(f[0], -f[1]))  # pair forces are antisymmetric
    True
    """
    x, v = check_state(x, v)
    p = params
    d = x.shape[-1]
    geo = pair_geometry(x) if geometry is None else geometry
    dx, rho = geo.dx, geo.rho
    inv_rho = np.maximum(rho, RHO_FLOOR)
    np.reciprocal(inv_rho, out=inv_rho)

    # Scalar pair magnitude along u_ij (eq. 10).
    scalar = geo.decay(p.l_a) * (p.C_a / p.l_a)
    scalar -= (p.C_r / p.l_r) * geo.decay(p.l_r)
    if p.C_o > 0:
        # Alignment (eq. 11): −C_o ((v_i − v_j)·u_ij) e^{−ρ/l_o}.
        proj = (v[..., :, None, 0] - v[..., None, :, 0]) * dx[0]
        for k in range(1, d):
            proj += (v[..., :, None, k] - v[..., None, :, k]) * dx[k]
        proj *= inv_rho
        proj *= geo.decay(p.l_o)
        proj *= p.C_o
        scalar -= proj
    scalar *= inv_rho  # now F_i = Σ_j scalar_ij r_ij
    total = np.stack([np.einsum("...ij,...ij->...i", scalar, dx[k]) for k in range(d)], axis=-1)
    if p.beta > 0:
        total -= p.beta * v
    if goal is not None:
        goal = check_goal(goal, x)
        if p.C_g > 0:
            total += goal_force(x, p, goal)
    return total


def kinetic_energy(v: np.ndarray, params: SocialPotentialParams) -> np.ndarray:
    """``Σ_i ½ m |v_i|²``, shaped ``(...)``."""
    v = np.asarray(v)
    return 0.5 * params.m * np.einsum("...ik,...ik->...", v, v)


def potential_energy(
    x: np.ndarray,
    params: SocialPotentialParams,
    goal: np.ndarray | None = None,
    *,
    geometry: PairGeometry | None = None,
) -> np.ndarray:
    """``Σ_{i<j} U(ρ_ij) + Σ_i V_goal(r_i)`` (eqs. 9, 16, 19), shaped ``(...)``."""
    x, _ = check_state(x)
    geo = pair_geometry(x) if geometry is None else geometry
    n = x.shape[-2]
    # U(ρ) = C_r e^{−ρ/l_r} − C_a e^{−ρ/l_a} over all ordered pairs, minus the N diagonal
    # terms U(0), halved.
    u = params.C_r * geo.decay(params.l_r) - params.C_a * geo.decay(params.l_a)
    pairs = 0.5 * (u.sum(axis=(-2, -1)) - n * (params.C_r - params.C_a))
    if goal is not None:
        goal = check_goal(goal, x)
        if params.C_g > 0:
            pairs = pairs + goal_potential(x, params, goal).sum(axis=-1)
    return pairs


def energy(
    x: np.ndarray,
    v: np.ndarray,
    params: SocialPotentialParams,
    goal: np.ndarray | None = None,
    *,
    geometry: PairGeometry | None = None,
) -> np.ndarray:
    """Total energy φ (eq. 16): kinetic + pair potential + goal potential, shaped ``(...)``.

    With no control, ``dφ/dt = −β Σ|v_i|² − ½ Σ_{i≠j} C_o ((v_ij·u_ij))² e^{−ρ_ij/l_o} ≤ 0``
    (eq. 18, with the projected relative velocity that the printed eq. writes as
    ``v_ij²``): φ is the Lyapunov function of the paper's section 3.

    >>> x = np.array([[0.0, 0.0], [1.0, 0.0]]); v = np.zeros_like(x)
    >>> p = SocialPotentialParams()
    >>> bool(np.isclose(energy(x, v, p), pair_potential(np.array(1.0), p)))
    True
    """
    x, v = check_state(x, v)
    return kinetic_energy(v, params) + potential_energy(x, params, goal, geometry=geometry)
