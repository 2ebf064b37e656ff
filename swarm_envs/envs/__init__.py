"""The SwarmNav environments: the APIs, the cores beneath them and the task they execute.

- :mod:`~swarm_envs.envs.adapters`: the PettingZoo, Gymnasium and SB3 VecEnv APIs, each
  written against :class:`Core` only;
- :mod:`~swarm_envs.envs.backends`: which core runs a config (``make_core``), with
  :mod:`~swarm_envs.envs.perturbed` around it where agents fail, join or are absent;
- :mod:`~swarm_envs.envs.cores`: the cores, one per backend (numpy, cut-off, torch; the
  C step in :mod:`swarm_envs.envs.cores.native`), each implementing :class:`Core`
  (:mod:`~swarm_envs.envs.protocol`);
- :mod:`~swarm_envs.envs.task`: the task every core executes, defined once, and the task
  layer above the cores;
- what the cores share: :mod:`~swarm_envs.envs.common` (input checks, starts, the
  unstable guard's bounds), :mod:`~swarm_envs.envs.dynamics` (each model's physics on
  the batched state), :mod:`~swarm_envs.envs.step_control` (a config's predictable
  substeps) and :mod:`~swarm_envs.envs.stiffness` (the stiff-swarm warning).
"""

from swarm_envs.envs.adapters.swarm_nav import SwarmNavEnv, SwarmNavParallelEnv
from swarm_envs.envs.cores.numpy import SwarmNavCore
from swarm_envs.envs.protocol import Core
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
