"""Who observes the goal in the informed task (``task="informed"``), drawn per episode.

Each swarm's informed agents are ``f·N`` of them, rounded (at least one;
:func:`~swarm_envs.tasks.informed_count`), chosen uniformly, with ``f`` the config's
``informed_fraction`` or, for a ``[low, high]`` range, drawn uniformly from it. An
agent that is not informed sees zeros for the goal offset; every agent sees its own
flag and its neighbours' (:mod:`~swarm_envs.envs.task.observation`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from swarm_envs.tasks import informed_count

if TYPE_CHECKING:
    from swarm_envs.config import SwarmConfig


def draw_informed(task: SwarmConfig, rng: np.random.Generator, n_swarms: int) -> np.ndarray:
    """Which agents of ``n_swarms`` new swarms are informed, ``(n, N)`` bool.

    Per swarm, in this order: the fraction (only for a range), then one permutation of
    the agents, whose first :func:`~swarm_envs.tasks.informed_count` are informed.

    >>> from swarm_envs.tasks import task_config
    >>> cfg = task_config("informed", informed_fraction=0.3)
    >>> told = draw_informed(cfg, np.random.default_rng(0), 2)
    >>> told.shape, told.sum(axis=1).tolist()
    ((2, 10), [3, 3])
    """
    n_agents = task.n_agents
    fraction = task.informed_fraction
    out = np.zeros((n_swarms, n_agents), dtype=bool)
    for b in range(n_swarms):
        f = float(rng.uniform(*fraction)) if isinstance(fraction, tuple) else fraction
        out[b, rng.permutation(n_agents)[: informed_count(f, n_agents)]] = True
    return out


__all__ = ["draw_informed"]
