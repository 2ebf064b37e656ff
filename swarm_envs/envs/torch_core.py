"""``swarm_envs.envs.torch_core.TorchSwarmNavCore``: the torch core, an import path that
stays.

The core is defined in :mod:`swarm_envs.envs.cores.torch.core`.
"""

from swarm_envs.envs.cores.torch.core import TorchSwarmNavCore

__all__ = ["TorchSwarmNavCore"]
