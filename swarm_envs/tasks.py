"""The tasks of the swarm environments, and the defaults each one brings.

One environment class runs every task; ``SwarmConfig.task`` says which, and each task
has its registered Gymnasium id and PettingZoo module (:data:`TASK_IDS`):

=============  ===============================  =============================================
``task``       registered id                    what the swarm must do
=============  ===============================  =============================================
navigation     ``swarm_envs/SwarmNav-v0``       gather inside the goal radius (every agent
                                                observes the goal)
informed       ``swarm_envs/SwarmInformed-v0``  the same, when only ``informed_fraction`` of
                                                the agents observe the goal; the others see
                                                their neighbours and which of them are
                                                informed (Couzin's informed individuals)
mill           ``swarm_envs/SwarmMill-v0``      reach the goal and circle it: a mill about
                                                the goal of a self-propelled swarm
=============  ===============================  =============================================

A task's defaults (:data:`TASK_DEFAULTS`) lie under whatever the caller gives: the
registered ids, the PettingZoo modules, :func:`~swarm_envs.config.load_swarm_config` and
a YAML file with ``task:`` all apply them, so ``gym.make("swarm_envs/SwarmMill-v0")``
is the mill with its self-propelled physics, and ``physics={"alpha": 2.0}`` changes only
that value. A :class:`~swarm_envs.config.SwarmConfig` built directly takes the
dataclass defaults; :func:`task_config` builds one with the task's defaults.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

#: The tasks (``SwarmConfig.task``), the first the default.
TASKS = ("navigation", "informed", "mill")

#: The Gymnasium id of each task.
TASK_IDS = {
    "navigation": "swarm_envs/SwarmNav-v0",
    "informed": "swarm_envs/SwarmInformed-v0",
    "mill": "swarm_envs/SwarmMill-v0",
}

#: The speed (a fraction of the cruise speed ``v₀``) above which the members within the
#: arrival radius count as milling: the mill task succeeds while they circle the goal at
#: least this fast and ``success_fraction`` of the members have arrived.
MILL_SUCCESS_SPEED = 0.5

#: Each task's defaults, applied beneath the caller's values (module docstring).
TASK_DEFAULTS: dict[str, dict[str, Any]] = {
    "navigation": {},
    "informed": {"informed_fraction": 0.3},
    "mill": {
        # The navigation set with self-propulsion, as the Fig. 11 reproduction runs it:
        # v₀ = √(α/β) = 1, and the sink acts passively, so the passive swarm itself
        # falls into a (slow) mill at the goal.
        "physics": {"alpha": 0.5, "beta": 0.5},
        "goal_in_physics": True,
        "goal_distance_min": 4.0,
        "goal_distance_max": 8.0,
        "max_steps": 300,
        "reward": {"success": 0.0, "time": 0.0, "mill": 0.1},
    },
}


def _merge(base: Mapping[str, Any], top: Mapping[str, Any]) -> dict[str, Any]:
    """``top`` over ``base``; sections (mappings) are merged key by key."""
    out = dict(base)
    for key, value in top.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = _merge(out[key], value)
        else:
            out[key] = value
    return out


def with_task_defaults(data: Mapping[str, Any]) -> dict[str, Any]:
    """``data`` (config keys) over the defaults of its task (``data["task"]``, else
    navigation). An unknown task is left to the config's validation."""
    task = data.get("task", TASKS[0])
    defaults = TASK_DEFAULTS.get(task, {}) if isinstance(task, str) else {}
    return _merge(defaults, data)


def task_config(task: str, **overrides: Any) -> Any:
    """A :class:`~swarm_envs.config.SwarmConfig` for ``task`` with its defaults, then
    ``overrides`` (config keys; a partial section changes only the keys it names).

    >>> cfg = task_config("mill", n_agents=12)
    >>> cfg.task, cfg.physics.alpha, cfg.goal_in_physics, cfg.n_agents
    ('mill', 0.5, True, 12)
    """
    from swarm_envs.config import load_swarm_config

    return load_swarm_config(None, {"task": task, **overrides})


def informed_count(fraction: float, n_agents: int) -> int:
    """How many of ``n_agents`` observe the goal: ``fraction · N`` rounded to the nearest
    whole agent (halves up), at least one. A range ``[0.1, 0.3]`` of 10 agents thus
    gives 1, 2 or 3 informed agents (a quarter, a half and a quarter of the episodes).

    >>> informed_count(0.1, 10), informed_count(0.3, 10), informed_count(0.05, 10)
    (1, 3, 1)
    >>> informed_count(0.24, 10), informed_count(0.25, 10)
    (2, 3)
    """
    return max(1, min(n_agents, math.floor(fraction * n_agents + 0.5 + 1e-9)))


__all__ = [
    "MILL_SUCCESS_SPEED",
    "TASKS",
    "TASK_DEFAULTS",
    "TASK_IDS",
    "informed_count",
    "task_config",
    "with_task_defaults",
]
