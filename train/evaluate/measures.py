"""The measures reported per policy: :func:`summarize` of an :class:`EpisodeBatch`.

:data:`METRIC_DOCS` says in one line what each measure is; it goes into
``results.json`` (as ``"metrics"``) and ``summary.md``. A measure that is undefined
(the time to goal when no episode succeeded, a mean over no values, anything not
finite) is ``None`` — ``null`` in JSON, ``—`` in the tables — never NaN or infinity:
:func:`json_safe` applies the same rule to whole results before they are written.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from train.evaluate.bound import time_over_bound
from train.evaluate.episodes import FINAL_KEYS, EpisodeBatch

__all__ = ["METRIC_DOCS", "finite", "json_safe", "summarize", "wilson_interval"]

#: z of the two-sided 95 % normal quantile (the success rate's interval).
Z95 = 1.959963984540054

#: One line per reported measure (used for ``summary.md`` and the docs).
METRIC_DOCS = {
    "success_rate": "fraction of episodes that ended in success (terminated)",
    "success_ci95": "95 % Wilson score interval of the success rate, [low, high]",
    "mean_return": "mean over episodes of the summed cooperative reward",
    "std_return": "population standard deviation of the episode returns",
    "mean_time_to_goal": "simulated seconds (steps × dt) to the first step of success (in "
    "the mill task, of the mill), over successful episodes; null when none succeeded",
    "std_time_to_goal": "population standard deviation of the time to goal over "
    "successful episodes; null when none succeeded",
    "mean_episode_length": "mean episode length in steps",
    "collisions_per_episode": "colliding pairs (closer than collision_radius) summed over "
    "the episode's steps, mean over episodes",
    "std_collisions": "population standard deviation of the collisions per episode",
    "control_effort": "Σ_t mean_i |a_i|² over the episode (action units), mean over episodes",
    "control_effort_per_step": "the same divided by the episode length, mean over episodes",
    "unstable_episodes": "episodes truncated because a step went unstable "
    '(info["unstable"] = 1, on_unstable="truncate")',
    "time_over_bound": "mean over successful episodes of the time to goal over its lower "
    "bound (train.evaluate.bound), minus 1: 0 is optimal; null where no bound is defined",
    "mean_substeps": 'integration substeps per step (info["substeps"], step-size control), '
    "over all integrated steps of all episodes; null when no step was integrated",
    **{f"final_{k}": f"{k.replace('_', ' ')} at the episode's last step" for k in FINAL_KEYS},
}


def finite(value: Any) -> float | None:
    """``value`` as a float, or ``None`` where it is missing or not finite."""
    if value is None:
        return None
    x = float(value)
    return x if math.isfinite(x) else None


def _mean(values: np.ndarray) -> float | None:
    return finite(values.mean()) if values.size else None


def _std(values: np.ndarray) -> float | None:
    return finite(values.std()) if values.size else None


def wilson_interval(successes: int, n: int, z: float = Z95) -> tuple[float, float] | None:
    """The Wilson score interval of a proportion (95 % by default); ``None`` if ``n = 0``.

    >>> [round(x, 3) for x in wilson_interval(0, 10)]
    [0.0, 0.278]
    """
    if n <= 0:
        return None
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)


def summarize(batch: EpisodeBatch, bound: np.ndarray | None = None) -> dict[str, Any]:
    """The JSON-ready measures of one :class:`EpisodeBatch` (see :data:`METRIC_DOCS`);
    undefined ones are ``None``. ``bound``: each episode's lower bound on the time to
    goal (``(B,)`` seconds, :func:`~train.evaluate.bound.time_to_goal_bound`), for
    ``time_over_bound``."""
    ok = batch.success
    lengths = batch.lengths.astype(np.float64)
    reached = lengths if batch.first_success is None else batch.first_success
    times = reached[ok].astype(np.float64) * batch.dt
    ci = wilson_interval(int(ok.sum()), ok.size)
    integrated = int(batch.integrated.sum())
    out: dict[str, Any] = {
        "mode": batch.mode,
        "mean_return": _mean(batch.returns),
        "std_return": _std(batch.returns),
        "success_rate": _mean(ok.astype(np.float64)),
        "success_ci95": None if ci is None else [ci[0], ci[1]],
        "mean_time_to_goal": _mean(times),
        "std_time_to_goal": _std(times),
        "mean_episode_length": _mean(lengths),
        "collisions_per_episode": _mean(batch.collisions),
        "std_collisions": _std(batch.collisions),
        "control_effort": _mean(batch.effort),
        "control_effort_per_step": _mean(batch.effort / np.maximum(lengths, 1)),
        "unstable_episodes": int(batch.unstable.sum()),
        "mean_substeps": finite(batch.substeps.sum() / integrated) if integrated else None,
    }
    out["time_over_bound"] = time_over_bound(reached * batch.dt, ok, bound)
    for k in FINAL_KEYS:
        out[f"final_{k}"] = _mean(batch.final[k])
    out["per_episode"] = {
        "return": [finite(r) for r in batch.returns],
        "success": [bool(s) for s in ok],
        "steps": [int(n) for n in batch.lengths],
        "time_to_goal": [
            float(t) * batch.dt if s else None for t, s in zip(reached, ok, strict=True)
        ],
        "unstable": [bool(u) for u in batch.unstable],
    }
    return out


def json_safe(obj: Any) -> Any:
    """``obj`` with every float that is not finite replaced by ``None`` and numpy
    scalars and arrays made plain Python, so that ``json.dumps(..., allow_nan=False)``
    accepts it."""
    if isinstance(obj, Mapping):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return [json_safe(v) for v in obj.tolist()]
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return finite(obj)
    return obj
