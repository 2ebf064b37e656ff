"""Fig. 11 with rotation in view: the decay law of linear friction and the self-propelled mill.

Two parts of the Fig. 11 reproduction (:func:`~swarm_envs.papers.mabrouk_mcinnes.navigation.
fig11_reproduction` puts them together with the paper's run):

- :func:`fig11_decay_law`: why no vortex can appear with the paper's linear friction.
  Cohesion and alignment are central, equal-and-opposite pair forces and the sink is
  central about ``G``, so only ``−βv`` changes the angular momentum about ``G``; one
  semi-implicit Euler step multiplies it by ``1 − β dt/m`` exactly
  (``docs/models.md`` §1.4). The function measures that law on the paper's start, on a
  smaller β and on a start given a deliberate rotation.
- :func:`fig11_self_propelled`: the same swarm with the Rayleigh self-propulsion of
  ``docs/models.md`` §1.7 in place of ``−βv``; it reaches the sink and holds a mill
  centred on it.

The statistics about the goal (:func:`goal_angular_momentum`,
:func:`goal_tangential_speed`, :func:`goal_mean_radius`) are signed, 2-D, and per
agent (unit masses): a ring of agents circling ``G`` at radius ``R`` with speed ``s``
has ``L_G = R·s`` and tangential speed ``s`` (positive counter-clockwise).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, replace
from typing import Any

import numpy as np

from swarm_envs import metrics
from swarm_envs.papers.claims import verdict
from swarm_envs.papers.mabrouk_mcinnes import common
from swarm_envs.papers.mabrouk_mcinnes.claims import fig11_decay_claims, fig11_mill_claims
from swarm_envs.papers.mabrouk_mcinnes.common import NAV_GOAL, NAV_SNAPSHOT_TIMES, RunSetup
from swarm_envs.physics import SocialPotentialParams

__all__ = [
    "DECAY_CASES",
    "MILL_ALPHA",
    "MILL_BETA",
    "fig11_decay_law",
    "fig11_self_propelled",
    "fig11_self_propelled_positions",
    "goal_angular_momentum",
    "goal_mean_radius",
    "goal_tangential_speed",
    "mill_params",
    "rotating_start",
]

#: Self-propulsion of the Fig. 11 mill: ``α`` and ``β_R`` of the Rayleigh term
#: ``(α − β_R|v|²)v``, cruise speed ``v₀ = √(α/β_R) = 1`` (see :func:`fig11_self_propelled`).
MILL_ALPHA = 0.5
MILL_BETA = 0.5

#: The runs of :func:`fig11_decay_law`: (label, β, rotation rate ω of the start).
DECAY_CASES: tuple[tuple[str, float, float], ...] = (
    ("paper start, β = 1", 1.0, 0.0),
    ("paper start, β = 0.1", 0.1, 0.0),
    ("start rotating at ω = 0.5, β = 1", 1.0, 0.5),
)

#: Relative errors of the decay law are measured while the prediction is above this
#: fraction of the start's scale ``S₀ = mean_i |r_i − G||v_i|`` (well above round-off).
DECAY_REL_FLOOR = 1e-6


def _offsets(x: Any, goal: Any) -> tuple[np.ndarray, np.ndarray]:
    x = np.asarray(x, dtype=np.float64)
    if x.ndim < 2 or x.shape[-1] != 2:
        raise ValueError(f"positions must be shaped (..., N, 2), got {x.shape}")
    g = np.asarray(goal, dtype=np.float64)
    if g.shape != (2,) or not np.all(np.isfinite(g)):
        raise ValueError(f"goal must be 2 finite numbers, got {goal!r}")
    return x - g, np.linalg.norm(x - g, axis=-1)


def _cross(r: np.ndarray, v: Any) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    if v.shape != r.shape:
        raise ValueError(f"velocities must have the positions' shape {r.shape}, got {v.shape}")
    return r[..., 0] * v[..., 1] - r[..., 1] * v[..., 0]


def goal_angular_momentum(x: Any, v: Any, goal: Any) -> np.ndarray:
    """Angular momentum about ``goal`` per agent, ``mean_i (r_i − G) × v_i`` (signed).

    The mechanical angular momentum of unit masses about the fixed point ``G``, divided
    by ``N``; positive counter-clockwise. Shape ``(...)`` for ``x, v`` shaped
    ``(..., N, 2)``.

    >>> theta = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    >>> ring = 2.0 * np.stack([np.cos(theta), np.sin(theta)], -1)
    >>> tangent = 0.5 * np.stack([-np.sin(theta), np.cos(theta)], -1)
    >>> round(float(goal_angular_momentum(ring + 3.0, tangent, (3.0, 3.0))), 12)
    1.0
    """
    r, _ = _offsets(x, goal)
    return _cross(r, v).mean(axis=-1)


def goal_tangential_speed(x: Any, v: Any, goal: Any) -> np.ndarray:
    """Mean signed tangential velocity about ``goal``, ``mean_i r̂_i × v_i``.

    ``r̂_i = (r_i − G)/|r_i − G|``; an agent on ``G`` contributes 0. Positive
    counter-clockwise; ``s`` for agents circling ``G`` at speed ``s``, 0 for a swarm
    moving radially.
    """
    r, d = _offsets(x, goal)
    unit = r / np.maximum(d, 1e-12)[..., None]
    return _cross(unit, v).mean(axis=-1)


def goal_mean_radius(x: Any, goal: Any) -> np.ndarray:
    """Mean distance of the agents to ``goal``, ``mean_i |r_i − G|``."""
    return _offsets(x, goal)[1].mean(axis=-1)


def rotating_start(x0: np.ndarray, v0: np.ndarray, omega: float) -> np.ndarray:
    """``v0`` plus a rigid rotation at rate ``omega`` about each swarm's centroid."""
    rel = x0 - x0.mean(axis=-2, keepdims=True)
    return v0 + omega * np.stack([-rel[..., 1], rel[..., 0]], axis=-1)


def mill_params(alpha: float = MILL_ALPHA, beta: float = MILL_BETA) -> SocialPotentialParams:
    """The paper's navigation set with ``−βv`` replaced by ``(α − β_R|v|²)v``."""
    return replace(SocialPotentialParams.navigation(), alpha=alpha, beta=beta)


def fig11_decay_law(
    *,
    setup: RunSetup | None = None,
    goal: Sequence[float] = NAV_GOAL,
    duration: float = 100.0,
    cases: Sequence[tuple[str, float, float]] = DECAY_CASES,
    n_agents: int = 31,
) -> dict[str, Any]:
    """The angular momentum about ``G`` under linear friction: ``L_n = L_0 (1 − β dt/m)^n``.

    Each case of ``cases`` (label, ``β``, rotation ``ω`` given to the start, see
    :func:`rotating_start`) runs the paper's navigation parameters with that ``β`` from
    :class:`RunSetup`'s start for ``duration`` and compares the measured
    ``L_G(t_n)`` with ``L_G(0)(1 − β dt/m)^n``. Reported per case: the largest deviation
    in units of the start's scale ``S₀ = mean_i |r_i − G||v_i|`` (round-off is about
    ``1e-15``), the largest relative error while the prediction is above
    ``1e-6 S₀``, the measured decay rate per unit time against ``−ln(1 − β dt/m)/dt``,
    and ``|L_G|`` of every seed over time with the prediction (for the figure).
    """
    setup = common.setup_for(setup)
    g = np.asarray(goal, dtype=np.float64)
    x0, v0 = setup.initial(n_agents=n_agents)
    steps = common.steps_for(duration, setup.dt)
    n = np.arange(steps + 1)
    thin = common.thin(steps + 1, 2 * common.SERIES_POINTS)
    out_cases = []
    for label, beta, omega in cases:
        params = replace(SocialPotentialParams.navigation(), beta=beta)
        start_v = rotating_start(x0, v0, omega) if omega else v0
        xs, vs = common.run_physics(params, x0, start_v, dt=setup.dt, duration=duration, goal=g)
        lg = goal_angular_momentum(xs, vs, g)  # (T, S)
        q = 1.0 - beta * setup.dt / params.m
        pred = lg[0] * q ** n[:, None]
        scale = (np.linalg.norm(xs[0] - g, axis=-1) * np.linalg.norm(vs[0], axis=-1)).mean(-1)
        deviation = np.abs(lg - pred) / scale
        above = np.abs(pred) >= DECAY_REL_FLOOR * scale
        rel = np.where(above, np.abs(lg - pred) / np.maximum(np.abs(pred), 1e-300), 0.0)
        last = np.array([np.flatnonzero(col).max() if col.any() else 0 for col in above.T])
        rate = np.array(
            [
                -np.log(lg[k, s] / lg[0, s]) / (k * setup.dt) if k > 0 else float("nan")
                for s, k in enumerate(last)
            ]
        )
        out_cases.append(
            {
                "label": label,
                "beta": beta,
                "omega": omega,
                "step_factor": q,
                "L0_per_seed": lg[0].tolist(),
                "scale_per_seed": scale.tolist(),
                "max_deviation_over_scale": float(deviation.max()),
                "max_relative_error": float(rel.max()),
                "relative_error_checked_up_to_t": float(last.min() * setup.dt),
                "decay_rate_measured_per_seed": rate.tolist(),
                "decay_rate_expected": float(-np.log(q) / setup.dt),
                "decay_rate_continuous": beta / params.m,
                "abs_L_per_seed": np.abs(lg[thin]).T.tolist(),
                "abs_prediction_per_seed": np.abs(pred[thin]).T.tolist(),
            }
        )
    claims = fig11_decay_claims(out_cases, rel_floor=DECAY_REL_FLOOR)
    return {
        "t": (thin * setup.dt).tolist(),
        "duration": duration,
        "dt": setup.dt,
        "cases": out_cases,
        "claims": claims,
    }


def _first_passage(dist: np.ndarray, t: np.ndarray, radius: float) -> np.ndarray:
    hit = dist < radius
    return np.where(hit.any(axis=0), t[np.argmax(hit, axis=0)], np.inf)


def fig11_self_propelled(
    *,
    setup: RunSetup | None = None,
    goal: Sequence[float] = NAV_GOAL,
    duration: float = 318.0,
    snapshot_times: Sequence[float] = NAV_SNAPSHOT_TIMES,
    alpha: float = MILL_ALPHA,
    beta: float = MILL_BETA,
    goal_radius: float = 1.0,
    hold_from: float = 0.75,
    n_agents: int = 31,
) -> dict[str, Any]:
    """Fig. 11 with self-propulsion: the swarm reaches the sink and mills around it.

    **Model.** The paper's navigation set (``C_g = 15, l_g = 5, C_a = C_r = 1,
    C_o = 0.7, l_a = 1, l_r = 0.2, l_o = 1.5, m = 1``, N = 31) with the friction
    ``−βv`` replaced by the Rayleigh term ``(α − β_R|v|²)v`` (``docs/models.md`` §1.7),
    which keeps the agents near the cruise speed ``v₀ = √(α/β_R)`` instead of draining
    their rotation. Same start, goal and ``dt`` as the paper's run
    (:func:`~swarm_envs.papers.mabrouk_mcinnes.navigation.fig11_navigation`).

    **Choice of α, β_R.** ``α = β_R = 0.5`` (``v₀ = 1``, of the order of the
    interaction range ``l_a = 1``). With ``v₀ = 1`` every ``α`` from 0.2 to 0.85 ends
    in a mill centred on ``G`` (mean radius about 0.27, speed about 0.8); at ``α = 1``,
    or at ``v₀ ≥ 1.4`` with ``α = 0.5``, the swarm instead circles ``G`` as a compact
    flock (its centroid on a circle of radius 0.3–0.8 about ``G``, unit milling about
    0.15). Small ``α`` lets the swarm fall into the sink as a flock; larger ``α`` builds
    the cruise speed before the sink acts, so more starts form a mill before the
    approach. 0.5 sits inside the mill range with margin on both sides; ``dt = 0.025``
    gives the same statistics.

    **Reported.** Over time (sampled, seed mean and per seed): the unit-heading milling
    about the centroid (:func:`swarm_envs.metrics.angular_momentum`), the angular
    momentum about ``G`` (:func:`goal_angular_momentum`), the tangential speed about
    ``G`` (:func:`goal_tangential_speed`), the mean radius about ``G``, the centroid
    distance to ``G`` and the mean speed; the first passage of the centroid within
    ``goal_radius``; over the hold window ``t ≥ hold_from · duration``, per seed, the
    smallest ``σ v_t / v₀`` and ``σ L_G / (R̄ v₀)`` (``σ``: the seed's sense of
    rotation, the sign of its mean ``v_t`` there; ``R̄`` the mean radius), the largest
    centroid distance over ``R̄`` and the smallest unit milling; the unit milling
    during the approach (``t`` from 5 to arrival); seed 0 at the snapshot times.
    """
    setup = common.setup_for(setup)
    params = mill_params(alpha, beta)
    v_cruise = params.cruise_speed
    g = np.asarray(goal, dtype=np.float64)
    x0, v0 = setup.initial(n_agents=n_agents)
    steps = common.steps_for(duration, setup.dt)
    xs, vs = common.run_physics(params, x0, v0, dt=setup.dt, duration=duration, goal=g)
    idx = common.sample_indices(steps, setup.max_samples * 2)
    t = idx * setup.dt
    x, v = xs[idx], vs[idx]
    series = {
        "milling": metrics.angular_momentum(x, v),
        "goal_angular_momentum": goal_angular_momentum(x, v, g),
        "tangential_speed": goal_tangential_speed(x, v, g),
        "mean_radius": goal_mean_radius(x, g),
        "centroid_distance": np.linalg.norm(metrics.centroid(x) - g, axis=-1),
        "mean_speed": np.linalg.norm(v, axis=-1).mean(axis=-1),
        "polarization": metrics.polarization(v),
    }
    arrival = _first_passage(series["centroid_distance"], t, goal_radius)
    hold = t >= hold_from * duration
    sense = np.where(series["tangential_speed"][hold].mean(axis=0) < 0, -1.0, 1.0)
    radius = np.maximum(series["mean_radius"][hold], 1e-12)
    hold_stats = {
        "tangential_speed_over_v0_min": (
            (sense * series["tangential_speed"][hold]).min(axis=0) / v_cruise
        ).tolist(),
        "L_G_over_R_v0_min": (
            (sense * series["goal_angular_momentum"][hold] / radius).min(axis=0) / v_cruise
        ).tolist(),
        "centroid_distance_over_R_max": (
            (series["centroid_distance"][hold] / radius).max(axis=0)
        ).tolist(),
        "centroid_distance_max": series["centroid_distance"][hold].max(axis=0).tolist(),
        "milling_min": series["milling"][hold].min(axis=0).tolist(),
        "mean_radius": series["mean_radius"][hold].mean(axis=0).tolist(),
        "mean_speed": series["mean_speed"][hold].mean(axis=0).tolist(),
        "tangential_speed": series["tangential_speed"][hold].mean(axis=0).tolist(),
        "goal_angular_momentum": series["goal_angular_momentum"][hold].mean(axis=0).tolist(),
        "sense": sense.tolist(),
    }
    end = np.where(np.isfinite(arrival), arrival, duration)
    approach_milling = [
        float(series["milling"][(t >= min(5.0, duration / 2)) & (t <= end[s]), s].mean())
        if ((t >= min(5.0, duration / 2)) & (t <= end[s])).any()
        else float("nan")
        for s in range(len(end))
    ]
    snaps = [float(s) for s in snapshot_times if s <= duration + 1e-9]
    snap_idx = [min(steps, round(s / setup.dt)) for s in snaps]
    xsnap, vsnap = xs[snap_idx], vs[snap_idx]
    snap_metrics = {
        "milling": metrics.angular_momentum(xsnap, vsnap)[:, 0].tolist(),
        "goal_angular_momentum": goal_angular_momentum(xsnap, vsnap, g)[:, 0].tolist(),
        "tangential_speed": goal_tangential_speed(xsnap, vsnap, g)[:, 0].tolist(),
        "centroid_distance": np.linalg.norm(metrics.centroid(xsnap) - g, axis=-1)[:, 0].tolist(),
    }
    claims = fig11_mill_claims(
        arrival.tolist(),
        hold_stats,
        approach_milling,
        goal_radius=goal_radius,
        duration=duration,
        hold_from=hold_from * duration,
    )
    thin = common.thin(t.size, 2 * common.SERIES_POINTS)
    return {
        "model": "Rayleigh self-propulsion (α − β_R|v|²)v in place of −βv",
        "parameters": asdict(params) | {"N": n_agents, "cruise_speed": v_cruise},
        "goal": g.tolist(),
        "goal_radius": goal_radius,
        "hold_window": [hold_from * duration, duration],
        "arrival_per_seed": arrival.tolist(),
        "arrival_median": float(np.median(arrival)),
        "approach_milling_per_seed": approach_milling,
        "hold": hold_stats,
        "snapshots": {
            "t": snaps,
            "seed0": snap_metrics,
            "positions_seed0": xsnap[:, 0].tolist(),
            "velocities_seed0": vsnap[:, 0].tolist(),
        },
        "time_series": {
            "t": t[thin].tolist(),
            "sense": sense.tolist(),
            **{k: val[thin].T.tolist() for k, val in series.items()},
        },
        "claims": claims,
        "verdict": verdict(claims),
    }


def fig11_self_propelled_positions(
    *,
    setup: RunSetup | None = None,
    goal: Sequence[float] = NAV_GOAL,
    duration: float = 318.0,
    alpha: float = MILL_ALPHA,
    beta: float = MILL_BETA,
    n_agents: int = 31,
) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities ``(T + 1, N, 2)`` of seed 0 of :func:`fig11_self_propelled`."""
    setup = common.setup_for(setup)
    x0, v0 = setup.initial(n_agents=n_agents)
    return common.run_physics(
        mill_params(alpha, beta),
        x0[0],
        v0[0],
        dt=setup.dt,
        duration=duration,
        goal=np.asarray(goal, dtype=np.float64),
    )
