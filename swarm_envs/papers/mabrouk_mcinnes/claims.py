"""What Mabrouk & McInnes state, figure by figure, as claims on our numbers.

Each function takes the numbers a figure function computed and returns its claims
(:mod:`swarm_envs.papers.claims`). ``paper_form`` marks the claims on the paper's own
statistic forms (eqs. 2–3, speed-weighted); the unit-heading forms and restricted
ranges are reported beside them but do not count toward the verdict.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from swarm_envs.papers.claims import Claim, claim, trend_claim

__all__ = [
    "fig1_claims",
    "fig4_5_claims",
    "fig6_8_claims",
    "fig9_claims",
    "fig10_claims",
    "fig11_claims",
    "fig11_decay_claims",
    "fig11_mill_claims",
]

_STATS = ("time_mean", "final")


def fig1_claims(betas: Sequence[float], stats: dict[str, dict[str, list[float]]]) -> list[Claim]:
    """Fig. 1: "higher dissipation will lead to a lower polarization", both forms."""
    return [
        trend_claim(
            "higher dissipation leads to lower polarization (Fig. 1)",
            betas,
            stats[measure][stat],
            measure=measure,
            statistic=stat,
            expected="decreasing",
            paper_form=measure == "velocity_polarization",
        )
        for measure in ("velocity_polarization", "polarization")
        for stat in _STATS
    ]


def _sooner(a: float, b: float) -> bool:
    return a < b or (math.isfinite(a) and not math.isfinite(b))


def fig4_5_claims(lo: dict[str, Any], hi: dict[str, Any]) -> list[Claim]:
    """Figs. 4–5: with the larger β (``hi``) σ → 1 "very soon" and L → 0 "rapidly".

    ``lo`` and ``hi`` are the per-β entries of
    :func:`~swarm_envs.papers.mabrouk_mcinnes.sweeps.fig4_5_variance_and_angular_momentum`.
    """
    expected = f"β = {hi['beta']:g} below/sooner than β = {lo['beta']:g}"
    s_lo, s_hi = lo["t_sigma_settle_0.9"], hi["t_sigma_settle_0.9"]
    sm_lo = lo["summary"]["spherical_variance"]["time_mean"]
    sm_hi = hi["summary"]["spherical_variance"]["time_mean"]
    l_lo = lo["summary"]["velocity_angular_momentum"]["final"]
    l_hi = hi["summary"]["velocity_angular_momentum"]["final"]
    tl_lo, tl_hi = lo["t_L_10pct"], hi["t_L_10pct"]
    sv_hi = hi["summary"]["spherical_variance"]["final"]
    return [
        claim(
            "higher β: spherical variance approaches 1 very soon",
            measure="spherical_variance",
            statistic="time from which σ stays ≥ 0.9; run mean; final",
            expected=expected,
            observed=f"settles at t = {s_hi:.3g} (β = {hi['beta']:g}) vs {s_lo:.3g} "
            f"(β = {lo['beta']:g}); run mean {sm_hi:.3g} vs {sm_lo:.3g}; "
            f"final σ = {sv_hi:.3g}",
            holds=_sooner(s_hi, s_lo) and sm_hi > sm_lo and sv_hi >= 0.9,
        ),
        claim(
            "higher β: angular momentum decreases rapidly to zero",
            measure="velocity_angular_momentum",
            statistic="time from which L stays < 10 % of its peak; final",
            expected=expected,
            observed=f"t = {tl_hi:.3g} vs {tl_lo:.3g}; final {l_hi:.3g} vs {l_lo:.3g}",
            holds=_sooner(tl_hi, tl_lo) and l_hi < l_lo,
        ),
    ]


#: Figs. 6–8: (statement, measure, expected direction, paper form).
FIG6_8_PLAN = (
    ("Fig. 6: angular momentum increases with C_o", "velocity_angular_momentum",
     "increasing", True),
    ("Fig. 6: angular momentum increases with C_o", "angular_momentum", "increasing", False),
    ("Fig. 7: polarization decreases with C_o", "velocity_polarization", "decreasing", True),
    ("Fig. 7: polarization decreases with C_o", "polarization", "decreasing", False),
    ("Fig. 8: expanse slowly increases with C_o", "expanse", "increasing", True),
    ("Fig. 8: average NND slowly increases with C_o", "nearest_neighbor_distance",
     "increasing", True),
)  # fmt: skip


def fig6_8_claims(c_os: Sequence[float], stats: dict[str, dict[str, list[float]]]) -> list[Claim]:
    """Figs. 6–8: angular momentum up, polarization down, expanse and NND slowly up.

    Every trend on both statistics; then the run-mean trends over ``C_o > 0`` only
    (``C_o = 0`` is a different regime: nothing damps the relative motion but β, so the
    collapsed cluster keeps vibrating), as extras.
    """
    claims = [
        trend_claim(
            text,
            c_os,
            stats[measure][stat],
            measure=measure,
            statistic=stat,
            expected=expected,
            paper_form=paper_form,
        )
        for text, measure, expected, paper_form in FIG6_8_PLAN
        for stat in _STATS
    ]
    positive = [k for k, c in enumerate(c_os) if c > 0]
    if len(positive) >= 2:
        claims += [
            trend_claim(
                f"{text} (C_o > 0 only)",
                [c_os[k] for k in positive],
                [stats[measure]["time_mean"][k] for k in positive],
                measure=measure,
                statistic="time_mean",
                expected=expected,
                paper_form=False,
            )
            for text, measure, expected, _ in FIG6_8_PLAN
        ]
    return claims


def _ratio_claims(
    fig: str, x: Sequence[float], series: dict[str, Any], label: str, primary: bool
) -> list[Claim]:
    return [
        trend_claim(
            f"{fig}: {measure} increases with the ratio ({label})",
            x,
            series[measure]["final"],
            measure=measure,
            statistic="final",
            expected="increasing",
            paper_form=primary,
        )
        for measure in ("expanse", "nearest_neighbor_distance")
    ]


def fig9_claims(
    ratios: Sequence[float], vary_l_r: dict[str, Any], vary_l_a: dict[str, Any]
) -> list[Claim]:
    """Fig. 9: expanse and NND increase with ``l`` (``l_r`` varied counts; ``l_a`` extra)."""
    claims = _ratio_claims("Fig. 9", ratios, vary_l_r, "l_r varied, l_a = 1", True)
    claims += _ratio_claims("Fig. 9", ratios, vary_l_a, "l_a varied, l_r = 0.2", False)
    claims.append(
        trend_claim(
            "Fig. 9: expanse in units of l_a increases with the ratio (l_a varied)",
            ratios,
            vary_l_a["expanse_over_l_a"]["final"],
            measure="expanse_over_l_a",
            statistic="final",
            expected="increasing",
            paper_form=False,
        )
    )
    return claims


def fig10_claims(
    ratios: Sequence[float], vary_c_r: dict[str, Any], vary_c_a: dict[str, Any]
) -> list[Claim]:
    """Fig. 10: expanse and NND increase with ``C``, for ``C_r`` and for ``C_a`` varied."""
    return _ratio_claims("Fig. 10", ratios, vary_c_r, "C_r varied, C_a = 1", True) + _ratio_claims(
        "Fig. 10", ratios, vary_c_a, "C_a varied, C_r = 1.2", True
    )


def fig11_claims(
    reached: Sequence[bool], vortex_mean: float, *, goal_radius: float, duration: float
) -> list[Claim]:
    """Fig. 11: the swarm reaches the sink, in a vortex-like pattern on the way."""
    n_reached = sum(bool(r) for r in reached)
    return [
        claim(
            "the swarm approaches and reaches the potential sink at G",
            measure="centroid distance to G",
            statistic=f"centroid within {goal_radius:g} by t = {duration:g}",
            expected="all seeds",
            observed=f"{n_reached}/{len(reached)} seeds",
            holds=n_reached == len(reached),
        ),
        claim(
            "the swarm moves in a vortex-like pattern while approaching",
            measure="angular_momentum",
            statistic="mean during the approach",
            expected="> 0.5 (rotating ring ≈ 1, random headings ≈ 0.18)",
            observed=f"{vortex_mean:.3g}",
            holds=vortex_mean > 0.5,
        ),
    ]


def fig11_decay_claims(cases: Sequence[dict[str, Any]], *, rel_floor: float) -> list[Claim]:
    """Fig. 11, linear friction: ``L_G`` follows ``L_G(0)(1 − β dt/m)^n`` to round-off.

    A fact of the model, not a statement of the paper (``paper_form`` false): it is
    why the paper's parameters cannot produce a lasting vortex. ``cases`` are the
    entries of :func:`~swarm_envs.papers.mabrouk_mcinnes.mill.fig11_decay_law`.
    """
    dev = max(c["max_deviation_over_scale"] for c in cases)
    rel = max(c["max_relative_error"] for c in cases)
    labels = "; ".join(
        f"{c['label']}: {c['max_relative_error']:.1e} / {c['max_deviation_over_scale']:.1e}"
        for c in cases
    )
    return [
        claim(
            "with linear friction the angular momentum about G only decays, "
            "L_G(t_n) = L_G(0)(1 − β dt/m)^n",
            measure="goal angular momentum L_G = mean_i (r_i − G) × v_i",
            statistic=f"max relative error while |prediction| ≥ {rel_floor:g}·S₀; "
            "max |deviation|/S₀ (S₀ = mean_i |r_i − G||v_i| at t = 0); all seeds and cases",
            expected="relative error < 1e-6 and deviation < 1e-12 (round-off)",
            observed=f"{rel:.2e} and {dev:.2e} ({labels})",
            holds=rel < 1e-6 and dev < 1e-12,
            paper_form=False,
        )
    ]


def fig11_mill_claims(
    arrival: Sequence[float],
    hold: dict[str, list[float]],
    approach_milling: Sequence[float],
    *,
    goal_radius: float,
    duration: float,
    hold_from: float,
    fraction: float = 0.5,
    centred: float = 0.25,
    milling: float = 0.8,
) -> list[Claim]:
    """Fig. 11 with self-propulsion: the swarm reaches the sink and holds a mill on it.

    ``hold`` and ``approach_milling`` are the entries of
    :func:`~swarm_envs.papers.mabrouk_mcinnes.mill.fig11_self_propelled`. Every
    claim must hold in every seed. The first four count toward that run's own verdict;
    the last (a vortex already during the approach) is reported beside them, since it
    depends on whether the random start carries rotation.
    """
    n = len(arrival)
    window = f"t ≥ {hold_from:g}, every sample, all seeds"
    reached = sum(math.isfinite(a) for a in arrival)
    v_t = min(hold["tangential_speed_over_v0_min"])
    l_g = min(hold["L_G_over_R_v0_min"])
    off = max(hold["centroid_distance_over_R_max"])
    mill = min(hold["milling_min"])
    n_vortex = sum(m > 0.5 for m in approach_milling if math.isfinite(m))
    return [
        claim(
            "self-propelled: the swarm reaches the potential sink at G",
            measure="centroid distance to G",
            statistic=f"centroid within {goal_radius:g} by t = {duration:g}",
            expected="all seeds",
            observed=f"{reached}/{n} seeds",
            holds=reached == n,
        ),
        claim(
            "self-propelled: the swarm rotates about G and keeps rotating (a held mill)",
            measure="σ·tangential speed / v₀ and σ·L_G / (R̄ v₀) about G (σ: sense)",
            statistic=f"minimum over {window}",
            expected=f"both > {fraction:g}",
            observed=f"{v_t:.3g} and {l_g:.3g}",
            holds=v_t > fraction and l_g > fraction,
        ),
        claim(
            "self-propelled: the mill is centred on G",
            measure="centroid distance to G / mean radius R̄ about G",
            statistic=f"maximum over {window}",
            expected=f"< {centred:g}",
            observed=f"{off:.3g} (largest distance {max(hold['centroid_distance_max']):.3g})",
            holds=off < centred,
        ),
        claim(
            "self-propelled: the swarm has a vortex-like shape at the sink",
            measure="angular_momentum (unit headings, about the centroid)",
            statistic=f"minimum over {window}",
            expected=f"> {milling:g} (rotating ring ≈ 1, random headings ≈ 0.18)",
            observed=f"{mill:.3g}",
            holds=mill > milling,
        ),
        claim(
            "self-propelled: the swarm is already a vortex while approaching",
            measure="angular_momentum (unit headings, about the centroid)",
            statistic="mean from t = 5 to arrival, per seed",
            expected="> 0.5 in all seeds",
            observed=f"{n_vortex}/{n} seeds",
            holds=n_vortex == n,
            paper_form=False,
        ),
    ]
