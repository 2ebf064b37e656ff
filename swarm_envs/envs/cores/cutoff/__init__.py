"""The cut-off core (``backend="cutoff"``): large swarms in ``O(N)`` per step.

- :mod:`~swarm_envs.envs.cores.cutoff.core`: :class:`CutoffSwarmNavCore`, the core, and
  its selection rule and defaults;
- :mod:`~swarm_envs.envs.cores.cutoff.neighbors`: the k nearest neighbours, on demand;
- :mod:`~swarm_envs.envs.cores.cutoff.masks`: the agent statuses' masks in its physics.
"""

from swarm_envs.envs.cores.cutoff.core import CutoffSwarmNavCore

__all__ = ["CutoffSwarmNavCore"]
