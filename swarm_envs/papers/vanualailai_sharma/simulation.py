"""Runs and measures of the Vanualailai & Sharma reproduction.

:data:`FIGURES` holds each figure's parameters (from the paper) and our choices (where
it is silent); :func:`simulate_figure` runs one, :func:`measures` and
:func:`leader_stats` reduce the trajectories to the numbers the claims are about
(:mod:`swarm_envs.papers.vanualailai_sharma.claims`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from swarm_envs.metrics import centroid, nearest_neighbor_distance
from swarm_envs.physics.lagrangian import (
    LagrangianParams,
    lagrangian_value,
    min_pair_clearance,
    simulate_lagrangian,
)

__all__ = [
    "FIG5_SWEEP_SEEDS",
    "FIGURES",
    "FigureSetup",
    "exact_gradient_run",
    "initial_positions",
    "leader_stats",
    "measures",
    "simulate_figure",
]


@dataclass(frozen=True)
class FigureSetup:
    """One figure's parameters (from the seed) and our choices (where it is silent)."""

    name: str
    n: int
    r: float
    alpha: float
    gamma: float | None
    beta: float | None
    gamma_range: tuple[float, float] | None = None
    beta_range: tuple[float, float] | None = None
    side: float = 300.0
    dt: float = 0.1
    steps: int = 1000
    quick_steps: int = 30
    seed: int = 0


FIGURES: dict[str, FigureSetup] = {
    "fig1": FigureSetup("fig1", 30, 10.0, 1.0, 2.0, 50.0, dt=0.1, steps=1000, seed=0),
    "fig2": FigureSetup("fig2", 70, 20.0, 0.1, 0.2, 50.0, side=600.0, dt=1.0, steps=1000),
    "fig3": FigureSetup(
        "fig3", 30, 10.0, 1.0, None, 100.0, gamma_range=(0.01, 1.0), dt=0.5, steps=1000, seed=1
    ),
    "fig4": FigureSetup(
        "fig4", 30, 10.0, 5.0, 1.0, None, beta_range=(200.0, 500.0), dt=0.05, steps=3000
    ),
    "fig5": FigureSetup(
        "fig5", 30, 10.0, 5.0, 2.0, None, beta_range=(200.0, 500.0), dt=0.05, steps=4000, seed=3
    ),
}

#: Extra seeds run for Fig. 5 (full run only) to say how often the circle appears.
FIG5_SWEEP_SEEDS = (0, 1, 2, 3)


def initial_positions(n: int, r: float, side: float, rng: np.random.Generator) -> np.ndarray:
    """``n`` points uniform in ``[0, side]²``, every pair at least ``2.4 r`` apart.

    Rejection sampling (our choice; the paper only says "randomly-positioned").
    """
    pts = np.empty((0, 2))
    while len(pts) < n:
        p = rng.uniform(0.0, side, size=2)
        if len(pts) == 0 or np.min(np.linalg.norm(pts - p, axis=1)) >= 2.4 * r:
            pts = np.vstack([pts, p])
    return pts


def _params(s: FigureSetup, rng: np.random.Generator, gradient: str = "seed") -> LagrangianParams:
    return LagrangianParams.randomized(
        s.n,
        rng,
        alpha=s.alpha,
        gamma=2.0 if s.gamma is None else s.gamma,
        beta=50.0 if s.beta is None else s.beta,
        r=s.r,
        gamma_range=s.gamma_range,
        beta_range=s.beta_range,
        gradient=gradient,
    )


def simulate_figure(
    setup: FigureSetup, *, quick: bool = False, seed: int | None = None, gradient: str = "seed"
) -> tuple[LagrangianParams, np.ndarray, np.ndarray, float]:
    """Run one figure: ``(params, xs, vs, dt)``. Random draws: params first, then ``x0``."""
    rng = np.random.default_rng(setup.seed if seed is None else seed)
    params = _params(setup, rng, gradient)
    x0 = initial_positions(setup.n, setup.r, setup.side, rng)
    steps = setup.quick_steps if quick else setup.steps
    xs, vs = simulate_lagrangian(params, x0, np.zeros_like(x0), dt=setup.dt, steps=steps)
    return params, xs, vs, setup.dt


def _heading_turns(vc: np.ndarray) -> np.ndarray:
    """Per-frame signed turn (rad) of the centroid velocity direction."""
    head = np.unwrap(np.arctan2(vc[:, 1], vc[:, 0]))
    return np.diff(head)


def _kurtosis(a: np.ndarray) -> float:
    a = np.asarray(a, dtype=float)
    if a.size < 4 or a.std() == 0:
        return 0.0
    z = (a - a.mean()) / a.std()
    return float(np.mean(z**4) - 3.0)


def measures(params: LagrangianParams, xs: np.ndarray, vs: np.ndarray, dt: float) -> dict[str, Any]:
    """Statistics used by every claim (``late``: the last half of the run)."""
    T = len(xs) - 1
    c = centroid(xs)
    vc = vs.mean(axis=1)
    speed = np.linalg.norm(vc, axis=-1)
    e = xs - c[:, None, :]
    spread = np.sqrt(np.einsum("tik,tik->ti", e, e).mean(axis=-1))
    L = lagrangian_value(xs, params)
    min_R = min_pair_clearance(xs, params)
    late = slice(T // 2, T + 1)
    cl = c[late]
    path = float(np.linalg.norm(np.diff(cl, axis=0), axis=-1).sum())
    net = float(np.linalg.norm(cl[-1] - cl[0]))
    turns = _heading_turns(vc[late])
    after = _heading_turns(vc[T // 10 :])  # the whole run after a 10 % transient
    # formation change: RMS change of the positions about the centroid over the late half
    de = e[late][-1] - e[late][0]
    formation_change = float(np.sqrt(np.einsum("ik,ik->i", de, de).mean()) / spread[-1])
    nn = nearest_neighbor_distance(xs[-1])
    dL = np.diff(L)
    return {
        "frames": T,
        "dt": dt,
        "t_end": T * dt,
        "centroid_speed": {
            "start": float(speed[0]),
            "late_mean": float(speed[late].mean()),
            "late_cv": float(speed[late].std() / max(speed[late].mean(), 1e-12)),
            "end": float(speed[-1]),
        },
        "spread": {"start": float(spread[0]), "end": float(spread[-1])},
        "late_net_over_path": net / path if path > 0 else 0.0,
        "late_path_length": path,
        "late_total_turn_rad": float(turns.sum()),
        "total_turn_after_10pct_rad": float(after.sum()),
        "max_abs_turn_rate_after_10pct": float(np.abs(after).max() / dt) if len(after) else 0.0,
        "late_turn_sign_consistency": float(abs(np.sign(turns).mean())) if len(turns) else 0.0,
        "late_turn_kurtosis": _kurtosis(turns),
        "formation_change_late": formation_change,
        "nearest_neighbor_end_mean": float(np.mean(nn)),
        "L": {
            "start": float(L[0]),
            "end": float(L[-1]),
            "max": float(L.max()),
            "fraction_of_frames_increasing": float(np.mean(dL > 0)) if len(dL) else 0.0,
            "samples": L[:: max(1, T // 50)],
        },
        "min_R_ij": float(min_R.min()),
    }


def leader_stats(params: LagrangianParams, xs: np.ndarray, vs: np.ndarray) -> dict[str, Any]:
    """Fig. 3: who is in front along the centroid velocity over the last half."""
    T = len(xs) - 1
    late = slice(T // 2, T + 1)
    c = centroid(xs[late])
    vc = vs[late].mean(axis=1)
    u = vc / np.maximum(np.linalg.norm(vc, axis=-1, keepdims=True), 1e-12)
    fwd = np.einsum("tik,tk->ti", xs[late] - c[:, None, :], u)
    front = fwd.argmax(axis=1)
    leader = int(np.bincount(front).argmax())
    order = np.sort(fwd, axis=1)
    gap = order[:, -1] - order[:, -2]
    gamma = np.broadcast_to(np.asarray(params.gamma, dtype=float), (xs.shape[1],))
    mean_fwd = fwd.mean(axis=0)
    rank_g = np.argsort(np.argsort(gamma))
    rank_f = np.argsort(np.argsort(mean_fwd))
    spearman = float(np.corrcoef(rank_g, rank_f)[0, 1])
    return {
        "leader": leader,
        "leader_fraction_in_front": float(np.mean(front == leader)),
        "leader_gamma": float(gamma[leader]),
        "gamma_rank_of_leader": int(rank_g[leader]),
        "lead_gap_mean": float(gap.mean()),
        "spearman_gamma_vs_forward": spearman,
    }


def exact_gradient_run(*, quick: bool = False) -> dict[str, Any]:
    """Fig. 1's parameters under the exact gradient ``∇L`` (a short run).

    ``L`` is then a Lyapunov function and, being translation invariant, leaves the
    centroid where it is.
    """
    s1 = replace(FIGURES["fig1"], steps=200, quick_steps=10)
    params, xs, _, _ = simulate_figure(s1, quick=quick, gradient="exact")
    L = lagrangian_value(xs, params)
    c = centroid(xs)
    return {
        "frames": len(xs) - 1,
        "L_start": float(L[0]),
        "L_end": float(L[-1]),
        "L_non_increasing": bool(np.all(np.diff(L) <= 0)),
        "centroid_displacement": float(np.linalg.norm(c[-1] - c[0])),
        "min_R_ij": float(min_pair_clearance(xs, params).min()),
        "spread_end": float(np.sqrt(((xs[-1] - c[-1]) ** 2).sum(-1).mean())),
    }
