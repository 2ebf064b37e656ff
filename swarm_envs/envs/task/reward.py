"""The cooperative SwarmNav reward: each term defined once, for every backend.

``r_t = Σ_terms sign · weight · value``, every agent receiving its swarm's reward, over
the terms of the config's task (:class:`~swarm_envs.tasks.TaskSpec` ``reward_terms``)
with the weights of the config's ``reward`` section
(:class:`~swarm_envs.config.RewardWeights`: one field per shipped term, same name, and
``terms`` for a registered task's own). The shipped terms are :data:`REWARD_TERMS`;
each term's ``doc`` says what its value is (the env docstring's reward table is made
from them).

A term reads :class:`RewardInputs`: this step's statistics, the previous step's, the
episode start's (:mod:`swarm_envs.envs.task.statistics`), and the actions' effort. Every
core, the C step included, combines its measured statistics through :func:`reward`.

Adding a term to a task is one :class:`RewardTerm` in its spec; its weight is then a key
of ``reward`` (a shipped term also has its field in ``RewardWeights``: a test checks that
the two lists match).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, NamedTuple

from swarm_envs._array import ArrayNamespace
from swarm_envs.config import RewardWeights
from swarm_envs.tasks import reward_term

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
    """One reward term: ``sign · weight · value(inputs)``.

    Attributes:
        name: the key of its weight in the config's ``reward`` section.
        sign: +1 (a gain) or −1 (a cost); the weights are non-negative.
        doc: what ``value`` is, one phrase (the env docstring's reward table).
        value: ``value(inputs) -> (B,)`` (or a scalar), over ``inputs.xp``.
        weight: the default weight (a task's defaults; ``dataclasses.replace`` gives a
            term another default for another task).
    """

    name: str
    sign: float
    doc: str
    value: Callable[[RewardInputs], Array]
    weight: float = 0.0


def _progress(r: RewardInputs) -> Array:
    start = r.xp.clip(r.start["mean_goal_distance"], MIN_START_DISTANCE, None)
    return (r.prev["mean_goal_distance"] - r.stats["mean_goal_distance"]) / start


#: The shipped terms' default weights (navigation's): ``RewardWeights``' defaults.
_DEFAULT = RewardWeights()

#: The shipped reward terms; their names are the fields of ``RewardWeights``.
REWARD_TERMS: tuple[RewardTerm, ...] = (
    RewardTerm(
        "progress",
        1.0,
        "(D_{t−1} − D_t)/D_0: the reduction of the mean agent-to-goal distance D, over its "
        "start value",
        _progress,
        _DEFAULT.progress,
    ),
    RewardTerm(
        "arrival",
        1.0,
        "A_t − A_{t−1}: the newly arrived fraction A of the agents (within the arrival radius)",
        lambda r: r.stats["fraction_arrived"] - r.prev["fraction_arrived"],
        _DEFAULT.arrival,
    ),
    RewardTerm("success", 1.0, "1 on success", lambda r: r.stats["success"], _DEFAULT.success),
    RewardTerm(
        "collision",
        -1.0,
        "C_t/N: the pairs closer than collision_radius, over N",
        lambda r: r.stats["collisions"] / r.n_agents,
        _DEFAULT.collision,
    ),
    RewardTerm(
        "effort",
        -1.0,
        "Σ_i ‖a_i‖²/N: the clipped actions' mean square",
        lambda r: r.effort / r.n_agents,
        _DEFAULT.effort,
    ),
    RewardTerm("time", -1.0, "1 per step", lambda r: 1.0, _DEFAULT.time),
    RewardTerm(
        "mill",
        1.0,
        "M_t: mill_order, the members' tangential speed about the goal (those within the "
        "arrival radius) over v₀, at most 1",
        lambda r: r.stats["mill_order"],
        _DEFAULT.mill,
    ),
)


def reward(weights: RewardWeights, inputs: RewardInputs) -> Array:
    """``Σ sign · weight · value`` over the weighted terms (terms of weight 0 skipped):
    :data:`REWARD_TERMS` by the fields of ``weights``, then a registered task's own
    terms by ``weights.terms`` (:func:`~swarm_envs.tasks.reward_term`).

    ``weights`` is the config's ``reward`` (validated against its task: a term the task
    does not have weighs 0). The result has the shape and array type of the
    statistics; the time term alone gives a float broadcast.
    """
    total: Array = 0.0 * inputs.stats["success"]
    for term in REWARD_TERMS:
        w = getattr(weights, term.name)
        if w != 0:
            total = total + (term.sign * w) * term.value(inputs)
    for name, w in weights.terms.items():
        if w != 0:
            term = reward_term(name)
            total = total + (term.sign * w) * term.value(inputs)
    return total
