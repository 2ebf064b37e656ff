"""Claims and verdicts, shared by every reproduction.

A **claim** is one statement of a paper tested on one measure of our runs. It is a
plain, JSON-ready ``dict`` (:data:`Claim`) with the keys of :data:`CLAIM_KEYS`:

``claim``
    the statement, in the paper's words where possible.
``measure``, ``statistic``
    what was measured and how it was reduced (time mean, final value, median, …).
``expected``, ``observed``
    what the paper leads us to expect and what we found (a direction, a bound, a
    count, a number).
``holds``
    whether the observation matches the expectation.
``paper_form``
    ``True`` when the claim tests the paper's statement in the paper's own terms
    (its statistic, its reading of the model); only these claims count toward the
    verdict. The others (other statistic forms, other readings, restricted ranges)
    are reported beside them.

Extra keys carry details (e.g. ``spearman`` for a trend).

A **verdict** is drawn from the ``paper_form`` claims of one figure or table
(:func:`verdict`): ``"reproduced"`` when all hold, ``"partly reproduced"`` when some
do, ``"not reproduced"`` when none does.

Trends along a sweep are classified by :func:`classify_trend` (Spearman rank
correlation and spread) and turned into claims by :func:`trend_claim`; numeric
bounds by :func:`bound_claim`; anything else by :func:`claim`.

>>> c = bound_claim("the path is straight", 0.99, measure="straightness",
...                 statistic="late half", low=0.95)
>>> c["expected"], c["holds"]
('> 0.95', True)
>>> verdict([c, claim("a circle forms", measure="turn", statistic="late half",
...                   expected="yes", observed="no", holds=False)])
'partly reproduced'
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

__all__ = [
    "CLAIM_KEYS",
    "VERDICTS",
    "Claim",
    "bound_claim",
    "claim",
    "classify_trend",
    "format_claim",
    "tally",
    "trend_claim",
    "verdict",
]

#: A claim: a JSON-ready dict with (at least) the keys of :data:`CLAIM_KEYS`.
Claim = dict[str, Any]

#: The keys every claim has.
CLAIM_KEYS = ("claim", "measure", "statistic", "expected", "observed", "holds", "paper_form")

#: The three verdicts, best first.
VERDICTS = ("reproduced", "partly reproduced", "not reproduced")


def claim(
    statement: str,
    *,
    measure: str,
    statistic: str,
    expected: Any,
    observed: Any,
    holds: bool,
    paper_form: bool = True,
    **details: Any,
) -> Claim:
    """One claim (see the module docstring); ``details`` become extra keys.

    >>> claim("reaches the goal", measure="distance", statistic="final",
    ...       expected="all seeds", observed="3/4 seeds", holds=False)["holds"]
    False
    """
    return {
        "claim": statement,
        "measure": measure,
        "statistic": statistic,
        "expected": expected,
        "observed": observed,
        "holds": bool(holds),
        "paper_form": bool(paper_form),
        **details,
    }


def _bound_text(low: float | None, high: float | None, strict: bool) -> str:
    lt, gt = ("<", ">") if strict else ("≤", "≥")
    if low is not None and high is not None:
        return f"{low:g} {lt} x {lt} {high:g}"
    if low is not None:
        return f"{gt} {low:g}"
    if high is not None:
        return f"{lt} {high:g}"
    raise ValueError("bound_claim needs low, high or both")


def bound_claim(
    statement: str,
    value: float,
    *,
    measure: str,
    statistic: str,
    low: float | None = None,
    high: float | None = None,
    strict: bool = True,
    paper_form: bool = True,
    **details: Any,
) -> Claim:
    """A claim that ``value`` lies above ``low`` and/or below ``high``.

    ``strict`` compares with ``<``/``>``, else with ``≤``/``≥``. A non-finite
    ``value`` never holds.

    >>> bound_claim("close", float("inf"), measure="error", statistic="median",
    ...             high=0.3, strict=False)["holds"]
    False
    """
    x = float(value)
    ok = math.isfinite(x)
    if low is not None:
        ok = ok and (x > low if strict else x >= low)
    if high is not None:
        ok = ok and (x < high if strict else x <= high)
    return claim(
        statement,
        measure=measure,
        statistic=statistic,
        expected=_bound_text(low, high, strict),
        observed=x,
        holds=ok,
        paper_form=paper_form,
        **details,
    )


def _spearman(x: np.ndarray, y: np.ndarray) -> float:
    """Spearman rank correlation (no ties expected; 0 for a constant input)."""
    rx = np.argsort(np.argsort(x)).astype(np.float64)
    ry = np.argsort(np.argsort(y)).astype(np.float64)
    rx -= rx.mean()
    ry -= ry.mean()
    den = math.sqrt(float((rx * rx).sum() * (ry * ry).sum()))
    return float((rx * ry).sum() / den) if den > 0 else 0.0


def classify_trend(
    x: Sequence[float],
    y: Sequence[float],
    *,
    flat_tol: float = 0.05,
    rho_min: float = 0.8,
) -> dict[str, Any]:
    """Direction of ``y`` along ``x``: increasing, decreasing, flat or non-monotonic.

    ``increasing``/``decreasing`` when the Spearman rank correlation is at least
    ``rho_min`` in size (however small the change: a paper's "slowly increases"
    counts; ``relative_change`` says how much), ``flat`` when it is not but the spread
    ``max y − min y`` is below ``flat_tol`` times ``max |y|`` (or ``y`` is constant
    to 1e-9), else ``non-monotonic``.

    Returns ``{"direction", "spearman", "relative_change"}``, the last being
    ``(y[-1] − y[0]) / max |y|``.

    >>> classify_trend([1, 2, 3, 4], [0.1, 0.2, 0.25, 0.4])["direction"]
    'increasing'
    >>> classify_trend([1, 2, 3], [1.0, 1.01, 0.99])["direction"]
    'flat'
    """
    xa = np.asarray(x, dtype=np.float64)
    ya = np.asarray(y, dtype=np.float64)
    if xa.shape != ya.shape or xa.ndim != 1 or xa.size < 2:
        raise ValueError(
            "classify_trend needs two 1-D sequences of equal length >= 2, "
            f"got shapes {xa.shape} and {ya.shape}"
        )
    scale = float(np.max(np.abs(ya)))
    spread = float(ya.max() - ya.min())
    rho = _spearman(xa, ya)
    rel = float((ya[-1] - ya[0]) / scale) if scale > 0 else 0.0
    if scale == 0 or spread <= 1e-9 * scale:
        direction = "flat"
    elif rho >= rho_min:
        direction = "increasing"
    elif rho <= -rho_min:
        direction = "decreasing"
    elif spread < flat_tol * scale:
        direction = "flat"
    else:
        direction = "non-monotonic"
    return {"direction": direction, "spearman": rho, "relative_change": rel}


def trend_claim(
    statement: str,
    x: Sequence[float],
    y: Sequence[float],
    *,
    measure: str,
    statistic: str,
    expected: str,
    paper_form: bool = True,
) -> Claim:
    """A claim that ``y`` follows the ``expected`` direction along ``x``.

    ``observed`` is the direction :func:`classify_trend` finds; ``spearman`` and
    ``relative_change`` are added as details.

    >>> trend_claim("grows", [0, 1, 2], [1.0, 2.0, 4.0], measure="expanse",
    ...             statistic="final", expected="increasing")["holds"]
    True
    """
    trend = classify_trend(x, y)
    return claim(
        statement,
        measure=measure,
        statistic=statistic,
        expected=expected,
        observed=trend["direction"],
        holds=trend["direction"] == expected,
        paper_form=paper_form,
        spearman=trend["spearman"],
        relative_change=trend["relative_change"],
    )


def tally(claims: Iterable[Claim]) -> tuple[int, int]:
    """``(held, counted)``: how many ``paper_form`` claims hold, out of how many.

    >>> tally([{"holds": True, "paper_form": True}, {"holds": False, "paper_form": True},
    ...        {"holds": True, "paper_form": False}])
    (1, 2)
    """
    held = [bool(c["holds"]) for c in claims if c["paper_form"]]
    return sum(held), len(held)


def verdict(claims: Iterable[Claim]) -> str:
    """The verdict from the ``paper_form`` claims: all hold, some, none (or no claim).

    >>> verdict([]), verdict([{"holds": True, "paper_form": True}])
    ('not reproduced', 'reproduced')
    """
    held, counted = tally(claims)
    if counted and held == counted:
        return "reproduced"
    if held:
        return "partly reproduced"
    return "not reproduced"


def _text(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def format_claim(c: Claim) -> str:
    """One line for a log: holds or not, counted or extra, expected and observed.

    >>> format_claim(claim("grows", measure="expanse", statistic="final",
    ...                    expected="increasing", observed="flat", holds=False))
    '[NO ] (paper) grows — expanse, final: expected increasing, observed flat'
    """
    mark = "yes" if c["holds"] else "NO "
    form = "paper" if c["paper_form"] else "extra"
    return (
        f"[{mark}] ({form}) {c['claim']} — {c['measure']}, {c['statistic']}: "
        f"expected {_text(c['expected'])}, observed {_text(c['observed'])}"
    )
