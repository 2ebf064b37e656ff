"""The numbers of Mabrouk & McInnes' Figs. 1, 4–5, 6–8, 9 and 10 (relaxing swarms).

Each function runs the physics for every swept value from the same batch of random
initial conditions (:class:`~swarm_envs.papers.mabrouk_mcinnes.common.RunSetup`) and
returns the JSON-ready ``dict`` the package docstring describes, with the figure's
claims (:mod:`swarm_envs.papers.mabrouk_mcinnes.claims`) and verdict.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from swarm_envs.papers.claims import verdict
from swarm_envs.papers.mabrouk_mcinnes import claims as paper_claims
from swarm_envs.papers.mabrouk_mcinnes import common
from swarm_envs.papers.mabrouk_mcinnes.common import (
    DEFAULT_BETAS,
    DEFAULT_C_OS,
    DEFAULT_C_RATIOS,
    DEFAULT_L_RATIOS,
    RELAX_SPEED,
    RunSetup,
)
from swarm_envs.physics import SocialPotentialParams

__all__ = [
    "fig1_polarization_vs_beta",
    "fig4_5_variance_and_angular_momentum",
    "fig6_8_alignment_sweep",
    "fig9_range_ratio_sweep",
    "fig10_amplitude_ratio_sweep",
]

_COHESION_KEYS = ("C_a", "C_r", "l_a", "l_r", "C_o", "l_o", "beta", "m")


def _stat_lists(names: Sequence[str]) -> dict[str, dict[str, list[float]]]:
    return {n: {"time_mean": [], "time_mean_std": [], "final": [], "final_std": []} for n in names}


def fig1_polarization_vs_beta(
    betas: Sequence[float] = DEFAULT_BETAS, *, setup: RunSetup | None = None
) -> dict[str, Any]:
    """Fig. 1: group polarization against the dissipation coefficient β.

    **Paper.** "Higher dissipation will lead to a lower polarization"; "β = 0.1
    [is] the workable value of dissipation before a rapid leak of the system's energy".
    Caption parameters: ``C_a = 1, C_r = 1.2, C_o = 0.1, l_a = 1, l_r = 0.2,
    l_o = 1.5, m = 1`` (N = 30 from the text), β swept; polarization is eq. 2,
    ``|Σ v_i|/N``.

    **Here.** β in :data:`DEFAULT_BETAS` (the paper's values are not legible), all
    other parameters the caption's; :class:`RunSetup` for ``dt``, run length and
    initial conditions. Reported per β: eq. 2 and unit-heading polarization
    (``time_mean``, ``final``), the mean speed at the end, whether the swarm relaxed
    (final mean speed below :data:`RELAX_SPEED`), and the fitted decay rate of the
    total momentum, which the model fixes at ``−ln(1 − β dt)/dt ≈ β`` (so eq. 2
    polarization is the initial one times ``e^{−βt}``, independent of everything else).
    """
    setup = common.setup_for(setup)
    betas = common.sweep_values("betas", betas)
    base = SocialPotentialParams()
    x0, v0 = setup.initial()
    idx = common.sample_indices(setup.steps, setup.max_samples)
    names = ("velocity_polarization", "polarization", "mean_speed")
    stats = _stat_lists(names)
    curves: dict[str, list[list[float]]] = {n: [] for n in names[:2]}
    thin = common.thin(idx.size)
    decay_rates: list[float] = []
    for beta in betas:
        xs, vs = common.run_physics(
            replace(base, beta=beta), x0, v0, dt=setup.dt, duration=setup.duration
        )
        values = common.series(xs, vs, idx, names)
        for n in names:
            for key, value in common.summary(values[n]).items():
                stats[n][key].append(value)
        for n in curves:
            curves[n].append(values[n].mean(axis=1)[thin].tolist())
        # Fit window: until the momentum would have fallen by 1e-8 (below that the
        # rounding noise of a sum of N velocities dominates).
        n_fit = setup.steps
        if beta > 0:
            n_fit = min(n_fit, max(1, int(math.log(1e8) / -math.log1p(-min(beta * setup.dt, 0.5)))))
        total = vs[[0, n_fit]].sum(axis=-2)
        momentum = np.sqrt(np.einsum("...k,...k->...", total, total))
        ok = (momentum[0] > 0) & (momentum[1] > 0)
        rate = -np.log(momentum[1][ok] / momentum[0][ok]) / (n_fit * setup.dt)
        decay_rates.append(float(np.mean(rate)) if rate.size else float("nan"))
    relaxed = [s < RELAX_SPEED for s in stats["mean_speed"]["final"]]
    claims = paper_claims.fig1_claims(betas, stats)
    relaxed_betas = [b for b, r in zip(betas, relaxed, strict=True) if r]
    return {
        "figure": "fig1",
        "title": "Polarization vs dissipation β",
        "paper": {
            "claim": "higher β gives lower polarization; β ≈ 0.1 is the workable value",
            "parameters": common.params_dict(base, [k for k in _COHESION_KEYS if k != "beta"])
            | {"N": setup.n_agents},
        },
        "setup": setup.as_dict(),
        "x": {"name": "beta", "values": betas},
        "metrics": stats,
        "relaxed": relaxed,
        "smallest_relaxed_beta": min(relaxed_betas) if relaxed_betas else None,
        "momentum_decay_rate": decay_rates,
        "momentum_decay_rate_expected": [
            -math.log(1 - b * setup.dt) / setup.dt if b * setup.dt < 1 else float("nan")
            for b in betas
        ],
        "time_series": {"t": (idx[thin] * setup.dt).tolist(), **curves},
        "claims": claims,
        "verdict": verdict(claims),
    }


def _settle_time(ok: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Per column of ``ok`` (time first), the time from which it stays true to the end.

    ``inf`` for a column that is false at the last sample.
    """
    stays = np.flip(np.logical_and.accumulate(np.flip(ok, axis=0), axis=0), axis=0)
    return np.where(stays[-1], t[stays.argmax(axis=0)], np.inf)


def fig4_5_variance_and_angular_momentum(
    betas: Sequence[float] = (0.01, 1.8), *, setup: RunSetup | None = None
) -> dict[str, Any]:
    """Figs. 4–5: spherical variance and angular momentum against time, β = 0.01 and 1.8.

    **Paper.** With the larger β the speeds fall, "the value of spherical variance
    approaches unity very soon" and "the group angular momentum decreases rapidly
    with time until reaching zero". Caption parameters: ``C_a = 1, C_r = 1.2,
    C_o = 0.1, l_a = 1, l_r = 0.2, l_o = 1.5, m = 1``, β = 0.01 (Fig. 4) and 1.8
    (Fig. 5). Spherical variance is eq. 4 (needs unit headings), angular momentum
    eq. 3 (speed-weighted).

    **Here.** :class:`RunSetup` (50 time units). Per β: the seed-mean time series of
    spherical variance, eq. 3 and unit-heading angular momentum and mean speed; the
    median over seeds of the time from which the spherical variance stays at or above
    0.9 to the end of the run (``t_sigma_settle_0.9``, ``None``/inf if it never
    settles), of the time from which eq. 3 angular momentum stays below 10 % of its
    peak (``t_L_10pct``), and the run-mean and end values. (The *first* time
    σ reaches 0.9 says nothing: random initial headings and the radial collapse give
    σ ≈ 0.9–1 at the start for every β.) With β = 0.01 the swarm
    is far from relaxed after 50 time units (momentum ``e^{−0.5}`` of the start).
    """
    setup = common.setup_for(setup)
    betas = common.sweep_values("betas", betas)
    base = SocialPotentialParams()
    x0, v0 = setup.initial()
    idx = common.sample_indices(setup.steps, setup.max_samples)
    t = idx * setup.dt
    thin = common.thin(idx.size)
    names = ("spherical_variance", "velocity_angular_momentum", "angular_momentum", "mean_speed")
    per_beta: list[dict[str, Any]] = []
    for beta in betas:
        xs, vs = common.run_physics(
            replace(base, beta=beta), x0, v0, dt=setup.dt, duration=setup.duration
        )
        values = common.series(xs, vs, idx, names)
        sigma_t = _settle_time(values["spherical_variance"] >= 0.9, t)
        lam = values["velocity_angular_momentum"]
        l_t = _settle_time(lam <= 0.1 * lam.max(axis=0, keepdims=True), t)
        per_beta.append(
            {
                "beta": beta,
                # median over seeds; inf if more than half never got there
                "t_sigma_settle_0.9": float(np.median(sigma_t)),
                "t_L_10pct": float(np.median(l_t)),
                "summary": {n: common.summary(values[n]) for n in names},
                "series_mean": {n: values[n].mean(axis=1)[thin].tolist() for n in names},
                "series_std": {n: values[n].std(axis=1)[thin].tolist() for n in names},
            }
        )
    claims = paper_claims.fig4_5_claims(per_beta[0], per_beta[-1])
    return {
        "figure": "fig4_5",
        "title": "Spherical variance and angular momentum vs time",
        "paper": {
            "claim": "high β: spherical variance → 1 soon, angular momentum → 0 rapidly",
            "parameters": common.params_dict(base, [k for k in _COHESION_KEYS if k != "beta"])
            | {"beta": betas, "N": setup.n_agents},
        },
        "setup": setup.as_dict(),
        "t": t[thin].tolist(),
        "runs": per_beta,
        "claims": claims,
        "verdict": verdict(claims),
    }


def fig6_8_alignment_sweep(
    c_os: Sequence[float] = DEFAULT_C_OS, *, setup: RunSetup | None = None
) -> dict[str, Any]:
    """Figs. 6–8: angular momentum, polarization, expanse and NND against ``C_o``.

    **Paper.** As ``C_o`` increases the angular momentum "noticeably increases"
    (Fig. 6), the polarization decreases (Fig. 7), and the expanse and average NND
    "slowly increase" (Fig. 8, centrifugal action). Caption parameters: ``l_r = 0.2,
    l_a = 1, C_r = 1.2, C_a = 1, β = 0.1`` (``l_o = 1.5``, ``m = 1``, N = 30).

    **Here.** ``C_o`` in :data:`DEFAULT_C_OS`; :class:`RunSetup`. Both statistic forms
    and both ``time_mean`` and ``final`` are reported and tested. Expect: eq. 2
    polarization is *exactly* the same for every ``C_o`` (alignment conserves
    momentum); the relaxed end state (``final`` expanse/NND) is the same minimum-
    energy cluster for every ``C_o``; alignment slows the collapse, so the run-averaged
    expanse and NND grow with ``C_o``.
    """
    setup = common.setup_for(setup)
    c_os = common.sweep_values("c_os", c_os)
    base = SocialPotentialParams()
    names = (
        "velocity_angular_momentum",
        "angular_momentum",
        "velocity_polarization",
        "polarization",
        "expanse",
        "nearest_neighbor_distance",
    )
    stats = common.sweep([replace(base, C_o=c) for c in c_os], setup, names)
    claims = paper_claims.fig6_8_claims(c_os, stats)
    return {
        "figure": "fig6_8",
        "title": "Alignment strength C_o sweep",
        "paper": {
            "claim": "C_o up: angular momentum up, polarization down, expanse and NND slowly up",
            "parameters": common.params_dict(base, [k for k in _COHESION_KEYS if k != "C_o"])
            | {"N": setup.n_agents},
        },
        "setup": setup.as_dict(),
        "x": {"name": "C_o", "values": c_os},
        "metrics": stats,
        "claims": claims,
        "verdict": verdict(claims),
    }


def fig9_range_ratio_sweep(
    ratios: Sequence[float] = DEFAULT_L_RATIOS, *, setup: RunSetup | None = None
) -> dict[str, Any]:
    """Fig. 9: group expanse and average NND against the range ratio ``l = l_r / l_a``.

    **Paper.** As ``l`` increases, "which can be due to either l_r increasing and/or
    l_a decreasing", the expanse and NND increase: a more dispersed group. Caption
    parameters: ``C_r = 1.2, C_a = 1, β = 0.1`` (``C_o = 0.1``, ``l_o = 1.5``, N = 30).

    **Here.** Two series over ``l`` in :data:`DEFAULT_L_RATIOS`: ``vary_l_r``
    (``l_a = 1``, ``l_r = l``; the primary one, the paper's defaults have ``l_a = 1``)
    and ``vary_l_a`` (``l_r = 0.2``, ``l_a = 0.2 / l``). The equilibrium shape depends
    on ``C`` and ``l`` only and its size scales with ``l_a``, so the second series is
    also reported in units of ``l_a`` (``expanse_over_l_a``). Claims use the relaxed
    end state (``final``). ``C·l²`` (H-stability, > 1 needed in 2-D) is listed per
    point: every point is in the collapsing regime.
    """
    setup = common.setup_for(setup)
    ratios = common.sweep_values("ratios", ratios)
    base = SocialPotentialParams()
    names = ("expanse", "nearest_neighbor_distance")
    vary_l_r = common.sweep([replace(base, l_a=1.0, l_r=r) for r in ratios], setup, names)
    l_as = [base.l_r / r for r in ratios]
    vary_l_a = common.sweep([replace(base, l_a=la) for la in l_as], setup, names)
    scaled = {
        f"{n}_over_l_a": {
            k: [v / la for v, la in zip(vary_l_a[n][k], l_as, strict=True)]
            for k in ("time_mean", "final", "time_mean_std", "final_std")
        }
        for n in names
    }
    vary_l_a.update(scaled)
    claims = paper_claims.fig9_claims(ratios, vary_l_r, vary_l_a)
    return {
        "figure": "fig9",
        "title": "Range ratio l = l_r/l_a sweep",
        "paper": {
            "claim": "expanse and average NND increase with l = l_r/l_a",
            "parameters": common.params_dict(base, ("C_a", "C_r", "C_o", "l_o", "beta", "m"))
            | {"N": setup.n_agents},
        },
        "setup": setup.as_dict(),
        "x": {"name": "l = l_r/l_a", "values": ratios},
        "h_stability": [base.amplitude_ratio * r * r for r in ratios],
        "series": {"vary_l_r": vary_l_r, "vary_l_a": vary_l_a},
        "series_parameters": {
            "vary_l_r": {"l_a": 1.0, "l_r": ratios},
            "vary_l_a": {"l_r": base.l_r, "l_a": l_as},
        },
        "claims": claims,
        "verdict": verdict(claims),
    }


def fig10_amplitude_ratio_sweep(
    ratios: Sequence[float] = DEFAULT_C_RATIOS, *, setup: RunSetup | None = None
) -> dict[str, Any]:
    """Fig. 10: group expanse and average NND against the amplitude ratio ``C = C_r/C_a``.

    **Paper.** "When the values of C increase so does the value of group expanse and
    average NND's." Caption parameters: ``l_r = 0.2, l_a = 1, β = 0.1`` (``C_o = 0.1``,
    ``l_o = 1.5``, N = 30).

    **Here.** Two series over ``C`` in :data:`DEFAULT_C_RATIOS`: ``vary_C_r``
    (``C_a = 1``, ``C_r = C``; primary) and ``vary_C_a`` (``C_r = 1.2``,
    ``C_a = 1.2 / C``). Both have the same equilibria (only ``C`` matters to the
    minimum-energy shape; the amplitudes also set the time scale, so the transients
    differ). Claims use the relaxed end state (``final``).
    """
    setup = common.setup_for(setup)
    ratios = common.sweep_values("ratios", ratios)
    base = SocialPotentialParams()
    names = ("expanse", "nearest_neighbor_distance")
    vary_c_r = common.sweep([replace(base, C_a=1.0, C_r=c) for c in ratios], setup, names)
    c_as = [base.C_r / c for c in ratios]
    vary_c_a = common.sweep([replace(base, C_a=ca) for ca in c_as], setup, names)
    claims = paper_claims.fig10_claims(ratios, vary_c_r, vary_c_a)
    return {
        "figure": "fig10",
        "title": "Amplitude ratio C = C_r/C_a sweep",
        "paper": {
            "claim": "expanse and average NND increase with C = C_r/C_a",
            "parameters": common.params_dict(base, ("l_a", "l_r", "C_o", "l_o", "beta", "m"))
            | {"N": setup.n_agents},
        },
        "setup": setup.as_dict(),
        "x": {"name": "C = C_r/C_a", "values": ratios},
        "h_stability": [c * base.range_ratio**2 for c in ratios],
        "series": {"vary_C_r": vary_c_r, "vary_C_a": vary_c_a},
        "series_parameters": {
            "vary_C_r": {"C_a": 1.0, "C_r": ratios},
            "vary_C_a": {"C_r": base.C_r, "C_a": c_as},
        },
        "claims": claims,
        "verdict": verdict(claims),
    }
