"""Environment adapters over the batched SwarmNav core (PettingZoo, Gymnasium, SB3 VecEnv)."""

from swarm_envs.envs.core import OBS_BOUND, STAT_KEYS, SwarmNavCore, observation_size
from swarm_envs.envs.swarm_nav import SwarmNavEnv, SwarmNavParallelEnv

__all__ = [
    "OBS_BOUND",
    "STAT_KEYS",
    "SwarmNavCore",
    "SwarmNavEnv",
    "SwarmNavParallelEnv",
    "observation_size",
]
