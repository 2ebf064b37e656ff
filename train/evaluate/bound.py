"""A lower bound on the time to goal: no policy can bring the swarm in sooner.

Navigation succeeds when every agent is within the arrival radius ``R`` of the goal at
once, so the swarm's centroid ``c`` is then within ``R`` too, and has advanced at least
``D − R`` along the unit vector ``ĝ`` from its start to the goal (``D = |g − c(0)|``).
What bounds the centroid's progress depends on the model:

- **social potential** (navigation and informed tasks, linear friction ``α = 0``, no
  passive sink): the pair forces (Morse and alignment) are equal and opposite, so they
  cancel in the sum and the centroid obeys ``m c̈ = ⟨u_i⟩ − β ċ``. The control's
  component along ``ĝ`` is at most ``u_max ‖ĝ‖₁`` (the action box's support: more than
  ``u_max`` along a diagonal). Full thrust along ``ĝ`` from the centroid's initial
  velocity is then the fastest progress: the bound is the first time it covers
  ``D − R``, the smaller of the exact solution and the semi-implicit Euler recursion of
  one substep per step (the integrator's own progress, which runs slightly ahead).
- **zone model**: every agent moves at its constant ``speed``, so the centroid covers at
  most ``speed · dt`` per step: ``⌈(D − R) / (speed · dt)⌉`` steps.

Elsewhere — the piecewise model (its neighbour forces are one-way and do not cancel),
the Lagrangian model, self-propulsion, a passive sink, a task with its own success rule
or one that holds a state (the mill, a user's task: ``TaskSpec.success``,
``terminates_on_success``), ``success_fraction
< 1`` or perturbations that change who acts — no bound is defined (``None``). The bound
ignores everything that slows a real swarm (keeping together, braking, turning), so a
policy at the bound is optimal, and one within a few percent of it has little left to
gain.
"""

from __future__ import annotations

import math

import numpy as np

from swarm_envs.config import SwarmConfig

__all__ = ["bound_reason", "free_agent_time", "time_over_bound", "time_to_goal_bound"]


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
    cfg: SwarmConfig, x: np.ndarray, v: np.ndarray, goal: np.ndarray
) -> np.ndarray | None:
    """The lower bound (simulated seconds, a multiple of ``dt``) on each swarm's time to
    goal from its start state, ``(B,)``; ``None`` where no bound is defined
    (:func:`bound_reason`).

    Args:
        cfg: the scenario.
        x, v: start positions and velocities ``(B, N, d)``.
        goal: goals ``(B, d)``.

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
    centroid, drift = x.mean(axis=1), v.mean(axis=1)
    offset = goal - centroid
    dist = np.sqrt(np.einsum("bk,bk->b", offset, offset))
    unit = offset / np.where(dist > 0, dist, 1.0)[:, None]
    gap = np.maximum(dist - cfg.arrival_radius, 0.0)
    if cfg.dynamics == "zone":
        per_step = cfg.zone.speed * cfg.dt
        return np.ceil(gap / per_step - 1e-9) * cfg.dt
    m, beta = cfg.physics.m, cfg.physics.beta
    accel = cfg.u_max * np.abs(unit).sum(axis=1) / m  # the box's support along ĝ
    speed0 = np.einsum("bk,bk->b", drift, unit)
    return _steps_to_cover(gap, speed0, accel, beta / m, cfg.dt, cfg.max_steps) * cfg.dt


def _steps_to_cover(
    gap: np.ndarray, speed: np.ndarray, accel: np.ndarray, drag: float, dt: float, max_steps: int
) -> np.ndarray:
    """Steps of ``dt`` until ``s ≥ gap`` under ``s̈ = accel − drag ṡ`` from ``ṡ = speed``,
    elementwise over arrays of one shape: the fewer of the exact flow's and one-substep
    semi-implicit Euler's (``max_steps + 1``: never)."""
    steps = np.where(gap <= 0, 0, max_steps + 1)
    s_euler, v_euler = np.zeros_like(gap), np.array(speed, dtype=np.float64)
    for n in range(1, max_steps + 1):
        open_ = steps > n - 1
        if not open_.any():
            break
        v_euler = v_euler + dt * (accel - drag * v_euler)
        s_euler = s_euler + dt * v_euler
        t = n * dt
        if drag > 0:
            terminal = accel / drag
            s_exact = terminal * t + (speed - terminal) * (1.0 - math.exp(-drag * t)) / drag
        else:
            s_exact = speed * t + 0.5 * accel * t * t
        covered = np.maximum(s_euler, s_exact) >= gap - 1e-12
        steps = np.where(open_ & covered, n, steps)
    return steps


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
    swarm would need to reach the arrival radius alone, at full thrust along its own line
    to the goal against the drag, from its start (``None`` where :func:`bound_reason`
    gives no bound, or for the zone model, whose bound is already per agent).

    It ignores the pair forces, which a coordinated swarm can use (cohesion pulls the
    rear forward), so a policy may beat it; a policy close to it has little left to gain
    without such coordination.
    """
    if bound_reason(cfg) is not None or cfg.dynamics == "zone":
        return None
    x = np.asarray(x, np.float64)
    v = np.asarray(v, np.float64)
    offset = np.asarray(goal, np.float64)[:, None, :] - x
    dist = np.sqrt(np.einsum("bnk,bnk->bn", offset, offset))
    unit = offset / np.where(dist > 0, dist, 1.0)[..., None]
    gap = np.maximum(dist - cfg.arrival_radius, 0.0)
    accel = cfg.u_max * np.abs(unit).sum(axis=-1) / cfg.physics.m
    speed0 = np.einsum("bnk,bnk->bn", v, unit)
    drag = cfg.physics.beta / cfg.physics.m
    steps = _steps_to_cover(gap, speed0, accel, drag, cfg.dt, cfg.max_steps)
    return steps.max(axis=1) * cfg.dt
