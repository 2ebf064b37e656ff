"""The cooperative SwarmNav reward: each term defined once, for every backend.

``r_t = Σ_terms sign · weight · value``, every agent receiving its swarm's reward, with
the weights of :class:`~swarm_envs.config.RewardWeights` (one field per term, same
name) and the terms of :data:`REWARD_TERMS`:

==============  ====  ======================================================
term            sign  value
==============  ====  ======================================================
``progress``    \\+    ``(D_{t−1} − D_t) / D_0``: the mean agent-to-goal
                      distance's reduction, normalised by its start value
``arrival``     \\+    ``A_t − A_{t−1}``: the newly arrived fraction of agents
``success``     \\+    1 on the step that succeeds
``collision``   −     colliding pairs / N
``effort``      −     ``Σ_i |a_i|² / N`` (clipped actions, in ``[0, d]``)
``time``        −     1 per step, so that arriving earlier pays
``mill``        \\+    ``mill_order``: the members' tangential speed about the
                      goal (those within the arrival radius counted) over the
                      cruise speed ``v₀``, at most 1
==============  ====  ======================================================

A term reads :class:`RewardInputs`: this step's statistics, the previous step's, the
episode start's (:mod:`swarm_envs.envs.task.statistics`), and the actions' effort. Every
core, the C step included, combines its measured statistics through :func:`reward`.

Adding a term is one :class:`RewardTerm` here and its weight field in
``RewardWeights`` (a test checks that the two lists match).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, NamedTuple

from swarm_envs._array import ArrayNamespace

Array = Any

#: A start distance below this is taken as this (a swarm starting on the goal).
MIN_START_DISTANCE = 1e-6


class RewardInputs(NamedTuple):
    """What the reward terms read, per swarm (``(B,)`` arrays, numpy or torch).

    Attributes:
        stats: this step's statistics (``STAT_KEYS``).
        prev: the previous step's statistics (after a reset, the start's).
        start: the statistics at the episode's start.
        effort: ``Σ_i |a_i|²`` of this step's clipped actions.
        n_agents: N.
        xp: the arrays' namespace (:mod:`swarm_envs._array`).
    """

    stats: Mapping[str, Array]
    prev: Mapping[str, Array]
    start: Mapping[str, Array]
    effort: Array
    n_agents: int
    xp: ArrayNamespace


@dataclass(frozen=True)
class RewardTerm:
    """One reward term: ``sign · weight · value(inputs)``."""

    name: str
    sign: float
    doc: str
    value: Callable[[RewardInputs], Array]


def _progress(r: RewardInputs) -> Array:
    start = r.xp.clip(r.start["mean_goal_distance"], MIN_START_DISTANCE, None)
    return (r.prev["mean_goal_distance"] - r.stats["mean_goal_distance"]) / start


#: The reward's terms; their names are the fields of ``RewardWeights``.
REWARD_TERMS: tuple[RewardTerm, ...] = (
    RewardTerm("progress", 1.0, "reduction of the mean goal distance / its start", _progress),
    RewardTerm(
        "arrival",
        1.0,
        "newly arrived fraction of agents",
        lambda r: r.stats["fraction_arrived"] - r.prev["fraction_arrived"],
    ),
    RewardTerm("success", 1.0, "1 on success", lambda r: r.stats["success"]),
    RewardTerm(
        "collision", -1.0, "colliding pairs / N", lambda r: r.stats["collisions"] / r.n_agents
    ),
    RewardTerm("effort", -1.0, "Σ|a_i|² / N", lambda r: r.effort / r.n_agents),
    RewardTerm("time", -1.0, "1 per step", lambda r: 1.0),
    RewardTerm(
        "mill",
        1.0,
        "mill_order: tangential speed about the goal / v₀, at most 1",
        lambda r: r.stats["mill_order"],
    ),
)


def reward(weights: Any, inputs: RewardInputs) -> Array:
    """``Σ sign · weight · value`` over :data:`REWARD_TERMS` (terms of weight 0 skipped).

    ``weights`` is a :class:`~swarm_envs.config.RewardWeights`. The result has the shape
    and array type of the statistics; the time term alone gives a float broadcast.
    """
    total: Array = 0.0 * inputs.stats["success"]
    for term in REWARD_TERMS:
        w = getattr(weights, term.name)
        if w != 0:
            total = total + (term.sign * w) * term.value(inputs)
    return total
