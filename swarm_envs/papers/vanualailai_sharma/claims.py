"""What Vanualailai & Sharma show in Figs. 1–5, as claims on our measures.

The paper's figures carry no numbers, so every claim is a qualitative behaviour made
testable by a threshold of our own (:mod:`swarm_envs.papers.claims`). Each function
returns ``(claims, why, note)``: the claims, one sentence with the numbers behind them
(the JSON's ``why``), and a qualification of a ``"reproduced"`` verdict (``""`` if
none).
"""

from __future__ import annotations

import math
from typing import Any

from swarm_envs.papers.claims import Claim, bound_claim, claim

__all__ = ["FIGURE_CLAIMS", "exact_gradient_claims", "is_circle"]

_LATE = "over the last half of the run"


def _fig1(m: dict[str, Any], entry: dict[str, Any]) -> tuple[list[Claim], str, str]:
    """Type A: the swarm cruises non-stop in a straight line, well spaced, fixed formation."""
    speed = m["centroid_speed"]
    claims = [
        bound_claim("the centroid cruises along a straight line", m["late_net_over_path"],
                    measure="centroid path straightness (net / path length)",
                    statistic=_LATE, low=0.95),
        bound_claim("the centroid cruises at a steady speed", speed["late_cv"],
                    measure="coefficient of variation of the centroid speed",
                    statistic=_LATE, high=0.1),
        bound_claim("the swarm cruises non-stop", speed["late_mean"],
                    measure="centroid speed", statistic=f"mean {_LATE}", low=0.1),
        bound_claim("the group keeps a fixed formation", m["formation_change_late"],
                    measure="formation change (RMS, in units of the spread)",
                    statistic=_LATE, high=0.1),
        bound_claim("the members stay well spaced (no collision)", m["min_R_ij"],
                    measure="min R_ij", statistic="over the run", low=0.0),
    ]  # fmt: skip
    why = (
        f"late centroid path straightness {m['late_net_over_path']:.3f}, speed "
        f"{speed['late_mean']:.3g} (cv {speed['late_cv']:.2g}), "
        f"formation change {m['formation_change_late']:.2g} of the spread"
    )
    return claims, why, ""


def _fig2(m: dict[str, Any], entry: dict[str, Any]) -> tuple[list[Claim], str, str]:
    """Type A: a constant arrangement about a stationary centroid."""
    drift = m["centroid_speed"]["late_mean"] * m["t_end"] / 2
    claims = [
        bound_claim("the centroid remains stationary", drift / m["spread"]["end"],
                    measure="centroid drift over the late half, in units of the spread",
                    statistic=_LATE, high=0.25),
        bound_claim("the members converge to a constant arrangement",
                    m["formation_change_late"],
                    measure="formation change (RMS, in units of the spread)",
                    statistic=_LATE, high=0.1),
    ]  # fmt: skip
    why = (
        f"centroid drifts {m['centroid_speed']['late_mean']:.3g} per unit time late "
        f"({drift:.3g} over the late half vs spread {m['spread']['end']:.3g}); "
        f"formation change {m['formation_change_late']:.2g}"
    )
    return claims, why, "approximately: the centroid creeps, it does not stop"


def _fig3(m: dict[str, Any], entry: dict[str, Any]) -> tuple[list[Claim], str, str]:
    """Type B: a nonlinear path with an emergent leader."""
    lead = entry["leader"]
    claims = [
        bound_claim("a leader emerges", lead["leader_fraction_in_front"],
                    measure="fraction of frames the same agent is in front",
                    statistic=_LATE, low=0.8),
        bound_claim("the swarm follows a nonlinear path", m["late_net_over_path"],
                    measure="centroid path straightness (net / path length)",
                    statistic=_LATE, high=0.99),
        bound_claim("the swarm cruises", m["centroid_speed"]["late_mean"],
                    measure="centroid speed", statistic=f"mean {_LATE}", low=0.1),
    ]  # fmt: skip
    why = (
        f"agent {lead['leader']} in front {lead['leader_fraction_in_front']:.0%} of late "
        f"frames (γ = {lead['leader_gamma']:.3g}, γ-rank {lead['gamma_rank_of_leader']}), "
        f"path straightness {m['late_net_over_path']:.3f}, total turn "
        f"{m['late_total_turn_rad']:.2f} rad late, {m['total_turn_after_10pct_rad']:.2f} rad "
        "after a 10 % transient (the path bends early, then runs straight)"
    )
    return claims, why, ""


def _fig4(m: dict[str, Any], entry: dict[str, Any]) -> tuple[list[Claim], str, str]:
    """Type C: a Lévy-like random walk of the centroid."""
    claims = [
        bound_claim("the centroid performs a random walk", m["late_net_over_path"],
                    measure="centroid path straightness (net / path length)",
                    statistic=_LATE, high=0.5),
        bound_claim("the walk is Lévy-like (long straight runs, sharp turns)",
                    m["late_turn_kurtosis"],
                    measure="excess kurtosis of the per-frame turn angles",
                    statistic=_LATE, low=3.0),
    ]  # fmt: skip
    why = (
        f"late centroid path straightness {m['late_net_over_path']:.3f}, turn-angle excess "
        f"kurtosis {m['late_turn_kurtosis']:.1f} (heavy-tailed: long straight runs, sharp "
        "turns); no Lévy exponent fitted"
    )
    return claims, why, "qualitatively"


def is_circle(m: dict[str, Any]) -> bool:
    """Whether a run ends in circular motion: a steady turning sense, over two turns."""
    return m["late_turn_sign_consistency"] > 0.95 and abs(m["late_total_turn_rad"]) > 4 * math.pi


def _fig5(m: dict[str, Any], entry: dict[str, Any]) -> tuple[list[Claim], str, str]:
    """Type C: a random walk, then ordered circular motion (clockwise)."""
    turn = m["late_total_turn_rad"]
    sense = "clockwise" if turn < 0 else "counter-clockwise"
    sweep = entry.get("seed_sweep", [])
    n_circ = sum(s["circle"] for s in sweep)
    claims = [
        claim(
            "the swarm ends in ordered circular motion",
            measure="centroid heading: |mean sign| of the per-frame turns, |total turn|",
            statistic=_LATE,
            expected="sign consistency > 0.95 and |total turn| > 4π (two full turns)",
            observed=f"{m['late_turn_sign_consistency']:.3g}, {abs(turn):.3g} rad",
            holds=is_circle(m),
        ),
        claim(
            "the circular motion is clockwise",
            measure="sign of the total turn",
            statistic=_LATE,
            expected="clockwise",
            observed=sense,
            holds=sense == "clockwise",
            paper_form=False,
        ),
    ]
    if sweep:
        claims.append(
            claim(
                "circular motion appears whatever the random draws",
                measure="runs ending in circular motion",
                statistic="Fig. 5 seed sweep",
                expected="all seeds",
                observed=f"{n_circ}/{len(sweep)} seeds",
                holds=n_circ == len(sweep),
                paper_form=False,
            )
        )
    why = (
        f"late centroid turn {turn:.1f} rad, sign consistency "
        f"{m['late_turn_sign_consistency']:.2f} ({sense}); circles in {n_circ}/{len(sweep)} "
        "sweep seeds within the run"
    )
    return claims, why, "for the shown seed; seed-dependent, see sweep"


#: Figure name → ``f(measures, entry) -> (claims, why, note)``.
FIGURE_CLAIMS = {"fig1": _fig1, "fig2": _fig2, "fig3": _fig3, "fig4": _fig4, "fig5": _fig5}


def exact_gradient_claims(exact: dict[str, Any]) -> list[Claim]:
    """The paper's Lyapunov argument, under the exact gradient ``∇L`` (extras).

    The printed eq. 6 is not ``∇L``; under ``∇L`` itself ``L`` must not increase and,
    ``L`` being translation invariant, the centroid must stay where it is.
    """
    return [
        claim("L is a Lyapunov function (under the exact gradient ∇L)",
              measure="L(t)", statistic="every frame of a Fig. 1 run",
              expected="non-increasing", observed="non-increasing"
              if exact["L_non_increasing"] else "increases somewhere",
              holds=exact["L_non_increasing"], paper_form=False),
        bound_claim("the centroid stays where it is (under the exact gradient ∇L)",
                    exact["centroid_displacement"], measure="centroid displacement",
                    statistic="start to end of a Fig. 1 run", high=1e-8, paper_form=False),
    ]  # fmt: skip
