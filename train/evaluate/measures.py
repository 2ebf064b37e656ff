"""The measures reported per policy: :func:`summarize` of an :class:`EpisodeBatch`.

:data:`METRIC_DOCS` says in one line what each measure is; it goes into
``results.json`` (as ``"metrics"``) and ``summary.md``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from train.evaluate.episodes import FINAL_KEYS, EpisodeBatch

__all__ = ["METRIC_DOCS", "summarize"]

#: One line per reported measure (used for ``summary.md`` and the docs).
METRIC_DOCS = {
    "success_rate": "fraction of episodes that ended in success (terminated)",
    "mean_return": "mean over episodes of the summed cooperative reward",
    "std_return": "population standard deviation of the episode returns",
    "mean_time_to_goal": "simulated seconds (steps × dt) to success, over successful "
    "episodes; null when none succeeded",
    "mean_episode_length": "mean episode length in steps",
    "collisions_per_episode": "colliding pairs (closer than collision_radius) summed over "
    "the episode's steps, mean over episodes",
    "control_effort": "Σ_t mean_i |a_i|² over the episode (action units), mean over episodes",
    "control_effort_per_step": "the same divided by the episode length, mean over episodes",
    **{f"final_{k}": f"{k.replace('_', ' ')} at the episode's last step" for k in FINAL_KEYS},
}


def summarize(batch: EpisodeBatch) -> dict[str, Any]:
    """The JSON-ready measures of one :class:`EpisodeBatch` (see :data:`METRIC_DOCS`)."""
    ok = batch.success
    lengths = batch.lengths.astype(np.float64)
    out: dict[str, Any] = {
        "mode": batch.mode,
        "mean_return": float(batch.returns.mean()),
        "std_return": float(batch.returns.std()),
        "success_rate": float(ok.mean()),
        "mean_time_to_goal": float(lengths[ok].mean() * batch.dt) if ok.any() else None,
        "mean_episode_length": float(lengths.mean()),
        "collisions_per_episode": float(batch.collisions.mean()),
        "control_effort": float(batch.effort.mean()),
        "control_effort_per_step": float((batch.effort / np.maximum(lengths, 1)).mean()),
    }
    for k in FINAL_KEYS:
        out[f"final_{k}"] = float(batch.final[k].mean())
    out["per_episode"] = {
        "return": [float(r) for r in batch.returns],
        "success": [bool(s) for s in ok],
        "steps": [int(n) for n in batch.lengths],
    }
    return out
