"""Social potential model of Mabrouk & McInnes: the pair law, the goal sink, forces, energy.

Reference: M. H. Mabrouk and C. R. McInnes, *Social potential model to simulate
emergent behaviour for swarm robots*. The reading below is the one fixed in
``docs/models.md`` §1; where it departs from the printed equations it says so.

Notation: ``r_ij = r_j − r_i``, ``ρ_ij = |r_ij|``, ``u_ij = r_ij / ρ_ij`` (unit vector
from i toward j), ``v_ij = v_i − v_j``. Arrays are shaped ``(..., N, d)``: any leading
batch dimensions, ``N`` agents, ``d = 2`` or ``3``. Nothing here loops over agents or
pairs in Python; pairwise terms are ``(..., N, N)`` arrays.

One definition, every backend: :func:`pair_law` (the Morse cohesion of eqs. 9–10 and the
alignment of eq. 11, per pair) and :func:`sink_law` (the goal sink of eqs. 19–20, per
agent) are written once, over any array type and an ``exp`` function. The functions
below apply them to numpy arrays or torch tensors alike (the namespace follows the
input, :mod:`swarm_envs._array`); the cut-off core's pair passes (numpy and numba) call
the same two laws on their pair lists.

Coincident agents (``ρ_ij = 0``): the direction ``u_ij`` is undefined; the convention
is ``u_ij = 0``, so a coincident pair exerts no force on each other (the distance is
floored at :data:`RHO_FLOOR` before dividing, and ``r_ij = 0`` makes the product zero).
Their pair energy is ``U(0) = C_r − C_a``, which is finite. Nothing returns NaN.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, Literal, NamedTuple, overload

import numpy as np

from swarm_envs._array import ArrayNamespace, namespace
from swarm_envs.physics._validation import check_goal, check_real, check_state

#: Distances are floored at this value before dividing (coincident-agent convention).
RHO_FLOOR = 1e-12

Array = Any


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
    """Linear dissipation (friction) coefficient β (eq. 12), ``≥ 0``; with
    ``alpha > 0`` the Rayleigh coefficient of :func:`dissipation`, ``> 0``."""
    C_g: float = 0.0
    """Goal-sink amplitude (eq. 19); 0 switches the sink off, ``≥ 0``."""
    l_g: float = 5.0
    """Goal-sink range (eq. 19; printed as ``l_a`` in eqs. 21/23), ``> 0``."""
    m: float = 1.0
    """Mass of every agent (the paper takes unit mass), ``> 0``."""
    alpha: float = 0.0
    """Self-propulsion α, ``≥ 0``: with ``alpha > 0`` the dissipation is the Rayleigh
    term ``(α − β|v_i|²) v_i`` (D'Orsogna et al. 2006), whose fixed speed is
    ``v₀ = √(α/β)`` (:func:`dissipation`); 0 keeps the linear friction ``−β v_i``."""

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
        if self.alpha > 0 and self.beta <= 0:
            raise ValueError(
                f"{type(self).__name__}.beta must be in (0, inf) when alpha > 0 "
                f"(the Rayleigh coefficient), got {self.beta!r}"
            )

    @property
    def cruise_speed(self) -> float:
        """``v₀ = √(α/β)``, the speed a free self-propelled agent tends to (0 without
        self-propulsion)."""
        return math.sqrt(self.alpha / self.beta) if self.alpha > 0 else 0.0

    @classmethod
    def navigation(cls) -> SocialPotentialParams:
        """The paper's Fig. 11 navigation set (``C_g = 15, l_g = 5, C_o = 0.7, β = 1``)."""
        return cls(
            C_a=1.0, C_r=1.0, l_a=1.0, l_r=0.2, C_o=0.7, l_o=1.5, beta=1.0, C_g=15.0, l_g=5.0, m=1.0
        )

    @classmethod
    def large_swarm(cls) -> SocialPotentialParams:
        """An H-stable set for large swarms, in 2-D and in 3-D (``docs/large_swarms.md``).

        ``C_a = 4, C_r = 64, l_a = 0.5, l_r = 0.25`` (``C = 16``, ``l = 0.5``):
        ``C·l² = 4`` and ``C·l³ = 2``, twice the H-stability threshold in 3-D and four
        times in 2-D, so the nearest-neighbour spacing stays bounded as ``N`` grows
        (D'Orsogna et al., PRL 96, 104302 (2006); :attr:`h_stability`,
        :attr:`h_stability_3d`). The pair potential has its minimum at
        ``ρ* = l_a l ln(C/l)/(1 − l) ≈ 1.73`` (depth 0.0625). Dissipation ``β = 1`` as
        in the navigation set; alignment ``C_o = 0.5`` with the range ``l_o = 1`` (the
        cut-off core's cut-off is then ``r_c ≈ 3.3`` at its default tolerance, against
        5.08 for the navigation set). The goal sink ``C_g = 30, l_g = 10`` reaches twice
        as far as the navigation set's (a swarm of this spacing is wider) with the same
        largest force ``C_g/l_g = 3``, the default action bound ``u_max``, so the
        analytic controller is never clipped.

        >>> p = SocialPotentialParams.large_swarm()
        >>> p.h_stability, p.h_stability_3d, p.C_g / p.l_g
        (4.0, 2.0, 3.0)
        """
        return cls(
            C_a=4.0,
            C_r=64.0,
            l_a=0.5,
            l_r=0.25,
            C_o=0.5,
            l_o=1.0,
            beta=1.0,
            C_g=30.0,
            l_g=10.0,
            m=1.0,
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

    @property
    def h_stability_3d(self) -> float:
        """``C·l³``; with ``l < 1`` the Morse swarm is H-stable in 3-D exactly when this
        exceeds 1.

        The 2-D argument of :attr:`h_stability` carried to 3-D: the Fourier transform
        of the pair potential, ``Û(k) = 8π [C_r l_r³ / (1 + k² l_r²)² − C_a l_a³ /
        (1 + k² l_a²)²]``, is positive at ``k = 0`` iff ``C·l³ > 1`` and then, with
        ``l_r < l_a``, at every ``k`` (``docs/large_swarms.md``). The navigation set
        gives 0.008.
        """
        return self.amplitude_ratio * self.range_ratio**3


# --------------------------------------------------------------------------- the laws


@overload
def pair_law(
    rho: Array,
    inv_rho: Array,
    vdot: Array | None,
    C_a: float,
    C_r: float,
    l_a: float,
    l_r: float,
    C_o: float,
    l_o: float,
    exp: Any,
    potential: Literal[True] = ...,
    potential_decay: Any = ...,
) -> tuple[Array, Array]: ...


@overload
def pair_law(
    rho: Array,
    inv_rho: Array,
    vdot: Array | None,
    C_a: float,
    C_r: float,
    l_a: float,
    l_r: float,
    C_o: float,
    l_o: float,
    exp: Any,
    potential: bool = ...,
    potential_decay: Any = ...,
) -> tuple[Array, Array | None]: ...


def pair_law(
    rho: Array,
    inv_rho: Array,
    vdot: Array | None,
    C_a: float,
    C_r: float,
    l_a: float,
    l_r: float,
    C_o: float,
    l_o: float,
    exp: Any,
    potential: bool = True,
    potential_decay: Any = None,
) -> tuple[Array, Array | None]:
    """The pair law of the social potential model, per pair: ``(s_ij, U(ρ_ij))``.

    ``s_ij`` is the force on i from j per unit of ``r_ij`` (so ``F_i = Σ_j s_ij r_ij``):

    ``s_ij = [ (C_a/l_a) e^{−ρ/l_a} − (C_r/l_r) e^{−ρ/l_r}
    − C_o ((v_i − v_j)·u_ij) e^{−ρ/l_o} ] / ρ``

    (cohesion eq. 10, the negative gradient of the generalised Morse potential eq. 9;
    alignment eq. 11), and ``U(ρ) = C_r e^{−ρ/l_r} − C_a e^{−ρ/l_a}`` (eq. 9).

    Args:
        rho: distances ``ρ_ij`` (any shape; an array, a tensor or a float).
        inv_rho: ``1 / max(ρ_ij, RHO_FLOOR)``, same shape.
        vdot: ``(v_i − v_j)·r_ij`` (not normalised), same shape; ``None`` (or
            ``C_o = 0``) skips the alignment term.
        C_a, C_r, l_a, l_r, C_o, l_o: the parameters of :class:`SocialPotentialParams`.
        exp: the exponential of the array type (``np.exp``, ``torch.exp``, a scalar
            ``exp`` in compiled loops).
        potential: ``False`` skips ``U`` (returned as ``None``) where only forces are
            wanted.
        potential_decay: ``None`` (``U`` reuses the force's exponentials), or a function
            ``(ρ, l) -> e^{−ρ/l}`` that evaluates them anew for ``U`` (an execution
            choice: a compiler then evaluates ``U`` inside the force's loop instead of
            storing the exponentials of every pair; see ``TorchNamespace``).

    >>> s, u = pair_law(1.0, 1.0, None, 1.0, 1.2, 1.0, 0.2, 0.1, 1.5, math.exp)
    >>> round(s, 6), round(u, 6)  # attraction at ρ = 1 (positive: toward j)
    (0.327452, -0.359794)
    """
    # Augmented operators only on values made here: in place for arrays (fewer
    # temporaries), plain rebinding for scalars, traced alike by torch.compile.
    e_a = exp(rho * (-1.0 / l_a))
    e_r = exp(rho * (-1.0 / l_r))
    s = (C_a / l_a) * e_a
    s -= (C_r / l_r) * e_r
    if vdot is not None and C_o != 0:
        align = vdot * inv_rho
        align *= exp(rho * (-1.0 / l_o))
        align *= C_o
        s -= align
    s *= inv_rho
    if not potential:
        return s, None
    if potential_decay is not None:
        e_a, e_r = potential_decay(rho, l_a), potential_decay(rho, l_r)
    u = C_r * e_r
    u -= C_a * e_a
    return s, u


def sink_law(dist: Array, inv_dist: Array, C_g: float, l_g: float, exp: Any) -> tuple[Array, Array]:
    """The goal sink, per agent: ``(g_i, V_goal)`` with ``F_goal_i = g_i (r_g − r_i)``.

    ``V_goal(r_i) = −C_g e^{−|r_g − r_i|/l_g}`` (eq. 19) and its negative gradient
    ``F_goal_i = (C_g/l_g) e^{−|r_g − r_i|/l_g} (r_g − r_i)/|r_g − r_i|``. The printed
    eqs. 21/23 drop the unit vector and write ``l_a`` for ``l_g`` (``docs/models.md``
    §1). ``inv_dist = 1 / max(dist, RHO_FLOOR)``: an agent on the goal feels no force.

    >>> g, v = sink_law(5.0, 0.2, 15.0, 5.0, math.exp)
    >>> round(g, 6), round(v, 6)
    (0.220728, -5.518192)
    """
    e = exp(dist * (-1.0 / l_g))
    return ((C_g / l_g) * e) * inv_dist, -C_g * e


def rate_law(
    rho: Array, C_a: float, C_r: float, l_a: float, l_r: float, C_o: float, l_o: float, exp: Any
) -> tuple[Array, Array | None]:
    """The pair's rates for the step-size rule, per pair: ``(κ(ρ_ij), w(ρ_ij))``.

    ``κ(ρ) = (C_r/l_r²) e^{−ρ/l_r} + (C_a/l_a²) e^{−ρ/l_a}`` bounds the curvature
    ``|U''(ρ)|`` of the Morse potential (eq. 9), the pair's stiffness along ``u_ij``;
    ``w(ρ) = C_o e^{−ρ/l_o}`` is the alignment's damping rate (eq. 11; ``None`` when
    ``C_o = 0``). :func:`~swarm_envs.physics.integrators.stable_substep` turns their
    per-agent sums into a step length (``docs/models.md`` §7).

    >>> k, w = rate_law(0.0, 1.0, 1.0, 1.0, 0.2, 0.7, 1.5, math.exp)
    >>> round(k, 6), round(w, 6)
    (26.0, 0.7)
    """
    kappa = (C_r / (l_r * l_r)) * exp(rho * (-1.0 / l_r))
    kappa += (C_a / (l_a * l_a)) * exp(rho * (-1.0 / l_a))
    if C_o == 0:
        return kappa, None
    return kappa, C_o * exp(rho * (-1.0 / l_o))


def stiffness_law(
    rho: Array,
    inv_rho: Array,
    C_a: float,
    C_r: float,
    l_a: float,
    l_r: float,
    exp: Any,
    maximum: Any,
) -> tuple[Array, Array]:
    """The pair's stiffness for the block bound of the step-size rule: ``(k_ij, p_ij)``.

    The Hessian block of the pair potential ``U(|r_ij|)`` is
    ``B_ij = U''(ρ) u uᵀ + (U'(ρ)/ρ)(I − u uᵀ)``; with the negative parts dropped
    (they only lower the largest eigenvalue of the Hessian, ``docs/models.md`` §7) it is
    ``B⁺_ij = t I + p u uᵀ`` with ``t = max(U'/ρ, 0)``, ``a = max(U'', 0)``,
    ``p = a − t``, and its norm is ``b = max(a, t)``. Returned: ``k = b + t`` (the
    scalar part: the block's norm in the off-diagonal sum plus its isotropic part) and
    ``p`` (the coefficient of ``u uᵀ``, of either sign), with
    ``U'' = (C_r/l_r²) e^{−ρ/l_r} − (C_a/l_a²) e^{−ρ/l_a}`` and
    ``U'/ρ = [(C_a/l_a) e^{−ρ/l_a} − (C_r/l_r) e^{−ρ/l_r}] / ρ`` (eq. 9;
    ``inv_rho = 1/max(ρ, RHO_FLOOR)``). ``maximum`` is the elementwise maximum of the
    array type (``np.maximum``, ``torch.maximum``, a scalar ``max``).

    >>> k, p = stiffness_law(1.0, 1.0, 1.0, 1.0, 1.0, 0.2, math.exp, max)
    >>> round(k, 6), round(p, 6)  # attraction at ρ = 1: only the transverse part is positive
    (0.668379, -0.33419)
    """
    e_a = exp(rho * (-1.0 / l_a))
    e_r = exp(rho * (-1.0 / l_r))
    curvature = (C_r / (l_r * l_r)) * e_r - (C_a / (l_a * l_a)) * e_a
    transverse = ((C_a / l_a) * e_a - (C_r / l_r) * e_r) * inv_rho
    a = maximum(curvature, 0.0 * curvature)
    t = maximum(transverse, 0.0 * transverse)
    return maximum(a, t) + t, a - t


def block_bound(k_sum: Array, q: list[list[Array]], dim: int, xp: Any) -> Array:
    """The bound ``Σ_j k_ij + λ̄(Q_i)`` per agent of :func:`stiffness_law`'s sums.

    ``k_sum = Σ_j k_ij`` and ``q[a][b] = Σ_j p_ij u_a u_b`` (``a ≤ b``; the symmetric
    ``d × d`` matrix ``Q_i``, ``u = r_ij/ρ_ij``, 0 for coincident agents).
    ``λ̄(Q) = tr Q/d + √((d − 1)/d) ‖Q − (tr Q/d) I‖_F`` bounds the largest eigenvalue of
    a symmetric matrix from its first two moments (Wolkowicz & Styan 1980; exact for
    ``d = 2``). ``xp``: the array namespace (``sqrt``) or :mod:`math`.
    """
    if dim == 2:
        trace = q[0][0] + q[1][1]
        half = 0.5 * (q[0][0] - q[1][1])
        return k_sum + 0.5 * trace + xp.sqrt(half * half + q[0][1] * q[0][1])
    trace = q[0][0] + q[1][1] + q[2][2]
    mean = trace * (1.0 / 3.0)
    d0, d1, d2 = q[0][0] - mean, q[1][1] - mean, q[2][2] - mean
    off = q[0][1] * q[0][1] + q[0][2] * q[0][2] + q[1][2] * q[1][2]
    dev2 = d0 * d0 + d1 * d1 + d2 * d2 + 2.0 * off
    return k_sum + mean + math.sqrt(2.0 / 3.0) * xp.sqrt(dev2)


def _pair_law(
    rho: Array,
    inv_rho: Array,
    vdot: Array | None,
    p: SocialPotentialParams,
    xp: ArrayNamespace,
    potential: bool = True,
) -> tuple[Array, Array | None]:
    return pair_law(
        rho,
        inv_rho,
        vdot,
        p.C_a,
        p.C_r,
        p.l_a,
        p.l_r,
        p.C_o,
        p.l_o,
        xp.exp_temp,
        potential,
        xp.potential_decay,
    )


# --------------------------------------------------------------------------- geometry


class PairGeometry(NamedTuple):
    """Pairwise offsets and distances of one set of positions (numpy or torch).

    ``dx[k]`` is ``r_ij[..., k] = x_j[k] − x_i[k]`` and ``rho`` is ``ρ_ij``, each
    ``(..., N, N)`` (zeros on the diagonal); components are separate arrays, faster than
    one ``(..., N, N, d)`` array for the reductions in :func:`forces`, and the layout on
    which a compiler fuses each pair's terms into one loop. Treat as read-only.
    """

    dx: list[Array]
    rho: Array


def components(a: Array) -> list[Array]:
    """``[a[..., 0], ..., a[..., d−1]]`` for an array; a list of components as it is."""
    if isinstance(a, (list, tuple)):
        return list(a)
    return [a[..., k] for k in range(a.shape[-1])]


def pair_geometry(x: Array) -> PairGeometry:
    """The :class:`PairGeometry` of positions ``x`` shaped ``(..., N, d)`` (or its list of
    ``d`` components, each ``(..., N)``)."""
    xs = components(x)
    xp = namespace(xs[0])
    dx = [c[..., None, :] - c[..., :, None] for c in xs]
    rho2 = dx[0] * dx[0]
    for k in range(1, len(dx)):
        rho2 += dx[k] * dx[k]
    return PairGeometry(dx, xp.sqrt_temp(rho2))


def present_geometry(geometry: PairGeometry, present: Array | None) -> PairGeometry:
    """``geometry`` with every pair that has a member not in ``present`` ``(..., N)``
    at infinite distance: such a pair has no force, energy or rate (every law here
    decays to exactly 0), is nobody's near neighbour and never collides. The diagonal
    keeps ``ρ_ii = 0``. ``present=None`` returns ``geometry``."""
    if present is None:
        return geometry
    rho = geometry.rho
    xp = namespace(rho)
    n = rho.shape[-1]
    pairs = present[..., :, None] & present[..., None, :]
    eye = xp.eye(n, like=rho) > 0
    return PairGeometry(geometry.dx, xp.where(pairs | eye, rho, xp.inf))


def pair_terms(
    geometry: PairGeometry,
    v: Array | None,
    params: SocialPotentialParams,
    *,
    energy: bool = True,
) -> tuple[list[Array], Array | None]:
    """The pair part of eq. 14 per component and the pair energy ``Σ_{i<j} U(ρ_ij)``.

    Returns ``([F_0, ..., F_{d−1}] each (..., N), E (...))`` with
    ``F_i = Σ_j s_ij r_ij`` from :func:`pair_law` (``v`` its velocities ``(..., N, d)``
    or components; ``None`` skips alignment). ``E`` sums ``U`` over all ordered pairs,
    subtracts the ``N`` diagonal terms ``U(0) = C_r − C_a`` and halves (``None`` with
    ``energy=False``).
    """
    p = params
    dx, rho = geometry.dx, geometry.rho
    xp = namespace(rho)
    inv_rho = xp.reciprocal_temp(xp.clip(rho, RHO_FLOOR, None))
    vdot = None
    if v is not None and p.C_o != 0:
        vs = components(v)
        vdot = vs[0][..., :, None] - vs[0][..., None, :]
        vdot *= dx[0]
        for k in range(1, len(dx)):
            term = vs[k][..., :, None] - vs[k][..., None, :]
            term *= dx[k]
            vdot += term
    s, u = _pair_law(rho, inv_rho, vdot, p, xp, potential=energy)
    total = None
    if energy:
        n = rho.shape[-1]
        total = 0.5 * (xp.sum(xp.sum(u, axis=-1), axis=-1) - n * (p.C_r - p.C_a))
    return [xp.sum_product(s, c) for c in dx], total


def dissipation(fs: list[Array], vs: list[Array], params: SocialPotentialParams) -> list[Array]:
    """The forces ``fs`` per component with the dissipation of every agent added.

    ``−β v_i`` (eq. 12, linear friction) when ``alpha = 0``; the Rayleigh term
    ``(α − β|v_i|²) v_i`` (D'Orsogna et al., PRL 96, 104302 (2006)) when
    ``alpha > 0``: it drives a free agent's speed to ``v₀ = √(α/β)``. ``vs`` are the
    velocity components ``(..., N)`` (numpy arrays or torch tensors).

    >>> p = SocialPotentialParams(alpha=1.0, beta=0.25)  # v₀ = 2
    >>> [float(f) for f in dissipation([0.0, 0.0], [2.0, 0.0], p)]
    [0.0, 0.0]
    """
    p = params
    if p.alpha > 0:
        speed2 = vs[0] * vs[0]
        for vc in vs[1:]:
            speed2 = speed2 + vc * vc
        gain = p.alpha - p.beta * speed2
        return [fc + gain * vc for fc, vc in zip(fs, vs, strict=True)]
    if p.beta > 0:
        return [fc - p.beta * vc for fc, vc in zip(fs, vs, strict=True)]
    return fs


def passive_components(
    pair_forces: list[Array],
    vs: list[Array],
    params: SocialPotentialParams,
    sink: list[Array] | None = None,
) -> list[Array]:
    """The passive force per component, assembled once for the numpy, cut-off and torch
    paths (the C step writes the same sum in its kernel): the pair forces
    (Morse and alignment, eqs. 9–13, however a core summed them: dense, cut-off or in
    compiled pair sums) with the dissipation (:func:`dissipation`) and, where given, the
    goal sink's force components (eq. 19, ``goal_terms(...)[0]``).

    >>> p = SocialPotentialParams(beta=0.5)
    >>> [float(f) for f in passive_components([1.0, 0.0], [2.0, 0.0], p, sink=[0.0, 3.0])]
    [0.0, 3.0]
    """
    fs = dissipation(pair_forces, vs, params)
    if sink is not None:
        fs = [fc + gc for fc, gc in zip(fs, sink, strict=True)]
    return fs


def dissipation_rate(vs: list[Array] | None, params: SocialPotentialParams) -> Any:
    """The largest damping rate (times the mass) of :func:`dissipation`, per swarm.

    ``β`` for linear friction (a float). With self-propulsion the Jacobian
    ``−∂/∂v_i [(α − β|v_i|²) v_i]`` has the eigenvalues ``β|v_i|² − α`` (across
    ``v_i``) and ``3β|v_i|² − α`` (along it), so the rate is
    ``max_i 3β|v_i|² − α``, shaped ``(...)``; negative where every agent is slower
    than ``v₀/√3`` (the term then injects energy). ``vs``: the velocity components
    ``(..., N)``, required when ``alpha > 0``.
    """
    p = params
    if p.alpha <= 0:
        return p.beta
    if vs is None:
        raise ValueError("the self-propelled dissipation rate needs the velocities")
    xp = namespace(vs[0])
    speed2 = vs[0] * vs[0]
    for vc in vs[1:]:
        speed2 = speed2 + vc * vc
    return 3.0 * p.beta * xp.amax(speed2, axis=-1) - p.alpha


def pair_rates(
    geometry: PairGeometry,
    params: SocialPotentialParams,
    *,
    sink: bool = False,
    v: Array | None = None,
) -> tuple[Array, Array]:
    """``(ω², γ)`` per swarm ``(...)``: the Gershgorin bounds of the step-size rule.

    ``ω² = (2/m) max_i Σ_{j≠i} κ(ρ_ij)`` bounds the largest eigenvalue of the Hessian of
    the potential divided by the mass (each pair's block enters its two agents' rows),
    and ``γ = (β + 2 max_i Σ_{j≠i} w(ρ_ij))/m`` the largest damping rate of dissipation
    and alignment (:func:`rate_law`). ``sink=True`` adds the goal sink's curvature
    ``C_g/l_g²`` (its largest, at the goal) to ``ω²``: the sink acts passively. With
    self-propulsion (``alpha > 0``) ``β`` is replaced by :func:`dissipation_rate` of
    the velocities ``v`` (``(..., N, d)`` or components, required then), and ``γ`` may
    be negative.
    """
    p = params
    rho = geometry.rho
    xp = namespace(rho)
    kappa, w = rate_law(rho, p.C_a, p.C_r, p.l_a, p.l_r, p.C_o, p.l_o, xp.exp_temp)
    k0 = p.C_r / (p.l_r * p.l_r) + p.C_a / (p.l_a * p.l_a)  # κ(0), the diagonal
    # the diagonal's κ(0) is subtracted from the row sums; the clip drops its round-off
    omega2 = (2.0 / p.m) * xp.clip(xp.amax(xp.sum(kappa, axis=-1), axis=-1) - k0, 0.0, None)
    if sink:
        omega2 = omega2 + p.C_g / (p.l_g * p.l_g * p.m)
    rate = dissipation_rate(None if v is None else components(v), p)
    if w is None:
        gamma = rate / p.m + 0.0 * omega2
    else:
        rows = xp.clip(xp.amax(xp.sum(w, axis=-1), axis=-1) - p.C_o, 0.0, None)
        gamma = (rate + 2.0 * rows) / p.m
    return omega2, gamma


def stiffness_rate(
    geometry: PairGeometry, params: SocialPotentialParams, *, sink: bool = False
) -> Array:
    """``ω²`` per swarm ``(...)``: the block bound of the step-size rule of
    ``"implicit_damping_euler"`` (``docs/models.md`` §7).

    The Hessian of the potential is ``Σ_{pairs} (e_i − e_j)(e_i − e_j)ᵀ ⊗ B_ij``; with the
    negative parts of the blocks dropped (:func:`stiffness_law`) and block Gershgorin
    (Feingold & Varga 1962), its largest eigenvalue is at most
    ``max_i [λ_max(Σ_j B⁺_ij) + Σ_j ‖B⁺_ij‖]``, which :func:`block_bound` bounds per
    agent; ``ω²`` is that over the mass. In 2-D never more than
    ``(2/m) max_i Σ_j b_ij``, the Gershgorin bound of the same blocks (``λ̄`` is then
    exact). ``sink=True`` adds the goal sink's curvature
    ``C_g/l_g²`` (over the mass), as :func:`pair_rates`.
    """
    p = params
    dx, rho = geometry.dx, geometry.rho
    xp = namespace(rho)
    n = rho.shape[-1]
    inv_rho = xp.reciprocal_temp(xp.clip(rho, RHO_FLOOR, None))
    k, pp = stiffness_law(rho, inv_rho, p.C_a, p.C_r, p.l_a, p.l_r, xp.exp_temp, xp.maximum)
    eye = xp.eye(n, like=rho) > 0
    k = xp.where(eye, 0.0, k)  # the diagonal ρ_ii = 0 is no pair
    units = [c * inv_rho for c in dx]  # u_ij, 0 on the diagonal
    d = len(dx)
    q = [[None] * d for _ in range(d)]
    for a in range(d):
        for b in range(a, d):
            q[a][b] = xp.sum(pp * units[a] * units[b], axis=-1)
    bound = block_bound(xp.sum(k, axis=-1), q, d, xp)
    omega2 = xp.amax(bound, axis=-1) / p.m
    if sink:
        omega2 = omega2 + p.C_g / (p.l_g * p.l_g * p.m)
    return omega2


def damping_rates(
    geometry: PairGeometry, v: Array, params: SocialPotentialParams
) -> tuple[Array, Array]:
    """The damping treated implicitly by ``"implicit_damping_euler"``, per agent (times
    the mass): ``(b_i, w_i)``, each ``(..., N)``.

    ``b_i = D_i⁺``, the positive part of agent i's dissipation rate ``D_i``: ``β``, or
    with self-propulsion the largest eigenvalue ``3β|v_i|² − α`` of its Jacobian
    (:func:`dissipation_rate`; a negative rate, energy injected, stays explicit);
    ``w_i = Σ_{j≠i} w(ρ_ij)``, the alignment's row sum (:func:`rate_law`), which bounds
    its damping of agent i. ``v``: velocities ``(..., N, d)`` or components.
    """
    p = params
    rho = geometry.rho
    xp = namespace(rho)
    vs = components(v)
    if p.alpha > 0:
        speed2 = vs[0] * vs[0]
        for vc in vs[1:]:
            speed2 = speed2 + vc * vc
        own = xp.clip(3.0 * p.beta * speed2 - p.alpha, 0.0, None)
    else:
        own = p.beta + 0.0 * vs[0]
    if p.C_o == 0:
        return own, 0.0 * own
    w = p.C_o * xp.exp(rho * (-1.0 / p.l_o))
    return own, xp.clip(xp.sum(w, axis=-1) - p.C_o, 0.0, None)


def goal_terms(
    x: Array, params: SocialPotentialParams, goal: Array
) -> tuple[list[Array], Array, Array]:
    """The goal sink on every agent: ``(F_goal per component, V_goal (..., N), dist (..., N))``.

    ``x`` is ``(..., N, d)`` or its components; ``goal`` broadcasts against ``(..., d)``.
    """
    xs = components(x)
    xp = namespace(xs[0])
    offset = [goal[..., None, k] - xc for k, xc in enumerate(xs)]  # r_g − r_i
    dist2 = offset[0] * offset[0]
    for oc in offset[1:]:
        dist2 = dist2 + oc * oc
    dist = xp.sqrt(dist2)
    g, potential = sink_law(
        dist, 1.0 / xp.clip(dist, RHO_FLOOR, None), params.C_g, params.l_g, xp.exp
    )
    return [oc * g for oc in offset], potential, dist


# --------------------------------------------------------------------------- public API


def pair_potential(rho: Array, params: SocialPotentialParams) -> Array:
    """Generalised Morse pair potential ``U(ρ) = C_r e^{−ρ/l_r} − C_a e^{−ρ/l_a}`` (eq. 9).

    >>> float(pair_potential(np.array(0.0), SocialPotentialParams()))  # C_r − C_a
    0.19999999999999996
    """
    if not type(rho).__module__.startswith("torch"):
        rho = np.asarray(rho)
    xp = namespace(rho)
    return _pair_law(rho, rho, None, params, xp)[1]


def _state(x: Any, v: Any | None = None) -> tuple[Array, Array | None]:
    """Validated ``(x, v)``: numpy arrays through :func:`check_state`, torch tensors as
    they are (floating, ``(..., N, d)``, ``d`` in {2, 3})."""
    return check_state(x, v)


def goal_potential(x: Array, params: SocialPotentialParams, goal: Array) -> Array:
    """Goal sink ``V_goal(r_i) = −C_g e^{−|r_i − r_g|/l_g}`` (eq. 19), shaped ``(..., N)``.

    ``goal`` broadcasts against ``(..., d)``.
    """
    x, _ = _state(x)
    return goal_terms(x, params, check_goal(goal, x))[1]


def goal_force(x: Array, params: SocialPotentialParams, goal: Array) -> Array:
    """Goal-sink force ``F_goal_i = (C_g/l_g) e^{−|r_g − r_i|/l_g} (r_g − r_i)/|r_g − r_i|``.

    The gradient of eq. 19 (:func:`sink_law`). An agent exactly on the goal feels no
    force. Shape ``(..., N, d)`` like ``x``.
    """
    x, _ = _state(x)
    xp = namespace(x)
    return xp.stack(goal_terms(x, params, check_goal(goal, x))[0], axis=-1)


def forces(
    x: Array,
    v: Array,
    params: SocialPotentialParams,
    goal: Array | None = None,
    *,
    geometry: PairGeometry | None = None,
) -> Array:
    """Total passive force on every agent (eq. 14, plus eq. 20's goal term).

    ``F_i = Σ_{j≠i} [ (C_a/l_a) e^{−ρ_ij/l_a} − (C_r/l_r) e^{−ρ_ij/l_r}
    − C_o ((v_i − v_j)·u_ij) e^{−ρ_ij/l_o} ] u_ij − β v_i + F_goal_i``

    cohesion (eq. 10, the negative gradient of eq. 9), alignment (eq. 11), dissipation
    (eq. 12; with ``alpha > 0`` the Rayleigh term ``(α − β|v_i|²) v_i`` in place of
    ``−β v_i``, :func:`dissipation`) and, when ``goal`` is given and ``C_g > 0``, the
    goal sink (gradient of eq. 19). Positive cohesion pulls i toward j. The cohesion part equals
    ``−∇_i V`` with ``V = Σ_{i<j} U(ρ_ij)`` (tested by finite differences).

    Args:
        x: positions ``(..., N, d)``, ``d`` in {2, 3}: a numpy array (float32 stays
            float32) or a floating torch tensor on any device.
        v: velocities, same shape and type.
        params: model parameters.
        goal: goal position broadcastable to ``(..., d)``, or ``None`` for no sink.
        geometry: ``pair_geometry(x)`` if the caller has it already (saves recomputing).

    Returns:
        Forces shaped like ``x`` (not divided by the mass), of the same array type.

    >>> x = np.array([[0.0, 0.0], [1.0, 0.0]])
    >>> f = forces(x, np.zeros_like(x), SocialPotentialParams())
    >>> bool(np.allclose(f[0], -f[1]))  # pair forces are antisymmetric
    True
    """
    x, v = _state(x, v)
    xp = namespace(x)
    p = params
    geo = pair_geometry(x) if geometry is None else geometry
    sink = None
    if goal is not None:
        goal = check_goal(goal, x)
        if p.C_g > 0:
            sink = goal_terms(x, p, goal)[0]
    pair_forces, _ = pair_terms(geo, v, p, energy=False)
    return xp.stack(passive_components(pair_forces, components(v), p, sink), axis=-1)


def kinetic_energy(v: Array, params: SocialPotentialParams) -> Array:
    """``Σ_i ½ m |v_i|²``, shaped ``(...)``."""
    if not type(v).__module__.startswith("torch"):
        v = np.asarray(v)
    xp = namespace(v)
    return 0.5 * params.m * xp.sum(xp.sum_components(v * v), axis=-1)


def potential_energy(
    x: Array,
    params: SocialPotentialParams,
    goal: Array | None = None,
    *,
    geometry: PairGeometry | None = None,
) -> Array:
    """``Σ_{i<j} U(ρ_ij) + Σ_i V_goal(r_i)`` (eqs. 9, 16, 19), shaped ``(...)``."""
    x, _ = _state(x)
    xp = namespace(x)
    geo = pair_geometry(x) if geometry is None else geometry
    pairs = pair_terms(geo, None, params)[1]
    if goal is not None:
        goal = check_goal(goal, x)
        if params.C_g > 0:
            pairs = pairs + xp.sum(goal_terms(x, params, goal)[1], axis=-1)
    return pairs


def energy(
    x: Array,
    v: Array,
    params: SocialPotentialParams,
    goal: Array | None = None,
    *,
    geometry: PairGeometry | None = None,
) -> Array:
    """Total energy φ (eq. 16): kinetic + pair potential + goal potential, shaped ``(...)``.

    With no control, ``dφ/dt = −β Σ|v_i|² − ½ Σ_{i≠j} C_o ((v_ij·u_ij))² e^{−ρ_ij/l_o} ≤ 0``
    (eq. 18, with the projected relative velocity that the printed eq. writes as
    ``v_ij²``): φ is the Lyapunov function of the paper's section 3. With
    self-propulsion (``alpha > 0``) the first term is ``Σ (α − β|v_i|²)|v_i|²``
    (:func:`dissipation`), of either sign; φ keeps its definition.

    >>> x = np.array([[0.0, 0.0], [1.0, 0.0]]); v = np.zeros_like(x)
    >>> p = SocialPotentialParams()
    >>> bool(np.isclose(energy(x, v, p), pair_potential(np.array(1.0), p)))
    True
    """
    x, v = _state(x, v)
    return kinetic_energy(v, params) + potential_energy(x, params, goal, geometry=geometry)
