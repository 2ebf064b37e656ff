"""Group statistics of a swarm (``docs/models.md`` §2), over arrays with leading batch axes.

Sources: M. H. Mabrouk and C. R. McInnes, *Social potential model to simulate emergent
behaviour for swarm robots*, §1.2 (seed ``001``, eqs. 1–6, and eq. 16 for the energy);
Naterop, Petrides & Prasad, *Implementing two mathematical swarm models…*, §4.1.4
(seed ``003``, eqs. 8–12 and the response time); Couzin et al., J. theor. Biol. 218
(2002) 1–11, for the unit-heading forms.

Statistics (``r_ic = r_i − r_c``, ``â = a / |a|``):

- :func:`centroid` — ``r_c = (1/N) Σ r_i`` (Mabrouk & McInnes eq. 1; Naterop eq. 9).
- :func:`polarization` — ``|Σ v̂_i| / N ∈ [0, 1]``, unit headings (Couzin; Naterop eq. 8).
- :func:`velocity_polarization` — ``|Σ v_i| / N``, depends on speed (Mabrouk & McInnes eq. 2).
- :func:`angular_momentum` — ``|Σ r̂_ic × v̂_i| / N ∈ [0, 1]``, unit headings (Couzin).
- :func:`velocity_angular_momentum` — ``|Σ r̂_ic × v_i| / N`` (Mabrouk & McInnes eq. 3).
- :func:`raw_angular_momentum` — ``|Σ r_ic × v_i| / N`` (Naterop eq. 10 and table 3).
- :func:`goal_angular_momentum` — ``|Σ_i (r_i − r_g) × v_i| / N``, the true angular
  momentum per agent (unit masses) about the goal ``r_g`` (a mill at the goal).
- :func:`tangential_speed` — ``|Σ_i r̂_ig × v_i| / N``, the mean tangential velocity
  about the goal (``r̂_ig`` the unit vector from the goal), optionally of the agents
  within a radius of it only.
- :func:`spherical_variance` — ``1 − polarization``, unit headings (Mabrouk & McInnes eq. 4).
- :func:`nearest_neighbor_distance` — ``(1/N) Σ_i min_{j≠i} |r_i − r_j|`` (eq. 5).
- :func:`expanse` — ``(1/N) Σ_i |r_i − r_c|`` (eq. 6 as the text defines it; Naterop eq. 11).
- :func:`packing_density` — ``expanse / N`` (Naterop eq. 12).
- :func:`total_energy` — total energy φ of the social-potential model (Mabrouk & McInnes eq. 16).
- :func:`fraction_within` — fraction of agents with ``|r_i − r_g| ≤ R`` (navigation).
- :func:`first_passage_time` — first time a series crosses a threshold: Naterop's response
  time, time until the centroid or a fraction of the agents is within the goal radius.

Naterop's eq. 10 writes ``r_ic = r_c − r_i``; the sign does not matter under the norm.
The cross product ``×`` is, in 2-D, the scalar ``z``-component ``a_x b_y − a_y b_x`` (the
statistic takes the absolute value of the sum) and, in 3-D, the vector (the statistic
takes the norm of the sum).

Shapes and dtypes: every statistic takes positions ``x`` and/or velocities ``v`` shaped
``(..., N, d)`` — any leading batch dimensions, ``N ≥ 1`` agents, ``d = 2`` or ``3`` —
and returns an array shaped ``(...)`` (0-d when there is no batch dimension). A floating
input keeps its dtype (float32 stays float32); integer input is computed in float64.
Nothing loops over agents or pairs in Python; the nearest-neighbour distance builds an
``(..., N, N)`` array of squared distances.

Degenerate cases never produce NaN (for finite input):

- an agent with zero speed has no heading; its unit heading is taken as the zero vector,
  so it adds nothing to the unit-heading sums but still counts in ``N`` (a swarm at rest
  has polarization 0 and spherical variance 1);
- an agent at the group centre has no direction ``r̂_ic``; it is taken as the zero vector
  (distances to the centre below the rounding level of the coordinates count as zero,
  so an agent that sits at the centre by symmetry stays there after a translation);
- coincident agents have nearest-neighbour distance 0; a single agent (``N = 1``) has
  nearest-neighbour distance 0 and expanse 0;
- ``N = 0`` raises :class:`ValueError`.

The unit-heading forms are clipped to ``[0, 1]`` to absorb rounding (a sum of ``N``
unit vectors can come out as ``N (1 + ε)``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from swarm_envs._array import NUMPY, ArrayNamespace, namespace
from swarm_envs.physics import SocialPotentialParams, energy
from swarm_envs.physics._validation import as_state

__all__ = [
    "angular_momentum",
    "centroid",
    "expanse",
    "first_passage_time",
    "fraction_within",
    "goal_angular_momentum",
    "mean_cross_about_goal",
    "nearest_neighbor_distance",
    "packing_density",
    "polarization",
    "raw_angular_momentum",
    "spherical_variance",
    "tangential_speed",
    "total_energy",
    "velocity_angular_momentum",
    "velocity_polarization",
]

#: A distance to the group centre counts as zero below
#: ``CENTRE_RTOL · eps(dtype) · √N · max_i |r_i|_∞`` (the rounding level of the centroid).
CENTRE_RTOL = 4.0


# --------------------------------------------------------------------------- helpers


def _as_state(name: str, a: Any) -> np.ndarray:
    """``a`` as a floating array shaped ``(..., N, d)``, ``N ≥ 1``, ``d`` in {2, 3}.

    A torch tensor stays a tensor (the statistics run on either; typed as numpy's)."""
    if _is_tensor(a):
        if a.ndim < 2 or a.shape[-1] not in (2, 3) or a.shape[-2] < 1:
            raise ValueError(f"{name} must have shape (..., N, d) with N >= 1, d in (2, 3)")
        return a
    return as_state(a, name, min_agents=1)


def _is_tensor(a: Any) -> bool:
    return type(a).__module__.startswith("torch")


def _as_pair(x: Any, v: Any) -> tuple[np.ndarray, np.ndarray]:
    x = _as_state("positions", x)
    v = _as_state("velocities", v)
    if v.shape != x.shape:
        raise ValueError(f"velocities shape {v.shape} must equal positions shape {x.shape}")
    return x, v


def _norm(a: Any, xp: ArrayNamespace) -> Any:
    """Euclidean norm over the last axis, shape ``a.shape[:-1]``."""
    return xp.norm(a)


def _unit(a: Any, norm: Any, keep: Any, xp: ArrayNamespace) -> Any:
    """``a / |a|`` with the zero vector wherever ``keep`` is false."""
    # Dividing by inf gives exactly the zero vector where the direction is undefined.
    return a / xp.where(keep, norm, xp.inf)[..., None]


def _headings(v: Any, xp: ArrayNamespace) -> Any:
    """Unit headings ``v̂_i``, the zero vector for an agent at rest."""
    speed = _norm(v, xp)
    return _unit(v, speed, speed > 0, xp)


def _weights(members: Any, like: Any, xp: ArrayNamespace) -> tuple[Any, Any]:
    """``(w (..., N), Σ w (...))``: the members as weights in the dtype of ``like``."""
    w = xp.astype(members, like)
    return w, xp.sum(w, axis=-1)


def _mean_members(a: Any, members: Any | None, xp: ArrayNamespace) -> Any:
    """The mean over the agents of vectors ``(..., N, d)``, or over the members only."""
    if members is None:
        return xp.mean_agents(a)
    w, count = _weights(members, a, xp)
    return xp.sum_agents(a * w[..., None]) / count[..., None]


def _average(a: Any, members: Any | None, xp: ArrayNamespace) -> Any:
    """The mean of values ``(..., N)`` over the agents, or over the members only."""
    if members is None:
        return xp.mean(a, axis=-1)
    _, count = _weights(members, a, xp)
    return xp.sum(xp.where(members, a, 0.0), axis=-1) / count


def _relative(x: Any, xp: ArrayNamespace, members: Any | None = None) -> Any:
    """``r_ic = r_i − r_c``, shaped like ``x`` (``r_c`` the members' centroid)."""
    return x - _mean_members(x, members, xp)[..., None, :]


def _unit_relative(x: Any, xp: ArrayNamespace, members: Any | None = None) -> Any:
    """``r̂_ic``, with the zero vector for an agent at the centre (to rounding)."""
    r = _relative(x, xp, members)
    dist = _norm(r, xp)
    n = x.shape[-2]
    largest = xp.abs(x[..., 0])
    for k in range(1, x.shape[-1]):
        largest = xp.where(xp.abs(x[..., k]) > largest, xp.abs(x[..., k]), largest)
    scale = xp.amax(largest, axis=-1)[..., None]  # (..., 1): max_i |r_i|_∞
    tol = (CENTRE_RTOL * xp.eps(x) * math.sqrt(n)) * scale
    return _unit(r, dist, dist > tol, xp)


def _cross_sum_norm(r: Any, v: Any, xp: ArrayNamespace) -> Any:
    """``|Σ_i r_i × v_i|`` over the agent axis: scalar z-component in 2-D, vector in 3-D."""
    z = xp.sum(r[..., 0] * v[..., 1] - r[..., 1] * v[..., 0], axis=-1)
    if r.shape[-1] == 2:
        return xp.abs(z)
    cx = xp.sum(r[..., 1] * v[..., 2] - r[..., 2] * v[..., 1], axis=-1)
    cy = xp.sum(r[..., 2] * v[..., 0] - r[..., 0] * v[..., 2], axis=-1)
    return xp.sqrt(cx * cx + cy * cy + z * z)


def _common(x: Any, v: Any) -> Any:
    """The common floating dtype of ``x`` and ``v`` (as an array to take it from)."""
    if _is_tensor(x):
        return x
    return np.empty(0, np.result_type(x, v))


def _result(value: Any, like: Any) -> Any:
    """``value`` in the floating dtype of ``like`` (an array for numpy input)."""
    if _is_tensor(value):
        return value.to(like.dtype) if _is_tensor(like) else value
    return np.asarray(value, dtype=like.dtype if hasattr(like, "dtype") else like)


# --------------------------------------------------------------------------- statistics


def centroid(x: ArrayLike) -> np.ndarray:
    """Group centre ``r_c = (1/N) Σ_i r_i`` (Mabrouk & McInnes eq. 1; Naterop eq. 9).

    Args:
        x: positions ``(..., N, d)``.

    Returns:
        ``r_c`` shaped ``(..., d)``, in the dtype of ``x``.

    >>> centroid(np.array([[0.0, 0.0], [2.0, 0.0], [1.0, 3.0]]))
    array([1., 1.])
    """
    x = _as_state("positions", x)
    return namespace(x).mean_agents(x)


def polarization(v: ArrayLike, members: ArrayLike | None = None) -> np.ndarray:
    """Unit-heading polarization ``|Σ_i v̂_i| / N ∈ [0, 1]`` (Couzin 2002; Naterop eq. 8).

    1 when every agent heads the same way, near 0 when the headings cancel. It does not
    depend on the speeds. An agent with zero speed has no heading and contributes the
    zero vector (it still counts in ``N``), so a swarm at rest has polarization 0.
    For the speed-weighted eq. 2 of Mabrouk & McInnes use :func:`velocity_polarization`.

    Args:
        v: velocities ``(..., N, d)``.
        members: optional bool ``(..., N)``: the statistic of these agents only (the
            swarm's members when agents fail, ``swarm_envs.envs.task.agent_status``).

    Returns:
        Shape ``(...)``, in the dtype of ``v``.

    >>> float(polarization(np.array([[1.0, 0.0], [3.0, 0.0]])))
    1.0
    >>> float(polarization(np.array([[1.0, 0.0], [-3.0, 0.0]])))
    0.0
    >>> float(polarization(np.array([[2.0, 0.0], [0.0, 0.0]])))  # resting agent adds 0
    0.5
    >>> float(polarization(np.array([[2.0, 0.0], [0.0, 0.0]]), members=np.array([1, 0])))
    1.0
    """
    v = _as_state("velocities", v)
    xp = namespace(v)
    if members is None:
        value = _norm(xp.sum_agents(_headings(v, xp)), xp) / v.shape[-2]
    else:
        value = _norm(_mean_members(_headings(v, xp), members, xp), xp)
    return _result(xp.clip(value, None, 1.0), v)


def velocity_polarization(v: ArrayLike) -> np.ndarray:
    """Group polarization ``φ_G = |Σ_i v_i| / N`` (Mabrouk & McInnes eq. 2).

    The paper's form: the speed of the mean velocity, so it scales with the speeds and
    is not bounded by 1 (for unit speeds it equals :func:`polarization`).

    Args:
        v: velocities ``(..., N, d)``.

    Returns:
        Shape ``(...)``, in the dtype of ``v``.

    >>> float(velocity_polarization(np.array([[1.0, 0.0], [3.0, 0.0]])))
    2.0
    """
    v = _as_state("velocities", v)
    xp = namespace(v)
    n = v.shape[-2]
    return _result(_norm(xp.sum_agents(v), xp) / n, v)


def spherical_variance(v: ArrayLike) -> np.ndarray:
    """Spherical variance ``σ = 1 − |Σ_i v̂_i| / N ∈ [0, 1]`` (Mabrouk & McInnes eq. 4).

    Mardia's circular/spherical variance needs unit vectors, so this is
    ``1 − polarization(v)`` with the unit-heading :func:`polarization` (the paper writes
    ``1 − φ_G`` with its speed-weighted eq. 2). Resting agents contribute zero headings,
    so a swarm at rest has ``σ = 1``.

    Args:
        v: velocities ``(..., N, d)``.

    Returns:
        Shape ``(...)``, in the dtype of ``v``.

    >>> float(spherical_variance(np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]])))
    1.0
    """
    p = polarization(v)
    return _result(1 - p, p)


def angular_momentum(x: ArrayLike, v: ArrayLike, members: ArrayLike | None = None) -> np.ndarray:
    """Unit-heading angular momentum ``|Σ_i r̂_ic × v̂_i| / N ∈ [0, 1]`` (Couzin 2002).

    ``r_ic = r_i − r_c`` with ``r_c`` the :func:`centroid`. 1 for a ring of agents
    circling its centre (either way round), 0 for a translating or radially moving swarm.
    In 2-D the cross product is the scalar ``z``-component and the absolute value of the
    sum is taken; in 3-D the norm of the vector sum. An agent at rest or at the centre
    contributes 0.

    Args:
        x: positions ``(..., N, d)``.
        v: velocities, same shape.
        members: optional bool ``(..., N)``: these agents only (their own centroid).

    Returns:
        Shape ``(...)``, in the common dtype of ``x`` and ``v``.

    >>> theta = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    >>> ring = np.stack([np.cos(theta), np.sin(theta)], axis=-1)
    >>> tangent = np.stack([-np.sin(theta), np.cos(theta)], axis=-1)
    >>> round(float(angular_momentum(ring + 5.0, 0.3 * tangent)), 12)
    1.0
    >>> round(float(angular_momentum(ring, 0.3 * ring)), 12)  # expanding radially
    0.0
    """
    x, v = _as_pair(x, v)
    xp = namespace(x, v)
    r, heading = _unit_relative(x, xp, members), _headings(v, xp)
    if members is None:
        value = _cross_sum_norm(r, heading, xp) / x.shape[-2]
    else:
        w, count = _weights(members, r, xp)
        value = _cross_sum_norm(r * w[..., None], heading, xp) / count
    return _result(xp.clip(value, None, 1.0), _common(x, v))


def velocity_angular_momentum(x: ArrayLike, v: ArrayLike) -> np.ndarray:
    """Group angular momentum ``m_G = |Σ_i r̂_ic × v_i| / N`` (Mabrouk & McInnes eq. 3).

    The paper's form: unit radial direction, raw velocity, so it scales with the speeds.
    An agent at the centre contributes 0. Cross product as in :func:`angular_momentum`.

    Args:
        x: positions ``(..., N, d)``.
        v: velocities, same shape.

    Returns:
        Shape ``(...)``, in the common dtype of ``x`` and ``v``.
    """
    x, v = _as_pair(x, v)
    xp = namespace(x, v)
    n = x.shape[-2]
    value = _cross_sum_norm(_unit_relative(x, xp), v, xp) / n
    return _result(value, _common(x, v))


def raw_angular_momentum(x: ArrayLike, v: ArrayLike) -> np.ndarray:
    """Angular momentum per agent ``|Σ_i r_ic × v_i| / N`` (Naterop eq. 10, table 3).

    The mechanical angular momentum about the centroid (unit masses) divided by ``N``:
    it scales with both the size of the swarm and the speeds (Naterop's table 3 values
    above 1, e.g. 2.71 for the torus, are in this form). Cross product as in
    :func:`angular_momentum`.

    Args:
        x: positions ``(..., N, d)``.
        v: velocities, same shape.

    Returns:
        Shape ``(...)``, in the common dtype of ``x`` and ``v``.

    >>> x = np.array([[2.0, 0.0], [-2.0, 0.0]]); v = np.array([[0.0, 3.0], [0.0, -3.0]])
    >>> float(raw_angular_momentum(x, v)), float(velocity_angular_momentum(x, v))
    (6.0, 3.0)
    """
    x, v = _as_pair(x, v)
    xp = namespace(x, v)
    n = x.shape[-2]
    value = _cross_sum_norm(_relative(x, xp), v, xp) / n
    return _result(value, _common(x, v))


def _about_goal(x: Any, v: Any, goal: Any) -> tuple[Any, Any, ArrayNamespace]:
    """``(r_i − r_g (..., N, d), v, xp)`` for a goal broadcastable to ``(..., d)``."""
    x, v = _as_pair(x, v)
    xp = namespace(x, v)
    if not _is_tensor(goal):
        goal = np.asarray(goal, dtype=_common(x, v).dtype)
    if goal.shape[-1:] != x.shape[-1:]:
        raise ValueError(f"goal must have shape (..., {x.shape[-1]}), got {tuple(goal.shape)}")
    return x - goal[..., None, :], v, xp


def mean_cross_about_goal(
    r: Any, v: Any, weights: Any | None, members: Any | None, xp: ArrayNamespace
) -> Any:
    """``|Σ_i w_i r_i × v_i| / n`` for offsets from the goal ``r`` ``(..., N, d)``: the
    definition behind :func:`goal_angular_momentum` (``w = 1``) and
    :func:`tangential_speed` (``w_i = 1/|r_i|`` within the radius, else 0). Over the
    ``members`` only when given (``n`` their count, else ``N``). Unchecked and in the
    namespace ``xp`` of its arrays, for code that has checked them (a step's
    statistics)."""
    count: Any = r.shape[-2]
    w = weights
    if members is not None:
        member, count = _weights(members, r, xp)
        w = member if w is None else w * member
    wv = v if w is None else v * w[..., None]
    return _cross_sum_norm(r, wv, xp) / count


def goal_angular_momentum(
    x: ArrayLike, v: ArrayLike, goal: ArrayLike, members: ArrayLike | None = None
) -> np.ndarray:
    """True angular momentum per agent about the goal, ``|Σ_i (r_i − r_g) × v_i| / N``.

    Unit masses. Unlike the unit-heading :func:`angular_momentum` it vanishes for a
    swarm at rest, whatever its residual spin, and grows with the mill's radius and
    speed: a ring of radius ``R`` about ``r_g`` circling at speed ``s`` gives ``R s``.
    Cross product as in :func:`angular_momentum` (absolute value in 2-D, norm in 3-D).

    Args:
        x: positions ``(..., N, d)``.
        v: velocities, same shape.
        goal: the goal ``r_g``, broadcastable to ``(..., d)``.
        members: optional bool ``(..., N)``: these agents only (divided by their count).

    >>> theta = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    >>> ring = np.stack([np.cos(theta), np.sin(theta)], axis=-1)
    >>> tangent = np.stack([-np.sin(theta), np.cos(theta)], axis=-1)
    >>> round(float(goal_angular_momentum(2 * ring + 5.0, 0.3 * tangent, [5.0, 5.0])), 12)
    0.6
    """
    r, v, xp = _about_goal(x, v, goal)
    return _result(mean_cross_about_goal(r, v, None, members, xp), _common(r, v))


def tangential_speed(
    x: ArrayLike,
    v: ArrayLike,
    goal: ArrayLike,
    radius: float | None = None,
    members: ArrayLike | None = None,
) -> np.ndarray:
    """Mean tangential velocity about the goal, ``|Σ_i r̂_ig × v_i| / N``.

    ``r̂_ig`` is the unit vector from the goal to agent i (an agent on the goal
    contributes 0). It is the speed at which the swarm circles the goal, in the units
    of ``v``: ``s`` for a ring circling at speed ``s`` whatever its radius, 0 for a swarm
    that moves radially or translates past the goal, and it stays 0 for a swarm at rest.
    With ``radius``, only the agents within that distance of the goal contribute (the
    others count as 0 in the mean), so that a mill far from the goal does not count.

    Args:
        x: positions ``(..., N, d)``.
        v: velocities, same shape.
        goal: the goal ``r_g``, broadcastable to ``(..., d)``.
        radius: optional distance ``≥ 0`` from the goal.
        members: optional bool ``(..., N)``: these agents only (divided by their count).

    >>> theta = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    >>> ring = np.stack([np.cos(theta), np.sin(theta)], axis=-1)
    >>> tangent = np.stack([-np.sin(theta), np.cos(theta)], axis=-1)
    >>> round(float(tangential_speed(2 * ring, 0.3 * tangent, [0.0, 0.0])), 12)
    0.3
    >>> float(tangential_speed(2 * ring, 0.3 * tangent, [0.0, 0.0], radius=1.0))
    0.0
    """
    r, v, xp = _about_goal(x, v, goal)
    dist = _norm(r, xp)
    keep = dist > 0
    if radius is not None:
        if not radius >= 0:
            raise ValueError(f"tangential_speed: radius must be >= 0, got {radius!r}")
        keep = keep & (dist <= radius)
    weights = 1.0 / xp.where(keep, dist, xp.inf)  # 0 where the agent does not count
    return _result(mean_cross_about_goal(r, v, weights, members, xp), _common(r, v))


def nearest_neighbor_distance(x: ArrayLike) -> np.ndarray:
    """Average nearest-neighbour distance ``(1/N) Σ_i min_{j≠i} |r_i − r_j|`` (eq. 5).

    Mabrouk & McInnes eq. 5. Coincident agents have nearest-neighbour distance 0. A
    single agent has no neighbour; by convention ``N = 1`` gives 0. Memory is
    ``O(N²)`` per batch element (squared distances, square root taken after the min).

    Args:
        x: positions ``(..., N, d)``.

    Returns:
        Shape ``(...)``, in the dtype of ``x``.

    >>> square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    >>> float(nearest_neighbor_distance(square))
    1.0
    >>> float(nearest_neighbor_distance(np.zeros((1, 2))))  # N = 1
    0.0
    """
    x = _as_state("positions", x)
    n, d = x.shape[-2:]
    if n == 1:
        return np.zeros(x.shape[:-2], dtype=x.dtype)
    diff = x[..., None, :, 0] - x[..., :, None, 0]
    rho2 = diff * diff
    for k in range(1, d):
        diff = x[..., None, :, k] - x[..., :, None, k]
        rho2 += diff * diff
    idx = np.arange(n)
    rho2[..., idx, idx] = np.inf
    return _result(np.sqrt(rho2.min(axis=-1)).mean(axis=-1), x)


def expanse(x: ArrayLike, members: ArrayLike | None = None) -> np.ndarray:
    """Group expanse ``ε_G = (1/N) Σ_i |r_i − r_c|`` (Mabrouk & McInnes §1.2; Naterop eq. 11).

    The mean distance of the agents from the :func:`centroid`, as the paper's text
    defines it. The extracted eq. 6, ``(1/N) Σ_i sqrt((|r_i| − |r_c|)²)``, compares
    distances *from the origin* and so changes when the swarm is translated; that is a
    typo (``docs/models.md`` §2), not the statistic. ``N = 1`` gives 0.

    Args:
        x: positions ``(..., N, d)``.
        members: optional bool ``(..., N)``: these agents only (their own centroid).

    Returns:
        Shape ``(...)``, in the dtype of ``x``.

    >>> square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    >>> bool(np.isclose(expanse(square + 10.0), np.sqrt(2) / 2))
    True
    """
    x = _as_state("positions", x)
    xp = namespace(x)
    return _result(_average(_norm(_relative(x, xp, members), xp), members, xp), x)


def packing_density(x: ArrayLike) -> np.ndarray:
    """Packing density ``ρ = expanse / N`` (Naterop eq. 12).

    Naterop's population-normalised expanse (despite the name, larger means *less*
    densely packed).

    Args:
        x: positions ``(..., N, d)``.

    Returns:
        Shape ``(...)``, in the dtype of ``x``.
    """
    x = _as_state("positions", x)
    return _result(expanse(x) / x.shape[-2], x)


def total_energy(
    x: ArrayLike,
    v: ArrayLike,
    params: SocialPotentialParams,
    goal: ArrayLike | None = None,
) -> np.ndarray:
    """Total energy φ (Mabrouk & McInnes eq. 16) of the social-potential model.

    ``φ = Σ_i ½ m |v_i|² + Σ_{i<j} U(ρ_ij) + Σ_i V_goal(r_i)``; a thin wrapper around
    :func:`swarm_envs.physics.energy` (``docs/models.md`` §1), listed here so that every
    group statistic of the paper's §1.2 lives in one module. The goal term is included
    when ``goal`` is given and ``params.C_g > 0``.

    Args:
        x: positions ``(..., N, d)``.
        v: velocities, same shape.
        params: model parameters.
        goal: goal position broadcastable to ``(..., d)``, or ``None``.

    Returns:
        Shape ``(...)``.
    """
    x, v = _as_pair(x, v)
    g = None if goal is None else np.asarray(goal)
    return np.asarray(energy(x, v, params, g))


def fraction_within(x: ArrayLike, goal: ArrayLike, radius: ArrayLike) -> np.ndarray:
    """Fraction of agents with ``|r_i − r_g| ≤ radius`` (``docs/models.md`` §2).

    Args:
        x: positions ``(..., N, d)``.
        goal: goal position broadcastable to ``(..., d)``.
        radius: goal radius ``≥ 0`` (``inf`` allowed), a scalar or broadcastable to
            ``(...)``.

    Returns:
        Values in ``{0, 1/N, …, 1}``, shape ``(...)``, in the dtype of ``x``.

    Raises:
        ValueError: if ``radius`` is negative or NaN.

    >>> x = np.array([[0.0, 0.0], [1.0, 0.0], [3.0, 0.0], [0.0, -0.5]])
    >>> float(fraction_within(x, [0.0, 0.0], 1.0))
    0.75
    """
    x = _as_state("positions", x)
    radius = np.asarray(radius)
    if np.any(np.isnan(radius)) or np.any(radius < 0):
        raise ValueError(f"fraction_within: radius must be >= 0, got {radius!r}")
    goal = np.asarray(goal, dtype=x.dtype)
    dist = _norm(x - goal[..., None, :], NUMPY)
    inside = dist <= radius[..., None]
    return _result(inside.mean(axis=-1, dtype=x.dtype), x)


def first_passage_time(
    values: ArrayLike, dt: float, threshold: ArrayLike, *, below: bool = True
) -> np.ndarray:
    """First time a time series reaches a threshold; ``inf`` where it never does.

    For ``values`` shaped ``(T, ...)`` (time first, ``values[t]`` at time ``t·dt``, as
    :func:`swarm_envs.physics.simulate` returns its trajectories), returns ``t*·dt``
    with ``t*`` the first index where ``values[t] ≤ threshold`` (``below=True``) or
    ``values[t] ≥ threshold`` (``below=False``), shaped ``(...)``. A series that is
    already there at ``t = 0`` gives 0; one that never gets there gives ``np.inf`` (not
    NaN). NaN entries count as not reached.

    Uses (``xs`` shaped ``(T, ..., N, d)``, goal ``g``, goal radius ``R``):

    - Naterop's *response time*, the time until the first member reaches the food:
      ``first_passage_time(np.linalg.norm(xs - g, axis=-1).min(axis=-1), dt, R)``;
    - time until the centroid is within the goal radius (``docs/models.md`` §2):
      ``first_passage_time(np.linalg.norm(centroid(xs) - g, axis=-1), dt, R)``;
    - time until a fraction ``q`` of the agents is within it:
      ``first_passage_time(fraction_within(xs, g, R), dt, q, below=False)``.

    Args:
        values: time series shaped ``(T, ...)``, ``T ≥ 1``.
        dt: time between samples, ``> 0``.
        threshold: scalar or broadcastable against ``values[0]``.
        below: look for ``values ≤ threshold`` (default) or ``values ≥ threshold``.

    Returns:
        Shape ``(...)``: the dtype of ``values`` if floating, else float64.

    >>> d = np.array([5.0, 3.0, 0.8, 0.2, 0.9])
    >>> float(first_passage_time(d, 0.1, 1.0))
    0.2
    >>> float(first_passage_time(d, 0.1, 0.0))
    inf
    >>> float(first_passage_time(d, 0.1, 3.0, below=False))
    0.0
    """
    values = np.asarray(values)
    if values.ndim < 1 or values.shape[0] < 1:
        raise ValueError(f"values must be shaped (T, ...) with T >= 1, got {values.shape}")
    if not np.isfinite(dt) or dt <= 0:
        raise ValueError(f"first_passage_time: dt must be finite and > 0, got {dt!r}")
    dtype = values.dtype if np.issubdtype(values.dtype, np.floating) else np.dtype(np.float64)
    hit = values <= threshold if below else values >= threshold
    reached = hit.any(axis=0)
    index = hit.argmax(axis=0)
    time = index.astype(dtype) * dtype.type(dt)
    return np.where(reached, time, dtype.type(np.inf)).astype(dtype, copy=False)
