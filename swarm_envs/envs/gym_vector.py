"""``swarm_envs.envs.gym_vector.SwarmNavVectorEnv``: Gymnasium's vector env, an import
path that stays (environment specs saved with it as their ``vector_entry_point`` load).

The env is defined in :mod:`swarm_envs.envs.adapters.gym_vector`.
"""

from swarm_envs.envs.adapters.gym_vector import SwarmNavVectorEnv

__all__ = ["SwarmNavVectorEnv"]
