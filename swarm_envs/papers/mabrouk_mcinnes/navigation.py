"""The numbers of Mabrouk & McInnes' Fig. 11: a swarm navigating to a potential sink.

:func:`fig11_navigation` is the paper's run (linear friction ``β = 1``);
:func:`fig11_reproduction` puts it together with the decay law of the angular momentum
and the self-propelled mill (:mod:`~swarm_envs.papers.mabrouk_mcinnes.mill`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict
from typing import Any

import numpy as np

from swarm_envs import metrics
from swarm_envs.papers.claims import verdict
from swarm_envs.papers.mabrouk_mcinnes import common
from swarm_envs.papers.mabrouk_mcinnes.claims import fig11_claims
from swarm_envs.papers.mabrouk_mcinnes.common import NAV_GOAL, NAV_SNAPSHOT_TIMES, RunSetup
from swarm_envs.papers.mabrouk_mcinnes.mill import (
    MILL_ALPHA,
    MILL_BETA,
    fig11_decay_law,
    fig11_self_propelled,
)
from swarm_envs.physics import SocialPotentialParams

__all__ = ["fig11_navigation", "fig11_reproduction"]


def fig11_navigation(
    *,
    setup: RunSetup | None = None,
    goal: Sequence[float] = NAV_GOAL,
    duration: float = 318.0,
    snapshot_times: Sequence[float] = NAV_SNAPSHOT_TIMES,
    goal_radius: float = 1.0,
    n_agents: int = 31,
) -> dict[str, Any]:
    """Fig. 11: a swarm in a "vortex like shape pattern" approaching a potential sink.

    **Paper.** N = 31, ``C_g = 15, l_g = 5, C_a = 1, C_r = 1, C_o = 0.7, l_a = 1,
    l_r = 0.2, l_o = 1.5, m = 1, β = 1``
    (:meth:`SocialPotentialParams.navigation`); snapshots at t = 0, 28, 86, 135, 204,
    318 (seed 001; seed 000 lists 0, 28, 86, 318). No goal position, start region or
    time unit is given.

    **Here.** The goal force is the gradient of eq. 19 (unit vector, range ``l_g``;
    ``docs/models.md`` §1), not the printed eq. 21. Start: :class:`RunSetup`'s disc of
    radius 2 at the origin with 31 agents; goal :data:`NAV_GOAL`, 25 length units away,
    chosen so that the approach (drift speed ``(C_g/l_g) e^{−D/l_g}/β`` at distance D)
    fills the paper's t = 0…318 window when t is read in time units; ``dt`` from the
    setup (6360 steps). Reported: first-passage times (centroid within ``goal_radius``,
    first agent within it, 90 % of agents within it; median over seeds), the
    statistics at the snapshot times (seed means), the mean unit-heading angular
    momentum during the approach (t from 5 to arrival; 1 for a rotating ring, about
    ``1/√N ≈ 0.18`` for random headings) as the vortex indicator, and seed 0's
    positions at the snapshots (for the figure).
    """
    setup = common.setup_for(setup)
    params = SocialPotentialParams.navigation()
    g = np.asarray(goal, dtype=np.float64)
    x0, v0 = setup.initial(n_agents=n_agents)
    steps = common.steps_for(duration, setup.dt)
    xs, vs = common.run_physics(params, x0, v0, dt=setup.dt, duration=duration, goal=g)
    t_all = np.arange(steps + 1) * setup.dt
    centroid_dist = np.linalg.norm(metrics.centroid(xs) - g, axis=-1)  # (T, S)
    agent_dist = np.linalg.norm(xs - g, axis=-1)  # (T, S, N)
    frac = metrics.fraction_within(xs, g, goal_radius)  # (T, S)
    t_centroid = metrics.first_passage_time(centroid_dist, setup.dt, goal_radius)
    t_first = metrics.first_passage_time(agent_dist.min(axis=-1), setup.dt, goal_radius)
    t_90 = metrics.first_passage_time(frac, setup.dt, 0.9, below=False)

    idx = common.sample_indices(steps, setup.max_samples * 2)
    names = (
        "angular_momentum",
        "velocity_angular_momentum",
        "polarization",
        "expanse",
        "nearest_neighbor_distance",
        "mean_speed",
    )
    values = common.series(xs, vs, idx, names)
    t = idx * setup.dt
    arrival = np.where(np.isfinite(t_centroid), t_centroid, duration)
    approach = (t[:, None] >= min(5.0, duration / 2)) & (t[:, None] <= arrival[None, :])
    am = values["angular_momentum"]
    vortex = [
        float(am[approach[:, s], s].mean()) if approach[:, s].any() else float("nan")
        for s in range(am.shape[1])
    ]

    snaps = [float(s) for s in snapshot_times if s <= duration + 1e-9]
    snap_idx = [min(steps, round(s / setup.dt)) for s in snaps]
    snap_stats = common.series(xs, vs, np.asarray(snap_idx), names)
    snapshot_metrics = {n: snap_stats[n].mean(axis=1).tolist() for n in names}
    snapshot_metrics["centroid_distance"] = centroid_dist[snap_idx].mean(axis=1).tolist()
    snapshot_metrics["fraction_within"] = frac[snap_idx].mean(axis=1).tolist()

    thin = common.thin(t_all.size, 2 * common.SERIES_POINTS)
    reached = np.isfinite(t_centroid)
    vortex_mean = float(np.nanmean(vortex)) if np.isfinite(vortex).any() else float("nan")
    claims = fig11_claims(reached.tolist(), vortex_mean, goal_radius=goal_radius, duration=duration)
    return {
        "figure": "fig11",
        "title": "Navigation to a potential sink (N = 31)",
        "paper": {
            "claim": "a swarm in a vortex-like pattern approaching a potential sink at G",
            "parameters": asdict(params) | {"N": n_agents},
            "snapshot_times": list(NAV_SNAPSHOT_TIMES),
        },
        "setup": setup.as_dict() | {"n_agents": n_agents, "duration": duration, "steps": steps},
        "goal": g.tolist(),
        "start_distance": float(np.linalg.norm(g)),
        "goal_radius": goal_radius,
        "first_passage": {
            "centroid_within_radius": {
                "median": float(np.median(t_centroid)),
                "per_seed": t_centroid.tolist(),
            },
            "first_agent_within_radius": {
                "median": float(np.median(t_first)),
                "per_seed": t_first.tolist(),
            },
            "ninety_percent_within_radius": {
                "median": float(np.median(t_90)),
                "per_seed": t_90.tolist(),
            },
        },
        "reached_fraction": float(reached.mean()),
        "vortex_indicator": {"mean": vortex_mean, "per_seed": vortex},
        "snapshots": {
            "t": snaps,
            "metrics": snapshot_metrics,
            "positions_seed0": xs[snap_idx, 0].tolist(),
            "velocities_seed0": vs[snap_idx, 0].tolist(),
        },
        "time_series": {
            "t": t_all[thin].tolist(),
            "centroid_distance": centroid_dist[thin].mean(axis=1).tolist(),
            "centroid_distance_per_seed": centroid_dist[thin].T.tolist(),
            "fraction_within": frac[thin].mean(axis=1).tolist(),
            "centroid_path_seed0": metrics.centroid(xs[thin, 0]).tolist(),
        },
        "sampled_series": {
            "t": t[common.thin(t.size)].tolist(),
            **{n: values[n].mean(axis=1)[common.thin(t.size)].tolist() for n in names},
        },
        "claims": claims,
        "verdict": verdict(claims),
    }


def _tagged(claims: list[dict[str, Any]], part: str, *, extra: bool) -> list[dict[str, Any]]:
    return [c | {"part": part} | ({"paper_form": False} if extra else {}) for c in claims]


def fig11_reproduction(
    *,
    setup: RunSetup | None = None,
    goal: Sequence[float] = NAV_GOAL,
    duration: float = 318.0,
    snapshot_times: Sequence[float] = NAV_SNAPSHOT_TIMES,
    decay_duration: float = 100.0,
    alpha: float = MILL_ALPHA,
    beta: float = MILL_BETA,
    n_agents: int = 31,
) -> dict[str, Any]:
    """Fig. 11 in three parts: the paper's run, the decay law, the self-propelled mill.

    - ``linear_friction``: :func:`fig11_navigation`, the paper's parameters (β = 1).
    - ``decay_law``: :func:`~swarm_envs.papers.mabrouk_mcinnes.mill.fig11_decay_law`
      over ``decay_duration``: with linear friction the angular momentum about ``G``
      is ``L_G(0)(1 − β dt/m)^n`` exactly, so no lasting vortex can appear.
    - ``self_propelled``: :func:`~swarm_envs.papers.mabrouk_mcinnes.mill.
      fig11_self_propelled`, the same swarm with the Rayleigh term (``α``, ``β_R =
      beta``) instead of ``−βv``: it reaches the sink and holds a mill centred on it.

    ``claims`` lists all of them, each with a ``part`` key. The ``verdict`` counts the
    paper-model claims only (those of ``linear_friction``); the decay law is a fact of
    the model and the self-propelled run adds an ingredient the paper does not have,
    so their claims are extras here; ``self_propelled_verdict`` is the verdict of the
    self-propelled run's own claims.
    """
    setup = common.setup_for(setup)
    nav = fig11_navigation(
        setup=setup, goal=goal, duration=duration, snapshot_times=snapshot_times,
        n_agents=n_agents,
    )  # fmt: skip
    decay = fig11_decay_law(setup=setup, goal=goal, duration=decay_duration, n_agents=n_agents)
    mill = fig11_self_propelled(
        setup=setup, goal=goal, duration=duration, snapshot_times=snapshot_times,
        alpha=alpha, beta=beta, n_agents=n_agents,
    )  # fmt: skip
    claims = (
        _tagged(nav["claims"], "linear_friction", extra=False)
        + _tagged(decay["claims"], "decay_law", extra=True)
        + _tagged(mill["claims"], "self_propelled", extra=True)
    )
    return {
        "figure": "fig11",
        "title": "Navigation to a potential sink (N = 31)",
        "paper": nav["paper"],
        "setup": nav["setup"],
        "goal": nav["goal"],
        "linear_friction": nav,
        "decay_law": decay,
        "self_propelled": mill,
        "claims": claims,
        "verdict": verdict(claims),
        "self_propelled_verdict": mill["verdict"],
    }
