"""The statistics SwarmNav reports per swarm: each one defined once, for every backend.

A :class:`Statistic` maps a :class:`Frame` (what a step measured: the state and the few
quantities that need a backend's own machinery, such as neighbour search and the pair
pass) to one value per swarm. The numpy and torch cores evaluate these very functions on
their arrays (:mod:`swarm_envs._array`); the C step writes the same quantities with its
own loops and is held to these definitions by the conformance tests. The group
statistics come from :mod:`swarm_envs.metrics` (``docs/models.md`` §2).

Adding a statistic is one entry in :data:`STATISTICS`; every core then reports it in
``info`` (the C step computes the ones it knows and leaves the others to these
definitions, evaluated on its state). A task's own statistics
(:class:`~swarm_envs.tasks.TaskSpec` ``statistics``) follow the common ones
(:func:`task_statistics`), and its success rule is the ``success`` statistic.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, NamedTuple

from swarm_envs import metrics
from swarm_envs._array import ArrayNamespace
from swarm_envs.tasks import MILL_SUCCESS_SPEED

if TYPE_CHECKING:
    from swarm_envs.config import SwarmConfig

Array = Any


class Frame(NamedTuple):
    """What one step measured, for ``B`` swarms of ``N`` agents (numpy or torch arrays).

    Attributes:
        x: positions ``(B, N, d)``.
        v: velocities ``(B, N, d)``.
        goal: goals ``(B, d)``.
        goal_distance: ``|r_g − r_i|`` per agent, ``(B, N)``.
        nearest_distance: distance to each agent's nearest other agent ``(B, N)``
            (zeros when ``N = 1``).
        close_pairs: unordered pairs closer than ``collision_radius`` ``(B,)``.
        energy: the model's energy statistic ``(B,)`` (``swarm_envs.envs.dynamics``).
        substeps: integration substeps the step took ``(B,)`` (step-size control;
            ``None``: none, as after a reset).
        members: which agents are the swarm's members ``(B, N)`` bool, the mobile ones
            (:mod:`~swarm_envs.envs.task.agent_status`); ``None``: every agent. The
            group statistics and the task count the members only; ``nearest_distance``
            is then each agent's distance to its nearest present other.
    """

    x: Array
    v: Array
    goal: Array
    goal_distance: Array
    nearest_distance: Array
    close_pairs: Array
    energy: Array
    substeps: Array | None = None
    members: Array | None = None


@dataclass(frozen=True)
class Statistic:
    """One statistic: ``value(frame, task, xp) -> (B,)``.

    ``task`` is the :class:`~swarm_envs.config.SwarmConfig`; ``wide`` statistics (counts,
    fractions, flags) are reported as float64 whatever the state's dtype.
    """

    name: str
    doc: str
    value: Callable[[Frame, SwarmConfig, ArrayNamespace], Array]
    wide: bool = False
    pairwise: bool = True
    """Whether it may read the frame's pair measures (``nearest_distance``,
    ``close_pairs``); a core that fills in statistics from its state alone skips
    computing those for the ones that do not."""


def success_count(n_agents: int, success_fraction: float) -> int:
    """Smallest count c of arrived agents with ``c/N ≥ success_fraction − 1e-9``.

    (``N + 1`` if none reaches it, which ``success_fraction ≤ 1`` rules out.)

    >>> success_count(10, 1.0), success_count(10, 0.55), success_count(3, 1 / 3)
    (10, 6, 1)
    """
    for c in range(n_agents + 1):
        if c / n_agents >= success_fraction - 1e-9:
            return c
    return n_agents + 1  # pragma: no cover - success_fraction ≤ 1 always reaches c = N


def _arrived_count(f: Frame, task: SwarmConfig, xp: ArrayNamespace) -> Array:
    arrived = f.goal_distance <= task.arrival_radius
    if f.members is not None:
        arrived = arrived & f.members
    return xp.sum(xp.astype(arrived, f.goal_distance), axis=-1)


def _members(members: Array, f: Frame, xp: ArrayNamespace) -> Array:
    """The count of the members ``members`` ``(B, N)`` per swarm, in the state's dtype."""
    return xp.sum(xp.astype(members, f.goal_distance), axis=-1)


def _member_count(f: Frame, task: SwarmConfig, xp: ArrayNamespace) -> Array | int:
    if f.members is None:
        return task.n_agents
    return _members(f.members, f, xp)


def _mean(values: Array, f: Frame, xp: ArrayNamespace) -> Array:
    """The mean of per-agent values ``(B, N)`` over the members."""
    if f.members is None:
        return xp.mean(values, axis=-1)
    return xp.sum(xp.where(f.members, values, 0.0), axis=-1) / _members(f.members, f, xp)


def _centroid_distance(f: Frame, task: SwarmConfig, xp: ArrayNamespace) -> Array:
    if f.members is None:
        centre = xp.mean_agents(f.x)
    else:
        w = xp.astype(f.members, f.x)
        centre = xp.sum_agents(f.x * w[..., None]) / xp.sum(w, axis=-1)[..., None]
    return xp.norm(centre - f.goal)


def arrival_success(f: Frame, task: SwarmConfig, xp: ArrayNamespace) -> Array:
    """1.0 where at least ``success_fraction`` of the members are within the arrival
    radius of the goal, else 0.0 (the default success rule of a task)."""
    if f.members is None:
        need = success_count(task.n_agents, task.success_fraction)
        return xp.astype(_arrived_count(f, task, xp) >= need, f.goal_distance)
    # success_count's rule, c / n ≥ success_fraction − 1e-9, for each swarm's n members
    fraction = _arrived_count(f, task, xp) / _member_count(f, task, xp)
    return xp.astype(fraction >= task.success_fraction - 1e-9, f.goal_distance)


def _goal_angular_momentum(f: Frame, task: SwarmConfig, xp: ArrayNamespace) -> Array:
    r = f.x - f.goal[:, None, :]
    return metrics.mean_cross_about_goal(r, f.v, None, f.members, xp)


def _mill_speed(f: Frame, task: SwarmConfig, xp: ArrayNamespace) -> Array:
    # metrics.tangential_speed's weights, from the distances the frame holds
    dist = f.goal_distance
    inside = (dist > 0) & (dist <= task.arrival_radius)
    weights = xp.where(inside, 1.0 / xp.where(inside, dist, 1.0), 0.0)
    return metrics.mean_cross_about_goal(f.x - f.goal[:, None, :], f.v, weights, f.members, xp)


#: ``v₀`` below this counts as this in ``mill_order`` (a ratio finite in float32).
MIN_CRUISE_SPEED = 1e-30


def mill_speed_scale(task: SwarmConfig) -> float:
    """The speed ``mill_order`` divides by: the cruise speed ``v₀``, at least
    :data:`MIN_CRUISE_SPEED`; 0 without self-propulsion (then ``mill_order`` is 0)."""
    v0 = task.physics.cruise_speed
    return max(v0, MIN_CRUISE_SPEED) if v0 > 0 else 0.0


def _mill_order(f: Frame, task: SwarmConfig, xp: ArrayNamespace) -> Array:
    """``min(mill_speed / v₀, 1)``; 0 without self-propulsion (no ``v₀``)."""
    v0 = mill_speed_scale(task)
    if v0 <= 0:
        return xp.zeros(f.energy.shape, like=f.energy)
    return xp.clip(_mill_speed(f, task, xp) / v0, None, 1.0)


def mill_success(f: Frame, task: SwarmConfig, xp: ArrayNamespace) -> Array:
    """The mill task's success: :func:`arrival_success`, while the members within the
    arrival radius also circle the goal at ``mill_order ≥ MILL_SUCCESS_SPEED``."""
    arrived = arrival_success(f, task, xp)
    return arrived * xp.astype(_mill_order(f, task, xp) >= MILL_SUCCESS_SPEED, arrived)


def _task_success(f: Frame, task: SwarmConfig, xp: ArrayNamespace) -> Array:
    """The success rule of ``task``'s spec; :func:`arrival_success` where it has none
    (or ``task`` is not a config with a task)."""
    spec = getattr(task, "task_spec", None)
    rule = spec.success if spec is not None else None
    return (rule or arrival_success)(f, task, xp)


def _substeps(f: Frame, task: SwarmConfig, xp: ArrayNamespace) -> Array:
    if f.substeps is None:
        return xp.zeros(f.energy.shape, like=f.energy)
    return f.substeps


#: Every statistic in ``info``, in this order (``STAT_KEYS``).
STATISTICS: tuple[Statistic, ...] = (
    Statistic(
        "polarization",
        "unit-heading polarization |Σ v̂_i|/N (metrics.polarization)",
        lambda f, task, xp: metrics.polarization(f.v, f.members),
    ),
    Statistic(
        "angular_momentum",
        "unit-heading angular momentum |Σ r̂_ic × v̂_i|/N (metrics.angular_momentum)",
        lambda f, task, xp: metrics.angular_momentum(f.x, f.v, f.members),
    ),
    Statistic(
        "expanse",
        "mean distance to the centroid (metrics.expanse)",
        lambda f, task, xp: metrics.expanse(f.x, f.members),
    ),
    Statistic(
        "nearest_neighbor_distance",
        "mean distance to the nearest other agent (0 for N = 1)",
        lambda f, task, xp: _mean(f.nearest_distance, f, xp),
    ),
    Statistic("energy", "the model's energy", lambda f, task, xp: f.energy),
    Statistic(
        "fraction_arrived",
        "fraction of the members within the arrival radius of the goal "
        "(SwarmConfig.arrival_radius)",
        lambda f, task, xp: _arrived_count(f, task, xp) / _member_count(f, task, xp),
        wide=True,
    ),
    Statistic(
        "collisions",
        "pairs closer than collision_radius (this step)",
        lambda f, task, xp: f.close_pairs,
        wide=True,
    ),
    Statistic("centroid_distance", "|r_c − r_g|", _centroid_distance),
    Statistic(
        "mean_goal_distance",
        "mean agent-to-goal distance",
        lambda f, task, xp: _mean(f.goal_distance, f, xp),
    ),
    Statistic(
        "goal_angular_momentum",
        "true angular momentum per member about the goal |Σ (r_i − r_g) × v_i|/N "
        "(metrics.goal_angular_momentum)",
        _goal_angular_momentum,
        pairwise=False,
    ),
    Statistic(
        "mill_speed",
        "tangential speed about the goal |Σ r̂_ig × v_i|/N, members within the arrival "
        "radius (metrics.tangential_speed)",
        _mill_speed,
        pairwise=False,
    ),
    Statistic(
        "mill_order",
        "mill_speed / v₀ (the cruise speed of self-propulsion), at most 1; 0 without "
        "self-propulsion",
        _mill_order,
        pairwise=False,
    ),
    Statistic(
        "success",
        "1 when the task succeeds: by default when at least success_fraction of the "
        "members have arrived (each task's rule: its spec's success_doc)",
        _task_success,
        wide=True,
        pairwise=False,
    ),
    Statistic(
        "substeps",
        "integration substeps this step took (step-size control, docs/models.md §7)",
        _substeps,
        wide=True,
    ),
    Statistic(
        "unstable",
        "1 when the step went unstable and the episode was truncated (on_unstable)",
        lambda f, task, xp: xp.zeros(f.energy.shape, like=f.energy),
        wide=True,
    ),
)

#: The common statistics' names, in the order of :data:`STATISTICS`.
STAT_KEYS: tuple[str, ...] = tuple(s.name for s in STATISTICS)


def task_statistics(task: SwarmConfig | None) -> tuple[Statistic, ...]:
    """Every statistic a config reports: :data:`STATISTICS`, then its task's own
    (``None``: :data:`STATISTICS`)."""
    spec = getattr(task, "task_spec", None)
    return STATISTICS if spec is None or not spec.statistics else STATISTICS + spec.statistics


def stat_keys(task: SwarmConfig | None) -> tuple[str, ...]:
    """The names of :func:`task_statistics`, in order (``STAT_KEYS`` for the package's
    tasks)."""
    return tuple(s.name for s in task_statistics(task))


def statistics(frame: Frame, task: SwarmConfig, xp: ArrayNamespace) -> dict[str, Array]:
    """Every statistic of ``task`` (:func:`task_statistics`) for ``frame``, as
    ``{name: (B,)}``."""
    return {s.name: s.value(frame, task, xp) for s in task_statistics(task)}
