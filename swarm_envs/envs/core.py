"""``swarm_envs.envs.core.SwarmNavCore``: the numpy core, an import path that stays.

The core is defined in :mod:`swarm_envs.envs.cores.numpy`.
"""

from swarm_envs.envs.cores.numpy import SwarmNavCore

__all__ = ["SwarmNavCore"]
