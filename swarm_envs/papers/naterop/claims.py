"""What the Naterop report states, as claims on our numbers (zone and force models).

Built with :mod:`swarm_envs.papers.claims`; the verdicts follow its rule (all claims
hold, some, none).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import Any

import numpy as np

from swarm_envs.papers.claims import Claim, claim

__all__ = ["dispersal_claims", "zone_row_claims", "zone_trend_claims"]


def zone_row_claims(
    row: dict[str, Any], report: dict[str, float], *, label: str = ""
) -> tuple[list[Claim], list[str]]:
    """Claims on one row of table 3, and a sentence per claim for the JSON's ``why``.

    A row is reproduced when our state label is the report's, ``|ΔP| ≤ 0.1``, the raw
    angular momentum is within a factor 2, and the median time to food within 30 %.
    ``label`` is appended to the statements (e.g. the reading of φ̄).
    """
    name = f"{row['configuration']} (r_o = {row['r_o']:g}){label}"
    p, p_rep = row["polarization"], report["polarization"]
    lraw, l_rep = row["angular_momentum_raw"], report["angular_momentum_raw"]
    t, t_rep = row["time_to_food_median"], report["time_to_food"]
    claims = [
        claim(
            f"{name}: the group is in the report's state",
            measure="state label from unit-heading P and M",
            statistic="time mean over [t_start, t_end], mean over seeds",
            expected=row["configuration"],
            observed=row["state"],
            holds=row["state"] == row["configuration"],
        ),
        claim(
            f"{name}: polarization as in table 3",
            measure="polarization (eq. 8)",
            statistic="time mean, mean over seeds",
            expected=f"{p_rep:.2f} ± 0.1",
            observed=p,
            holds=abs(p - p_rep) <= 0.1,
        ),
        claim(
            f"{name}: angular momentum as in table 3",
            measure="raw angular momentum (eq. 10)",
            statistic="time mean, mean over seeds",
            expected=f"{l_rep:.2f}, within a factor 2",
            observed=lraw,
            holds=0.5 <= lraw / l_rep <= 2.0,
        ),
        claim(
            f"{name}: time to food as in table 3",
            measure="time until the first member reaches the food [s]",
            statistic="median over repetitions",
            expected=f"{t_rep:.0f} ± 30 %",
            observed=t,
            holds=abs(t - t_rep) <= 0.3 * t_rep,
        ),
    ]
    why = [
        f"state: ours {row['state']!r} (P={p:.2f}, M={row['angular_momentum']:.2f}) vs "
        f"report {row['configuration']!r}" + (" — match" if claims[0]["holds"] else " — differs"),
        f"polarization {p:.2f} vs {p_rep:.2f}"
        + (" (within 0.1)" if claims[1]["holds"] else " (off by more than 0.1)"),
        f"raw angular momentum {lraw:.2f} vs {l_rep:.2f}"
        + (" (within x2)" if claims[2]["holds"] else " (off by more than x2)"),
        f"median time to food {t:.0f} s vs {t_rep:.0f} s"
        + (" (within 30 %)" if claims[3]["holds"] else " (off by more than 30 %)"),
    ]
    return claims, why


def zone_trend_claims(
    rows: Sequence[dict[str, Any]], *, label: str = "", paper_form: bool = True
) -> list[Claim]:
    """The report's qualitative claims across the four configurations (§5.3).

    ``rows`` are in the order of increasing ``r_o`` (swarm, torus, dynamic parallel,
    highly parallel).
    """
    p = [r["polarization"] for r in rows]
    lraw = [r["angular_momentum_raw"] for r in rows]
    t = [r["time_to_food_median"] for r in rows]
    largest = rows[int(np.argmax(lraw))]["configuration"]
    return [
        claim(
            f"polarization increases with r_o{label}",
            measure="polarization (eq. 8)",
            statistic="per configuration, in the order of r_o",
            expected="strictly increasing",
            observed=p,
            holds=all(a < b for a, b in itertools.pairwise(p)),
            paper_form=paper_form,
        ),
        claim(
            f"the torus has the largest angular momentum{label}",
            measure="raw angular momentum (eq. 10)",
            statistic="largest over the configurations",
            expected="torus",
            observed=largest,
            holds=largest == "torus",
            paper_form=paper_form,
        ),
        claim(
            f"time to food decreases with r_o{label}",
            measure="median time to food [s]",
            statistic="per configuration, in the order of r_o",
            expected="strictly decreasing",
            observed=t,
            holds=all(a > b for a, b in itertools.pairwise(t)),
            paper_form=paper_form,
        ),
    ]


def dispersal_claims(dispersed: np.ndarray, bounded: np.ndarray) -> list[Claim]:
    """§5.1 and its fix (§5.1, §6), on the per-run flags of the two main settings.

    ``dispersed`` holds the flags of the report-like runs (no drag, ``dt = 0.1 s``),
    ``bounded`` those of the fixed runs (drag, ``dt = 0.01 s``), over ``r_0`` and seeds.
    """
    d, b = np.asarray(dispersed, dtype=bool), np.asarray(bounded, dtype=bool)
    return [
        claim(
            "§5.1: the expanse increases continuously with time for all cases "
            "(no drag, dt = 0.1 s)",
            measure="expanse (eq. 11)",
            statistic="E(T) >= 5 E(0) and E(T) >= 1.3 E(T/2), per r_0 and seed",
            expected="all runs",
            observed=f"{int(d.sum())}/{d.size} runs",
            holds=bool(d.all()),
        ),
        claim(
            "§5.1/§6: a smaller time step and a drag force keep the swarm together "
            "(β = 0.5, dt = 0.01 s)",
            measure="expanse (eq. 11)",
            statistic="mean E[T/2,T] <= 1.2 mean E[T/4,T/2] and max E[T/2,T] < R, per r_0 and seed",
            expected="all runs",
            observed=f"{int(b.sum())}/{b.size} runs",
            holds=bool(b.all()),
        ),
    ]
