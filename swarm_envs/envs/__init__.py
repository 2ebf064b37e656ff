"""Environment adapters over the batched SwarmNav cores (PettingZoo, Gymnasium, SB3 VecEnv).

The cores (:mod:`~swarm_envs.envs.backends`) implement :class:`Core`; the task they all
execute is defined once in :mod:`swarm_envs.envs.task`.
"""

from swarm_envs.envs.core import SwarmNavCore
from swarm_envs.envs.protocol import Core
from swarm_envs.envs.swarm_nav import SwarmNavEnv, SwarmNavParallelEnv
from swarm_envs.envs.task import OBS_BOUND, STAT_KEYS, observation_size

__all__ = [
    "OBS_BOUND",
    "STAT_KEYS",
    "Core",
    "SwarmNavCore",
    "SwarmNavEnv",
    "SwarmNavParallelEnv",
    "observation_size",
]
