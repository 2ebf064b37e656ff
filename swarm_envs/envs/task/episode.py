"""When an episode ends, defined once for every core.

A task terminates on success (its spec's ``terminates_on_success``): navigation, with
or without informed agents, ends once the swarm has gathered at the goal. A task with
no end state to reach, only one to hold, never terminates: the mill's ``success``
reports each step whether the swarm mills there. Every task truncates after
``max_steps`` steps (where it has not terminated).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from swarm_envs.config import SwarmConfig


def episode_end(
    task: SwarmConfig, success: np.ndarray, t: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``(terminated, truncated)`` ``(B,)`` bool from this step's ``success`` ``(B,)``
    and each swarm's step count ``t`` ``(B,)`` (``task``: the ``SwarmConfig``).

    >>> from swarm_envs.tasks import task_config
    >>> done = np.array([True, False]), np.array([5, 300])
    >>> [a.tolist() for a in episode_end(task_config("navigation", max_steps=300), *done)]
    [[True, False], [False, True]]
    >>> [a.tolist() for a in episode_end(task_config("mill"), *done)]
    [[False, False], [False, True]]
    """
    success = np.asarray(success, dtype=bool)
    late = np.asarray(t) >= task.max_steps
    if not task.task_spec.terminates_on_success:
        return np.zeros_like(success), late
    return success, late & ~success


__all__ = ["episode_end"]
