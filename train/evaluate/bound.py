"""A lower bound on the time to goal: no policy can bring the swarm in sooner.

Navigation succeeds when every agent is within the arrival radius ``R`` of the goal at
once, so the swarm's centroid ``c`` is then within ``R`` of the goal too. What bounds
the time depends on the model:

- **social potential** (navigation and informed tasks, linear friction ``α = 0``, no
  passive sink): the pair forces (Morse and alignment) are equal and opposite, so they
  cancel in the sum and the centroid obeys ``m c̈ = ⟨u_i⟩ − β ċ``, where the mean
  control ``⟨u_i⟩`` lies in the action box like each agent's. The box's components
  are independent, so the centroid's reachable positions at time ``t`` form a box too:
  along each axis, the interval between full thrust backward and full thrust forward
  from that axis's start velocity. The bound is the first step at which that box meets
  the ball of radius ``R`` about the goal. Each end of an interval is the farther of
  the exact flow's and the one-substep semi-implicit Euler recursion's (the integrator's
  own progress, which runs slightly ahead; more substeps approach the flow).
- **zone model**: every agent must be within ``R`` of the goal, and agent ``i`` moves
  exactly ``s_i dt`` per step (its own speed ``s_i = |v_i|``, drawn with the model's
  spread) along a heading that turns by at most its own ``φ_i`` per step before it moves.
  After ``n`` steps its heading's angle to the line from its start to the goal is at
  least ``θ_i − nφ_i`` (``θ_i`` at the start), so its progress along that line is at most
  ``s_i dt Σ_{k ≤ n} cos(max(0, θ_i − kφ_i))``; it needs ``D_i − R`` (``D_i`` its start
  distance). The bound is the slowest agent's first such step (without the per-agent
  ``φ_i``, the straight line: ``⌈(D_i − R) / (s_i dt)⌉``).

Elsewhere — the piecewise model (its neighbour forces are one-way and do not cancel),
the Lagrangian model, self-propulsion, a passive sink, a task with its own success rule
or one that holds a state (the mill, a user's task: ``TaskSpec.success``,
``terminates_on_success``), ``success_fraction
< 1`` or perturbations that change who acts — no bound is defined (``None``). The bound
ignores everything else that slows a real swarm (keeping together, braking, and in the
informed task that most agents do not know where the goal is), so a policy at the bound
is optimal, and one within a few percent of it has little left to gain.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from swarm_envs.config import SwarmConfig

__all__ = [
    "NEAR_OPTIMAL",
    "bound_of_episodes",
    "bound_reason",
    "free_agent_time",
    "time_over_bound",
    "time_to_goal_bound",
]

#: A policy whose time over the bound is at most this (5 %) is near-optimal: no policy
#: can arrive sooner by more, so the tables do not count its row as one to win.
NEAR_OPTIMAL = 0.05


def bound_reason(cfg: SwarmConfig) -> str | None:
    """Why no bound is defined for ``cfg`` (``None``: one is).

    >>> bound_reason(SwarmConfig()) is None
    True
    >>> bound_reason(SwarmConfig(dynamics="piecewise"))
    "dynamics 'piecewise': the pair forces do not cancel"
    """
    p = cfg.perturbations
    spec = cfg.task_spec
    if spec.success is not None or not spec.terminates_on_success:
        return f"task {cfg.task!r}: its success is not the swarm gathered at the goal"
    if cfg.success_fraction < 1.0:
        return "success_fraction < 1"
    if any(
        float(np.max(getattr(p, k))) > 0
        for k in ("failed_fraction", "absent_fraction", "join_fraction", "action_noise")
    ):
        return "perturbations change who acts or how"
    if cfg.dynamics == "zone":
        return None
    if cfg.dynamics != "social_potential":
        return f"dynamics {cfg.dynamics!r}: the pair forces do not cancel"
    if cfg.physics.alpha > 0:
        return "self-propulsion"
    if cfg.passive_sink:
        return "the passive sink"
    return None


def time_to_goal_bound(
    cfg: SwarmConfig,
    x: np.ndarray,
    v: np.ndarray,
    goal: np.ndarray,
    max_turn: np.ndarray | None = None,
) -> np.ndarray | None:
    """The lower bound (simulated seconds, a multiple of ``dt``) on each swarm's time to
    goal from its start state, ``(B,)``; ``None`` where no bound is defined
    (:func:`bound_reason`).

    Args:
        cfg: the scenario.
        x, v: start positions and velocities ``(B, N, d)``.
        goal: goals ``(B, d)``.
        max_turn: the zone model's per-agent turning limits ``φ_i`` ``(B, N)`` in radians
            (``EpisodeBatch.start["max_turn"]``); ``None``: no turning limit counted
            (a looser bound, still one). Other models ignore it.

    >>> import dataclasses
    >>> from swarm_envs.physics import SocialPotentialParams
    >>> no_drag = dataclasses.replace(SocialPotentialParams.navigation(), beta=0.0)
    >>> cfg = SwarmConfig(physics=no_drag)               # no drag: ½ a t² ≥ D − R
    >>> x = np.zeros((1, 2, 2)); v = np.zeros((1, 2, 2))
    >>> float(time_to_goal_bound(cfg, x, v, np.array([[7.5, 0.0]]))[0])  # 6 = ½·3·t²: t = 2
    2.0
    """
    if bound_reason(cfg) is not None:
        return None
    x = np.asarray(x, np.float64)
    v = np.asarray(v, np.float64)
    goal = np.asarray(goal, np.float64)
    if cfg.dynamics == "zone":
        return _zone_steps(cfg, x, v, goal, max_turn).max(axis=1) * cfg.dt
    centroid, drift = x.mean(axis=1), v.mean(axis=1)
    return _steps_to_reach(cfg, goal - centroid, drift) * cfg.dt


def bound_of_episodes(cfg: SwarmConfig, start: Mapping[str, np.ndarray]) -> np.ndarray | None:
    """:func:`time_to_goal_bound` of the episodes whose start state is ``start``
    (``EpisodeBatch.start``: ``x``, ``v``, ``goal`` and, for the zone model,
    ``max_turn``)."""
    return time_to_goal_bound(
        cfg, start["x"], start["v"], start["goal"], max_turn=start.get("max_turn")
    )


def _zone_steps(
    cfg: SwarmConfig, x: np.ndarray, v: np.ndarray, goal: np.ndarray, max_turn: Any
) -> np.ndarray:
    """Steps until each agent of the zone model can first be within the arrival radius
    ``(B, N)`` (``max_steps + 1``: never): the module docstring's per-agent bound.

    Args:
        cfg: the scenario (``dt``, ``max_steps``, the radius).
        x, v: start positions and velocities ``(B, N, d)`` (``|v_i|`` is the speed).
        goal: goals ``(B, d)``.
        max_turn: per-agent turning limits ``(B, N)`` or ``None`` (π: none).
    """
    dt, radius = cfg.dt, cfg.arrival_radius
    speed = np.sqrt(np.einsum("bnk,bnk->bn", v, v))
    offset = goal[:, None, :] - x
    distance = np.sqrt(np.einsum("bnk,bnk->bn", offset, offset))
    cos = np.einsum("bnk,bnk->bn", v, offset) / np.maximum(speed * distance, 1e-300)
    angle = np.arccos(np.clip(cos, -1.0, 1.0))
    phi = np.broadcast_to(math.pi if max_turn is None else np.asarray(max_turn), angle.shape)
    # The positions are sums of rounded steps: a bound that an exact arrival meets must
    # not wait for the last ulp.
    need = distance - radius - 1e-9 * np.maximum(distance, 1.0)
    steps = np.where(need <= 0, 0, cfg.max_steps + 1)
    progress = np.zeros_like(distance)
    for n in range(1, cfg.max_steps + 1):
        open_ = steps > n - 1
        if not open_.any():
            break
        progress += speed * dt * np.cos(np.maximum(angle - n * phi, 0.0))
        steps = np.where(open_ & (progress >= need), n, steps)
    return steps


def _steps_to_reach(cfg: SwarmConfig, offset: np.ndarray, speed: np.ndarray) -> np.ndarray:
    """Steps of ``dt`` until a point driven by ``m s̈ = u − β ṡ``, each component of
    ``u`` in ``[−u_max, u_max]``, can first be within the arrival radius of ``offset``
    (``max_steps + 1``: never).

    The components are independent, so the points reachable at time ``t`` form a box:
    along each axis the interval between full thrust backward and full thrust forward
    from that axis's start speed. The bound is the first step at which that box meets
    the ball of the arrival radius about ``offset``. Each end of an interval is the farther of
    the exact flow's and one-substep semi-implicit Euler's (the integrator's own
    recursion, which runs slightly ahead of the flow).

    Args:
        cfg: the scenario (``u_max``, ``m``, ``β``, ``dt``, ``max_steps``, the radius).
        offset: the target relative to the start, ``(..., d)``.
        speed: the start velocity, ``(..., d)``.

    Returns:
        ``(...)`` integer steps.
    """
    radius, dt, max_steps = cfg.arrival_radius, cfg.dt, cfg.max_steps
    accel, drag = cfg.u_max / cfg.physics.m, cfg.physics.beta / cfg.physics.m
    offset = np.asarray(offset, np.float64)
    speed = np.asarray(speed, np.float64)
    shape = offset.shape[:-1]
    steps = np.full(shape, max_steps + 1)
    steps[_inside(offset, np.zeros_like(offset), np.zeros_like(offset), radius)] = 0
    v_hi, v_lo = speed.copy(), speed.copy()
    s_hi, s_lo = np.zeros_like(offset), np.zeros_like(offset)
    for n in range(1, max_steps + 1):
        open_ = steps > n - 1
        if not open_.any():
            break
        v_hi = v_hi + dt * (accel - drag * v_hi)
        v_lo = v_lo + dt * (-accel - drag * v_lo)
        s_hi, s_lo = s_hi + dt * v_hi, s_lo + dt * v_lo
        t = n * dt
        if drag > 0:
            terminal, decay = accel / drag, (1.0 - math.exp(-drag * t)) / drag
            exact_hi = terminal * t + (speed - terminal) * decay
            exact_lo = -terminal * t + (speed + terminal) * decay
        else:
            exact_hi = speed * t + 0.5 * accel * t * t
            exact_lo = speed * t - 0.5 * accel * t * t
        hi, lo = np.maximum(s_hi, exact_hi), np.minimum(s_lo, exact_lo)
        steps = np.where(open_ & _inside(offset, lo, hi, radius), n, steps)
    return steps


def _inside(offset: np.ndarray, lo: np.ndarray, hi: np.ndarray, radius: float) -> np.ndarray:
    """Whether the box ``[lo, hi]`` (per axis, ``(..., d)``) meets the ball of ``radius``
    about ``offset``."""
    gap = np.maximum(np.maximum(offset - hi, lo - offset), 0.0)
    return np.einsum("...k,...k->...", gap, gap) <= radius * radius * (1.0 + 1e-12)


def time_over_bound(
    reached: np.ndarray, success: np.ndarray, bound: np.ndarray | None
) -> float | None:
    """The mean, over the successful episodes, of the time to goal over its episode's
    lower bound, minus 1 (0: optimal); ``None`` where no bound is defined or no episode
    with a positive bound succeeded.

    Args:
        reached: each episode's time to goal in seconds, ``(..., E)`` (any value where
            it failed).
        success: which episodes succeeded, shaped like ``reached``.
        bound: each episode's bound ``(E,)`` (:func:`time_to_goal_bound`), or ``None``.

    >>> time_over_bound(np.array([3.0, 9.0]), np.array([True, False]), np.array([2.0, 2.0]))
    0.5
    """
    if bound is None:
        return None
    ok = np.asarray(success, bool) & (bound > 0)
    if not ok.any():
        return None
    ratio = np.asarray(reached, np.float64) / np.where(bound > 0, bound, 1.0)
    value = float(ratio[ok].mean() - 1.0)
    return value if math.isfinite(value) else None


def free_agent_time(
    cfg: SwarmConfig, x: np.ndarray, v: np.ndarray, goal: np.ndarray
) -> np.ndarray | None:
    """An estimate, not a bound: the time (seconds, ``(B,)``) the slowest agent of each
    swarm would need to reach the arrival radius alone, its own control the only force
    beside the drag (the reachable box of :func:`time_to_goal_bound`, per agent), from
    its start (``None`` where :func:`bound_reason`
    gives no bound, or for the zone model, whose bound is already the slowest agent's).

    It ignores the pair forces, which a coordinated swarm can use (cohesion pulls the
    rear forward), so a policy may beat it; a policy close to it has little left to gain
    without such coordination.
    """
    if bound_reason(cfg) is not None or cfg.dynamics == "zone":
        return None
    x = np.asarray(x, np.float64)
    v = np.asarray(v, np.float64)
    offset = np.asarray(goal, np.float64)[:, None, :] - x
    return _steps_to_reach(cfg, offset, v).max(axis=1) * cfg.dt
