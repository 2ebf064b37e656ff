"""``swarm_envs.envs.swarm_nav``: the single-swarm envs, an import path that stays.

:class:`SwarmNavParallelEnv` (PettingZoo) and :class:`SwarmNavEnv` (Gymnasium) are
defined in :mod:`swarm_envs.envs.adapters.swarm_nav`.
"""

from swarm_envs.envs.adapters.swarm_nav import SwarmNavEnv, SwarmNavParallelEnv

__all__ = ["SwarmNavEnv", "SwarmNavParallelEnv"]
