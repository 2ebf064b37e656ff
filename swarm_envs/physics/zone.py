"""Zone model with informed individuals (Couzin et al. 2002, as in Naterop §4.1).

References: I. D. Couzin, J. Krause, R. James, G. D. Ruxton and N. R. Franks,
*Collective memory and spatial sorting in animal groups*, J. theor. Biol. 218 (2002) 1–11;
Naterop, Petrides & Prasad, *Implementing two mathematical swarm models…* (seed ``003``),
§4.1 "Unit-vector-based model" (eqs. 1–7, table 1) and §5.3 (table 3). The reading is the
one documented in ``docs/models.md`` §3.

The model is kinematic with constant speed: agent ``i`` has a position ``r_i`` and a unit
heading ``η̂_i``, and moves with ``v_i = s_i η̂_i`` (Naterop eq. 2). Each step, among its
``λ`` nearest neighbours (Naterop §4.1), with ``u_ij = (r_j − r_i)/|r_j − r_i|``:

- **repulsion** (eq. 3, highest priority): if any neighbour lies in ``[0, r_r)``, the
  desired direction is ``d_i = −Σ u_ij`` over those neighbours;
- otherwise (eq. 4) ``d_i = ½ (Σ_{orientation} η̂_j + Σ_{attraction} u_ij)`` over the
  neighbours in ``[r_r, r_o)`` and ``[r_o, r_a)``; with no neighbour in any zone (or a
  desired vector that cancels to zero) the agent keeps its heading;
- **informed agents** (eq. 6) blend in the unit vector ``ĝ_i`` toward the food/goal:
  ``d̂_i ← (d̂_i + ω ĝ_i)/|d̂_i + ω ĝ_i|``;
- **turning limit** (eq. 5): the heading rotates toward ``d̂_i`` by at most ``φ̄`` (the
  maximum turning angle *per step*, Naterop 50°); in 2-D this is an exact rotation by
  ``clip(θ, −φ̄, φ̄)``, in 3-D a rotation in the plane of ``η̂_i`` and ``d̂_i``;
- the position moves with the new heading: ``r_i ← r_i + dt s_i η̂_i``.

Per-agent parameters (eq. 7): each agent draws its own ``r_r, r_o, r_a, φ̄, s`` as
``μ_i = μ_0 (1 + σ ξ_i)``, ``ξ_i ~ N(0, 1)`` (see :class:`ZoneParams.param_spread` for why
the spread is read as relative), clipped at 0 (and ``φ̄`` at π).

Zone boundaries are half-open, ``[0, r_r)``, ``[r_r, r_o)``, ``[r_o, r_a)``, so ``r_o = r_r``
switches the orientation zone off exactly and ``r_a = r_o`` the attraction zone. Neither
Naterop nor Couzin et al. (2002) use a blind angle here or angular noise in Naterop's
version; this module has neither. Arrays are shaped ``(..., N, d)`` (any leading batch
dimensions, ``d = 2`` or ``3``); pairwise terms are ``(..., N, N)`` arrays, and nothing
loops over agents or pairs in Python.

Coincident agents (``ρ_ij = 0``): the direction ``u_ij`` is taken as the zero vector
(the distance is floored at :data:`RHO_FLOOR`). A coincident neighbour is inside
``r_r``, so it switches repulsion on but contributes no direction; if nothing else is
in the repulsion zone the desired vector is zero and the agent keeps its heading.
Nothing returns NaN.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from swarm_envs.physics._validation import check_goal, check_real, check_run, check_state

#: Distances are floored at this value before dividing (coincident-agent convention).
RHO_FLOOR = 1e-12

#: A desired vector shorter than this counts as zero (the agent keeps its heading).
DIRECTION_FLOOR = 1e-12


@dataclass(frozen=True)
class ZoneParams:
    """Parameters of the zone model (Naterop §4.1, table 1; Couzin et al. 2002).

    All fields are validated on construction: a non-finite or out-of-range value raises
    :class:`ValueError` naming the field and the allowed range. Defaults are Naterop's
    table 1 with ``r_o = 9`` (their "dynamic parallel" row of table 3) and all agents as
    neighbours (``λ = N − 1``).

    >>> ZoneParams().max_turn == math.radians(50)
    True
    >>> ZoneParams(r_o=20.0)
    Traceback (most recent call last):
    ...
    ValueError: ZoneParams.r_o must be in [1, 15], got 20.0
    """

    r_r: float = 1.0
    """Repulsion radius ``r_r`` (eq. 3, table 1: 1 m); zone ``[0, r_r)``, ``≥ 0``."""
    r_o: float = 9.0
    """Orientation radius ``r_o`` (eq. 4, table 1: 2–13 m); zone ``[r_r, r_o)``,
    ``r_r ≤ r_o ≤ r_a``."""
    r_a: float = 15.0
    """Attraction radius ``r_a`` (eq. 4, table 1: 15 m); zone ``[r_o, r_a)``, ``≥ r_r``."""
    n_neighbors: int | None = None
    """``λ``, the number of nearest neighbours an agent considers (§4.1; table 1: "up to
    N"), an integer ``≥ 1``; ``None`` means all others (``λ = N − 1``)."""
    speed: float = 2.0
    """Speed ``|v|`` (eq. 2, table 1: 2 m/s), ``> 0``."""
    max_turn: float = math.radians(50.0)
    """Maximum turning angle per step ``φ̄`` in radians (eq. 5, table 1: 50°), ``[0, π]``."""
    omega: float = 0.5
    """Weight ``ω`` of the direction to the food for informed agents (eq. 6), ``≥ 0``.
    Naterop does not give it; 0.5 is a value used by Couzin et al., Nature 433 (2005)."""
    informed_fraction: float = 0.2
    """Fraction of informed agents (eq. 6: 1 in 5), ``[0, 1]``; the count per group is
    ``round(fraction · N)``, drawn uniformly without replacement."""
    param_spread: float = 0.05
    """Relative Gaussian spread ``σ`` of the per-agent parameters (eq. 7, table 1: 0.05),
    ``≥ 0``: ``μ_i = μ_0 (1 + σ ξ_i)``. Table 1 lists σ without units while the same σ
    applies to radii (m), speed (m/s) and angle (°), so only a relative spread is
    consistent."""

    def __post_init__(self) -> None:
        name = type(self).__name__
        r_r = check_real(name, "r_r", self.r_r, low=0.0)
        object.__setattr__(self, "r_r", r_r)
        r_a = check_real(name, "r_a", self.r_a, low=r_r)
        object.__setattr__(self, "r_a", r_a)
        object.__setattr__(self, "r_o", check_real(name, "r_o", self.r_o, low=r_r, high=r_a))
        lam = self.n_neighbors
        if lam is not None:
            if isinstance(lam, bool) or not isinstance(lam, (int, np.integer)) or lam < 1:
                raise ValueError(
                    f"{name}.n_neighbors must be an integer >= 1 or None (all), got {lam!r}"
                )
            object.__setattr__(self, "n_neighbors", int(lam))
        object.__setattr__(
            self, "speed", check_real(name, "speed", self.speed, low=0.0, low_inclusive=False)
        )
        object.__setattr__(
            self, "max_turn", check_real(name, "max_turn", self.max_turn, low=0.0, high=math.pi)
        )
        object.__setattr__(self, "omega", check_real(name, "omega", self.omega, low=0.0))
        object.__setattr__(
            self,
            "informed_fraction",
            check_real(name, "informed_fraction", self.informed_fraction, low=0.0, high=1.0),
        )
        object.__setattr__(
            self, "param_spread", check_real(name, "param_spread", self.param_spread, low=0.0)
        )

    @classmethod
    def naterop(cls, r_o: float = 9.0, **overrides: Any) -> ZoneParams:
        """Naterop's table 1 set with the given orientation radius (table 3: 2, 5, 9, 13)."""
        values: dict[str, Any] = {
            "r_r": 1.0,
            "r_o": r_o,
            "r_a": 15.0,
            "n_neighbors": None,
            "speed": 2.0,
            "max_turn": math.radians(50.0),
            "omega": 0.5,
            "informed_fraction": 0.2,
            "param_spread": 0.05,
        }
        values.update(overrides)
        return cls(**values)

    @classmethod
    def navigation(cls, **overrides: Any) -> ZoneParams:
        """The SwarmNav default (``dynamics="zone"``): Naterop's zones scaled to the task.

        The goal lies 8–12 m away with a 1.5 m arrival radius, so the zones shrink to
        ``r_r = 0.3, r_o = 1, r_a = 3`` m, the speed to 1 m/s and the turn to 30° per
        0.1 s step; the spread (σ = 0.05), ``ω = 0.5`` and 1 in 5 informed stay Naterop's.
        """
        values: dict[str, Any] = {
            "r_r": 0.3,
            "r_o": 1.0,
            "r_a": 3.0,
            "speed": 1.0,
            "max_turn": math.radians(30.0),
        }
        return cls(**{**values, **overrides})

    @property
    def max_turn_degrees(self) -> float:
        """``φ̄`` in degrees, as the report states it."""
        return math.degrees(self.max_turn)


class ZoneAgentParams(NamedTuple):
    """Per-agent parameters (Naterop eq. 7), each an array broadcastable to ``(..., N)``."""

    r_r: np.ndarray
    r_o: np.ndarray
    r_a: np.ndarray
    speed: np.ndarray
    max_turn: np.ndarray


def uniform_agent_params(params: ZoneParams) -> ZoneAgentParams:
    """The swarm's values for every agent (no spread), as 0-d arrays."""
    return ZoneAgentParams(
        *(np.asarray(getattr(params, k)) for k in ("r_r", "r_o", "r_a", "speed", "max_turn"))
    )


def draw_agent_params(
    params: ZoneParams, rng: np.random.Generator, shape: tuple[int, ...]
) -> ZoneAgentParams:
    """Per-agent parameters ``μ_i = μ_0 (1 + σ ξ_i)`` shaped ``shape = (..., N)`` (eq. 7).

    One independent ``ξ ~ N(0, 1)`` per agent and parameter, drawn from ``rng`` in the
    order ``r_r, r_o, r_a, speed, max_turn``; values are clipped at 0 (``max_turn`` also
    at π). With ``σ = 0`` nothing is drawn.
    """
    sigma = params.param_spread
    if sigma == 0:
        base = uniform_agent_params(params)
        return ZoneAgentParams(*(np.broadcast_to(a, shape).copy() for a in base))
    out = {}
    for k in ("r_r", "r_o", "r_a", "speed", "max_turn"):
        out[k] = np.maximum(getattr(params, k) * (1.0 + sigma * rng.standard_normal(shape)), 0.0)
    out["max_turn"] = np.minimum(out["max_turn"], math.pi)
    return ZoneAgentParams(**out)


def informed_count(params: ZoneParams, n_agents: int) -> int:
    """``round(informed_fraction · N)`` (halves rounded up): 13 of 64 for 1 in 5."""
    return math.floor(params.informed_fraction * n_agents + 0.5)


def draw_informed(
    params: ZoneParams, rng: np.random.Generator, shape: tuple[int, ...]
) -> np.ndarray:
    """Boolean mask ``shape = (..., N)`` with exactly :func:`informed_count` true per group.

    The informed agents are chosen uniformly without replacement (Naterop §4.1.2).
    """
    k = informed_count(params, shape[-1])
    ranks = np.argsort(np.argsort(rng.random(shape), axis=-1), axis=-1)
    return ranks < k


# --------------------------------------------------------------------------- geometry


def _normalize(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(a/|a|, |a|>floor)``; the zero vector where ``|a|`` is below the floor."""
    norm = np.sqrt(np.einsum("...k,...k->...", a, a))
    ok = norm > DIRECTION_FLOOR
    return a / np.where(ok, norm, np.inf)[..., None], ok


def neighbor_mask(rho: np.ndarray, n_neighbors: int | None) -> np.ndarray:
    """Boolean ``(..., N, N)``: ``j`` is one of the ``λ`` nearest others of ``i``.

    ``rho`` holds the pair distances with ``inf`` (or any value larger than all others)
    on the diagonal. ``None`` or ``λ ≥ N − 1`` selects every other agent. Ties at equal
    distance are broken by :func:`numpy.argpartition` (deterministic).
    """
    n = rho.shape[-1]
    if n_neighbors is None or n_neighbors >= n - 1:
        return ~np.eye(n, dtype=bool)
    idx = np.argpartition(rho, n_neighbors - 1, axis=-1)[..., :n_neighbors]
    mask = np.zeros(rho.shape, dtype=bool)
    np.put_along_axis(mask, idx, True, axis=-1)
    return mask


def _agent(a: Any, like: np.ndarray) -> np.ndarray:
    """A per-agent value as an array broadcastable to ``(..., N, 1)`` (for pair masks)."""
    a = np.asarray(a, dtype=like.dtype)
    return a[..., None] if a.ndim else a


def desired_direction(
    x: np.ndarray,
    heading: np.ndarray,
    params: ZoneParams,
    goal: np.ndarray | None = None,
    informed: np.ndarray | None = None,
    *,
    agent_params: ZoneAgentParams | None = None,
) -> np.ndarray:
    """Unit desired direction ``d̂_i`` of every agent (Naterop eqs. 3, 4 and 6).

    Repulsion has priority (eq. 3); otherwise ``½`` (orientation + attraction) (eq. 4);
    with neither, or a sum that cancels, the current heading. Informed agents
    (``informed`` true, a goal given) use ``(d̂_i + ω ĝ_i)/|…|`` (eq. 6); an agent exactly
    on the goal has ``ĝ_i = 0``.

    Args:
        x: positions ``(..., N, d)``.
        heading: unit headings ``η̂``, same shape.
        params: model parameters (``n_neighbors``, ``omega``; the radii unless
            ``agent_params`` is given).
        goal: food/goal position broadcastable to ``(..., d)``, or ``None``.
        informed: boolean mask broadcastable to ``(..., N)``; ignored without a goal.
        agent_params: per-agent radii (eq. 7); default the swarm's values.

    Returns:
        Unit vectors shaped like ``x``.

    >>> x = np.array([[0.0, 0.0], [0.5, 0.0]]); h = np.array([[0.0, 1.0], [0.0, 1.0]])
    >>> (desired_direction(x, h, ZoneParams()) + 0.0).tolist()  # repulsion: apart
    [[-1.0, 0.0], [1.0, 0.0]]
    """
    x, heading = check_state(x, heading)
    ap = uniform_agent_params(params) if agent_params is None else agent_params
    d = x.shape[-1]
    dx = [x[..., None, :, k] - x[..., :, None, k] for k in range(d)]  # r_ij = r_j − r_i
    rho2 = dx[0] * dx[0]
    for k in range(1, d):
        rho2 += dx[k] * dx[k]
    rho = np.sqrt(rho2, out=rho2)
    n = x.shape[-2]
    diag = np.eye(n, dtype=bool)
    inv_rho = np.where(diag | (rho <= RHO_FLOOR), 0.0, 1.0 / np.maximum(rho, RHO_FLOOR))
    near = neighbor_mask(np.where(diag, np.inf, rho), params.n_neighbors)

    in_r = near & (rho < _agent(ap.r_r, x))
    rest = near & ~in_r
    in_o = rest & (rho < _agent(ap.r_o, x))
    in_a = rest & ~in_o & (rho < _agent(ap.r_a, x))

    def unit_sum(mask: np.ndarray) -> np.ndarray:
        w = mask * inv_rho
        return np.stack([np.einsum("...ij,...ij->...i", w, dx[k]) for k in range(d)], axis=-1)

    repulse = -unit_sum(in_r)
    social = 0.5 * (np.matmul(in_o.astype(x.dtype), heading) + unit_sum(in_a))
    has_r = in_r.any(axis=-1)
    desired = np.where(has_r[..., None], repulse, social)
    d_hat, ok = _normalize(desired)
    h_hat, _ = _normalize(heading)
    d_hat = np.where(ok[..., None], d_hat, h_hat)

    if goal is not None and informed is not None and params.omega > 0:
        g = check_goal(goal, x)
        g_hat, _ = _normalize(g[..., None, :] - x)
        blended, ok_b = _normalize(d_hat + params.omega * g_hat)
        use = np.asarray(informed, dtype=bool)[..., None] & ok_b[..., None]
        d_hat = np.where(use, blended, d_hat)
    return d_hat


def _perpendicular(h: np.ndarray) -> np.ndarray:
    """A unit vector perpendicular to each unit ``h`` (3-D), chosen deterministically."""
    axis = np.zeros_like(h)
    np.put_along_axis(axis, np.argmin(np.abs(h), axis=-1)[..., None], 1.0, axis=-1)
    p, _ = _normalize(np.cross(h, axis))
    return p


def turn_toward(heading: np.ndarray, desired: np.ndarray, max_turn: Any) -> np.ndarray:
    """Rotate unit headings toward ``desired`` by at most ``max_turn`` radians (eq. 5).

    If the angle ``θ`` between ``η̂`` and ``d̂`` is at most ``φ̄`` the result is ``d̂``;
    otherwise ``η̂`` rotated by ``φ̄`` toward ``d̂``. In 2-D this is the exact rotation by
    ``clip(θ, −φ̄, φ̄)`` (signed angle from ``atan2``; an exactly opposite ``d̂`` turns
    counter-clockwise). In 3-D the rotation is in the plane of ``η̂`` and ``d̂`` (for an
    exactly opposite ``d̂``, a deterministic perpendicular plane). A zero ``desired``
    keeps the heading.

    Args:
        heading: unit headings ``(..., N, d)``.
        desired: desired directions, same shape (need not be unit).
        max_turn: ``φ̄``, scalar or broadcastable to ``(..., N)``, in ``[0, π]``.

    Returns:
        Unit headings shaped like ``heading``.

    >>> h = np.array([[1.0, 0.0]]); d = np.array([[0.0, 1.0]])
    >>> np.round(turn_toward(h, d, np.pi / 4), 6).tolist()
    [[0.707107, 0.707107]]
    """
    h, _ = _normalize(np.asarray(heading, dtype=float))
    d_hat, ok = _normalize(np.asarray(desired, dtype=h.dtype))
    phi = np.asarray(max_turn, dtype=h.dtype)
    if h.shape[-1] == 2:
        cross = h[..., 0] * d_hat[..., 1] - h[..., 1] * d_hat[..., 0]
        dot = h[..., 0] * d_hat[..., 0] + h[..., 1] * d_hat[..., 1]
        theta = np.arctan2(cross, dot)
        within = np.abs(theta) <= phi
        ang = np.clip(theta, -phi, phi)
        c, s = np.cos(ang), np.sin(ang)
        rot = np.stack([c * h[..., 0] - s * h[..., 1], s * h[..., 0] + c * h[..., 1]], axis=-1)
    else:
        dot = np.clip(np.einsum("...k,...k->...", h, d_hat), -1.0, 1.0)
        theta = np.arccos(dot)
        within = theta <= phi
        e, ok_e = _normalize(d_hat - dot[..., None] * h)
        e = np.where(ok_e[..., None], e, _perpendicular(h))
        ang = np.minimum(theta, phi)[..., None]
        rot = np.cos(ang) * h + np.sin(ang) * e
    out = np.where(within[..., None], d_hat, rot)
    out = np.where(ok[..., None], out, h)
    unit, _ = _normalize(out)
    return unit


def zone_step(
    x: np.ndarray,
    heading: np.ndarray,
    params: ZoneParams,
    *,
    dt: float,
    goal: np.ndarray | None = None,
    informed: np.ndarray | None = None,
    rng: np.random.Generator | None = None,
    agent_params: ZoneAgentParams | None = None,
    bias: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """One step of the zone model: turn toward :func:`desired_direction`, then move.

    ``η̂' = turn_toward(η̂, d̂, φ̄_i)``, ``r' = r + dt s_i η̂'`` (Naterop eqs. 2–6).
    ``bias`` (shaped like ``x``), when given, is added to the unit desired direction
    before the turn, ``d̂_i + b_i`` (how the SwarmNav environments apply an action,
    ``docs/models.md`` §6; ``b_i = ω ĝ_i`` is the informed-individual rule of eq. 6); a
    zero bias leaves the model unchanged.
    ``rng`` is accepted for a uniform signature; this step is deterministic (the random
    parts of the model, the per-agent parameters and the informed subset, are drawn
    once per run by :func:`simulate_zone`). Returns new arrays ``(x', η̂')``.

    >>> x = np.array([[0.0, 0.0], [20.0, 0.0]]); h = np.array([[1.0, 0.0], [1.0, 0.0]])
    >>> x1, h1 = zone_step(x, h, ZoneParams(), dt=0.5)  # nobody within r_a: straight on
    >>> x1.tolist(), h1.tolist()
    ([[1.0, 0.0], [21.0, 0.0]], [[1.0, 0.0], [1.0, 0.0]])
    """
    del rng
    ap = uniform_agent_params(params) if agent_params is None else agent_params
    desired = desired_direction(x, heading, params, goal, informed, agent_params=ap)
    if bias is not None:
        desired = desired + bias
    new_heading = turn_toward(heading, desired, ap.max_turn).astype(np.asarray(x).dtype)
    speed = np.asarray(ap.speed, dtype=new_heading.dtype)
    step = (dt * speed)[..., None] if speed.ndim else dt * speed
    return x + step * new_heading, new_heading


def initial_headings(v0: np.ndarray, rng: np.random.Generator | None) -> np.ndarray:
    """Unit headings from the directions of ``v0``; uniform random where ``v0 = 0``.

    Raises:
        ValueError: naming ``rng`` if some ``v0`` is zero and no generator is given.
    """
    h, ok = _normalize(v0)
    if ok.all():
        return h
    if rng is None:
        raise ValueError(
            "simulate_zone: rng (a numpy Generator) is required to draw the headings of "
            "agents with zero initial velocity"
        )
    r, _ = _normalize(rng.standard_normal(v0.shape))
    return np.where(ok[..., None], h, r).astype(v0.dtype)


def simulate_zone(
    params: ZoneParams,
    x0: Any,
    v0: Any,
    *,
    dt: float,
    steps: int,
    goal: Any | None = None,
    rng: np.random.Generator | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Run the zone model from ``(x0, v0)`` for ``steps`` steps of length ``dt``.

    The initial heading is ``v0``'s direction (uniform random where ``v0 = 0``); the
    returned velocities are ``s_i η̂_i`` (so ``vs[0]`` has the initial headings at the
    agents' speeds, not ``v0`` itself). Random parts, drawn once per run from ``rng`` in
    this order: headings for zero ``v0``; per-agent parameters (eq. 7) when
    ``param_spread > 0``; the informed subset (eq. 6) when ``informed_fraction > 0`` and a
    goal is given (without a goal nobody can be informed).

    Args:
        params: model parameters.
        x0, v0: initial positions and velocities ``(..., N, d)``.
        dt: time step, ``> 0``. ``max_turn`` is per step, so the dynamics depend on it.
        steps: number of steps, ``≥ 0``.
        goal: food position broadcastable to ``(..., d)``, or ``None``.
        rng: numpy Generator; required when something above must be drawn.

    Returns:
        ``(xs, vs)``, each shaped ``(steps + 1, ..., N, d)``; index 0 is the start.

    Raises:
        ValueError: for invalid arguments; naming ``rng`` when it is needed and missing.

    >>> xs, vs = simulate_zone(ZoneParams(param_spread=0.0), np.zeros((3, 2)),
    ...                        np.ones((3, 2)), dt=0.1, steps=4)
    >>> xs.shape, bool(np.allclose(np.linalg.norm(vs, axis=-1), 2.0))
    ((5, 3, 2), True)
    """
    if not isinstance(params, ZoneParams):
        raise ValueError(
            f"simulate_zone: unsupported parameter type {type(params).__name__}; "
            "expected ZoneParams"
        )
    dt, steps = check_run("simulate_zone", dt, steps)
    x, v = check_state(x0, v0)
    if goal is not None:
        goal = check_goal(goal, x)
    need_informed = goal is not None and params.informed_fraction > 0
    if rng is None and (params.param_spread > 0 or need_informed):
        what = "param_spread > 0" if params.param_spread > 0 else "informed_fraction > 0"
        raise ValueError(
            f"simulate_zone: rng (a numpy Generator) is required when {what}; "
            "pass rng=numpy.random.default_rng(seed)"
        )
    heading = initial_headings(v, rng)
    shape = x.shape[:-1]
    if params.param_spread > 0:
        assert rng is not None
        ap = draw_agent_params(params, rng, shape)
    else:
        ap = uniform_agent_params(params)
    informed = None
    if need_informed:
        assert rng is not None
        informed = draw_informed(params, rng, shape)
    speed = np.asarray(ap.speed, dtype=x.dtype)
    speed = speed[..., None] if speed.ndim else speed
    xs = np.empty((steps + 1, *x.shape), dtype=x.dtype)
    vs = np.empty_like(xs)
    xs[0], vs[0] = x, speed * heading
    for n in range(steps):
        x, heading = zone_step(
            x, heading, params, dt=dt, goal=goal, informed=informed, agent_params=ap
        )
        xs[n + 1], vs[n + 1] = x, speed * heading
    return xs, vs
