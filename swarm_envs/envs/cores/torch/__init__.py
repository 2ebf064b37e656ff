"""The torch core (``backend="torch"``): the step as one (compiled) torch function.

- :mod:`~swarm_envs.envs.cores.torch.core`: :class:`TorchSwarmNavCore`, the core;
- :mod:`~swarm_envs.envs.cores.torch.step`: the fused step and substep functions;
- :mod:`~swarm_envs.envs.cores.torch.statuses`: the agent statuses on the device.
"""

from swarm_envs.envs.cores.torch.core import TorchSwarmNavCore

__all__ = ["TorchSwarmNavCore"]
