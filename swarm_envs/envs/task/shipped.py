"""The package's tasks as registry entries: navigation, informed and mill.

Each is a :class:`~swarm_envs.tasks.TaskSpec` of the shipped reward terms
(:data:`~swarm_envs.envs.task.reward.REWARD_TERMS`), the common statistics and the
shipped success rules; :mod:`swarm_envs.tasks` registers them first, in this order.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

from swarm_envs.envs.task.observation import INFORMED_FLAG
from swarm_envs.envs.task.reward import REWARD_TERMS, RewardTerm
from swarm_envs.envs.task.statistics import mill_success
from swarm_envs.tasks import MILL_SUCCESS_SPEED, TaskSpec

if TYPE_CHECKING:
    from swarm_envs.config import SwarmConfig


def _mill_needs(cfg: SwarmConfig) -> str | None:
    if cfg.dynamics != "social_potential" or cfg.physics.alpha <= 0:
        return (
            "runs on the self-propelled social potential: it needs "
            "dynamics='social_potential' and physics.alpha > 0, got "
            f"dynamics={cfg.dynamics!r}, physics.alpha={cfg.physics.alpha!r}"
        )
    return None


def _reweighted(**weights: float) -> tuple[RewardTerm, ...]:
    """:data:`REWARD_TERMS` with other default weights for the terms named."""
    return tuple(
        dataclasses.replace(t, weight=weights[t.name]) if t.name in weights else t
        for t in REWARD_TERMS
    )


NAVIGATION = TaskSpec(
    name="navigation",
    doc="gather inside the goal radius (every agent observes the goal)",
    reward_terms=REWARD_TERMS,
    env_id="swarm_envs/SwarmNav-v0",
    module="swarm_envs.swarm_nav_v0",
)

INFORMED = TaskSpec(
    name="informed",
    doc="gather inside the goal radius when only informed_fraction of each swarm "
    "observes the goal (drawn per episode); every agent observes its own informed flag "
    "and each neighbour's (Couzin's informed individuals)",
    reward_terms=REWARD_TERMS,
    features=(INFORMED_FLAG,),
    informed=True,
    defaults={"informed_fraction": 0.3},
    env_id="swarm_envs/SwarmInformed-v0",
    module="swarm_envs.swarm_informed_v0",
)

MILL = TaskSpec(
    name="mill",
    doc="reach the goal and circle it: a mill about the goal of the self-propelled "
    "social potential",
    reward_terms=_reweighted(success=0.0, time=0.0, mill=0.1),
    success=mill_success,
    success_doc="at least success_fraction of the members have arrived and those within "
    f"the arrival radius circle the goal at mill_order ≥ {MILL_SUCCESS_SPEED:g}",
    terminates_on_success=False,
    check=_mill_needs,
    defaults={
        # The navigation set with self-propulsion, as the Fig. 11 reproduction runs it:
        # v₀ = √(α/β) = 1, and the sink acts passively, so the passive swarm itself
        # falls into a (slow) mill at the goal.
        "physics": {"alpha": 0.5, "beta": 0.5},
        "goal_in_physics": True,
        "goal_distance_min": 4.0,
        "goal_distance_max": 8.0,
        "max_steps": 300,
    },
    env_id="swarm_envs/SwarmMill-v0",
    module="swarm_envs.swarm_mill_v0",
)

#: The package's tasks, the first the default.
SHIPPED_TASKS: tuple[TaskSpec, ...] = (NAVIGATION, INFORMED, MILL)

__all__ = ["INFORMED", "MILL", "NAVIGATION", "SHIPPED_TASKS"]
