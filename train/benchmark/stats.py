"""Bootstrap confidence intervals of the benchmark's measures.

The data of one policy in one evaluation are arrays shaped ``(S, E)``: ``S`` training
seeds (one for a deterministic baseline) × ``E`` episodes, the same seeded episodes for
every policy. :func:`bootstrap` draws resamples of them in two levels: first ``S`` seeds
with replacement, then, within each drawn seed, ``E`` of its episodes with replacement
(the hierarchical bootstrap; with one seed it is the ordinary bootstrap over episodes).
Every statistic is computed on every resample, with the same resampled indices for all
of them; the interval is the percentile interval of the resampled values (95 % by
default: the 2.5 % and 97.5 % quantiles).

Both levels matter for a learned policy: seeds differ more from each other than
episodes of one seed do, and an interval over episodes alone would hide that. With few
seeds the seed level has few distinct resamples (3 seeds: 10), so the interval is a
rough one; more seeds narrow it honestly.

The statistics (:data:`STATISTICS`):

- ``return``: mean episode return;
- ``success``: fraction of episodes that succeeded;
- ``time_to_goal``: mean simulated time to success over the successful episodes
  (pooled over seeds); undefined (``None``) where no episode succeeded;
- ``iqm_return``: the interquartile mean of the episode returns, pooled over seeds
  (the mean of the middle 50 %: ``scipy.stats.trim_mean(x, 0.25)``), a summary robust
  to a few outlying episodes, as ``rliable`` recommends.

A statistic undefined on a resample (the time to goal of a resample without success) is
left out of that statistic's interval; ``defined`` reports the fraction of resamples
where it was defined.

>>> import numpy as np
>>> x = np.arange(6.0).reshape(2, 3)
>>> r = bootstrap({"v": x}, {"mean": lambda d: d["v"].mean(axis=(-2, -1))}, n_resamples=200)
>>> r["mean"].value, r["mean"].low <= 2.5 <= r["mean"].high
(2.5, True)
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from train.evaluate.measures import finite

__all__ = [
    "BOOTSTRAP_SEED",
    "CONFIDENCE",
    "N_RESAMPLES",
    "STATISTICS",
    "Interval",
    "bootstrap",
    "interquartile_mean",
    "mean_over_defined",
    "paired_difference",
    "summarize_runs",
]

#: Resamples of every bootstrap.
N_RESAMPLES = 10_000
#: Seed of the bootstrap's generator (``numpy.random.default_rng``).
BOOTSTRAP_SEED = 0
#: Coverage of the intervals.
CONFIDENCE = 0.95
#: Most resampled values held at once (resamples are drawn in chunks of this size).
CHUNK_VALUES = 4_000_000

Statistic = Callable[[Mapping[str, np.ndarray]], np.ndarray]


@dataclass(frozen=True)
class Interval:
    """A statistic's value on the data and its bootstrap interval.

    ``value`` is None where the statistic is undefined on the data, ``low`` and
    ``high`` where it is undefined on every resample; ``defined`` is the fraction of
    resamples where it was defined.
    """

    value: float | None
    low: float | None
    high: float | None
    defined: float

    def to_dict(self) -> dict[str, Any]:
        """``{"value", "ci": [low, high] or None, "defined_resamples"}``."""
        ci = None if self.low is None or self.high is None else [self.low, self.high]
        return {"value": self.value, "ci": ci, "defined_resamples": self.defined}


def interquartile_mean(x: np.ndarray) -> np.ndarray:
    """The interquartile mean over the last two axes (seeds × episodes pooled).

    Cuts ``floor(n / 4)`` values from each end of the ``n`` sorted values and averages
    the rest, as ``scipy.stats.trim_mean(x, 0.25)`` does.

    >>> float(interquartile_mean(np.array([[1.0, 2.0, 3.0, 100.0]])))
    2.5
    """
    flat = np.sort(x.reshape(*x.shape[:-2], -1), axis=-1)
    n = flat.shape[-1]
    cut = n // 4
    return flat[..., cut : n - cut].mean(axis=-1)


def mean_over_defined(x: np.ndarray) -> np.ndarray:
    """The mean over the last two axes of the finite values; NaN where there are none
    (no warning).

    >>> mean_over_defined(np.array([[[1.0, np.nan], [3.0, np.nan]], [[np.nan] * 2] * 2]))
    array([ 2., nan])
    """
    ok = np.isfinite(x)
    total = np.where(ok, x, 0.0).sum(axis=(-2, -1))
    count = ok.sum(axis=(-2, -1))
    return np.divide(total, count, out=np.full(total.shape, np.nan), where=count > 0)


def _mean(key: str) -> Statistic:
    return lambda d: d[key].mean(axis=(-2, -1))


#: The statistics of :func:`summarize_runs`, each of the resampled arrays ``return``,
#: ``success`` (0/1) and ``time`` (time to goal, NaN where the episode failed).
STATISTICS: dict[str, Statistic] = {
    "return": _mean("return"),
    "success": _mean("success"),
    "time_to_goal": lambda d: mean_over_defined(d["time"]),
    "iqm_return": lambda d: interquartile_mean(d["return"]),
}


def _check_data(data: Mapping[str, Any]) -> dict[str, np.ndarray]:
    if not data:
        raise ValueError("bootstrap needs at least one array")
    arrays = {k: np.asarray(v, dtype=np.float64) for k, v in data.items()}
    shapes = {v.shape for v in arrays.values()}
    shape = next(iter(shapes))
    if len(shapes) != 1 or len(shape) != 2 or min(shape) < 1:
        raise ValueError(
            "bootstrap data must be arrays of one shape (seeds, episodes), each >= 1; "
            f"got shapes {sorted(shapes)}"
        )
    return arrays


def bootstrap(
    data: Mapping[str, Any],
    statistics: Mapping[str, Statistic],
    *,
    n_resamples: int = N_RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
    confidence: float = CONFIDENCE,
) -> dict[str, Interval]:
    """The hierarchical bootstrap intervals of ``statistics`` on ``data``.

    Args:
        data: arrays of one shape ``(S, E)``: seeds × episodes.
        statistics: name → function of a mapping like ``data`` whose arrays have
            leading resample axes, ``(..., S, E)``, returning ``(...)``. NaN marks a
            value undefined on that resample.
        n_resamples: number of resamples ``≥ 1``.
        seed: seed of the generator; the same seed gives the same intervals.
        confidence: coverage of the percentile interval, in ``(0, 1)``.

    Raises:
        ValueError: arrays of different or empty shapes, or bad ``n_resamples`` or
            ``confidence``.
    """
    arrays = _check_data(data)
    if isinstance(n_resamples, bool) or int(n_resamples) != n_resamples or n_resamples < 1:
        raise ValueError(f"n_resamples must be an integer >= 1, got {n_resamples!r}")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence!r}")
    S, E = next(iter(arrays.values())).shape
    rng = np.random.default_rng(seed)
    chunk = max(1, min(int(n_resamples), CHUNK_VALUES // (S * E)))
    values: dict[str, list[np.ndarray]] = {name: [] for name in statistics}
    done = 0
    while done < n_resamples:
        m = min(chunk, int(n_resamples) - done)
        seeds = rng.integers(0, S, size=(m, S))
        episodes = rng.integers(0, E, size=(m, S, E))
        resampled = {k: v[seeds[..., None], episodes] for k, v in arrays.items()}
        for name, stat in statistics.items():
            values[name].append(np.asarray(stat(resampled), dtype=np.float64))
        done += m
    tail = (1.0 - confidence) / 2.0
    out = {}
    for name, stat in statistics.items():
        value = finite(np.asarray(stat({k: v[None] for k, v in arrays.items()}))[0])
        drawn = np.concatenate(values[name])
        ok = drawn[np.isfinite(drawn)]
        low = high = None
        if ok.size:
            low, high = (float(q) for q in np.quantile(ok, [tail, 1.0 - tail]))
        out[name] = Interval(value, low, high, ok.size / drawn.size)
    return out


def summarize_runs(
    returns: Any,
    success: Any,
    steps: Any,
    dt: float,
    *,
    n_resamples: int = N_RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
    confidence: float = CONFIDENCE,
) -> dict[str, Any]:
    """The benchmark's measures of one policy with their intervals and per-seed values.

    Args:
        returns, success, steps: per-episode returns, success flags and the steps to
            the first success (the episode's length in navigation), each ``(S, E)``.
        dt: the step's simulated seconds (time to goal = steps × dt).

    Returns ``{"n_seeds", "n_episodes", "<statistic>": Interval.to_dict(), ...,
    "per_seed": {"<statistic>": [one value per seed]}}`` for each of
    :data:`STATISTICS`; undefined values are None.
    """
    ok = np.asarray(success, dtype=bool)
    data = {
        "return": np.asarray(returns, dtype=np.float64),
        "success": ok.astype(np.float64),
        "time": np.where(ok, np.asarray(steps, dtype=np.float64) * dt, np.nan),
    }
    arrays = _check_data(data)
    intervals = bootstrap(
        arrays, STATISTICS, n_resamples=n_resamples, seed=seed, confidence=confidence
    )
    S, E = arrays["return"].shape
    per_seed = {
        name: [finite(v) for v in stat({k: v[:, None, :] for k, v in arrays.items()})]
        for name, stat in STATISTICS.items()
    }
    return {
        "n_seeds": S,
        "n_episodes": E,
        **{name: iv.to_dict() for name, iv in intervals.items()},
        "per_seed": per_seed,
    }


def paired_difference(
    learned: Any,
    baseline: Any,
    *,
    n_resamples: int = N_RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
    confidence: float = CONFIDENCE,
) -> dict[str, Any]:
    """The mean of ``learned − baseline`` over paired episodes, with its interval.

    ``learned`` is ``(S, E)`` (seeds × episodes), ``baseline`` ``(E,)`` or ``(1, E)``, on
    the same seeded episodes: each learned episode is paired with the baseline's run of
    the same start, and the differences ``(S, E)`` are resampled as :func:`bootstrap`
    does (seeds, then episodes). Pairing removes what the episodes share (a far goal
    costs every policy), so the interval is the one a "learned beats baseline" claim
    needs. Returns :meth:`Interval.to_dict`.

    >>> d = paired_difference(np.array([[2.0, 3.0, 4.0]]), np.array([1.0, 2.0, 3.0]),
    ...                       n_resamples=100)
    >>> d["value"], d["ci"]
    (1.0, [1.0, 1.0])
    """
    a = np.asarray(learned, dtype=np.float64)
    b = np.asarray(baseline, dtype=np.float64).reshape(1, -1)
    if a.ndim != 2 or a.shape[1] != b.shape[1]:
        raise ValueError(
            f"paired_difference: learned {a.shape} and baseline {b.shape} must share episodes"
        )
    out = bootstrap(
        {"diff": a - b},
        {"mean": _mean("diff")},
        n_resamples=n_resamples,
        seed=seed,
        confidence=confidence,
    )
    return out["mean"].to_dict()
