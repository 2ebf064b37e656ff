"""PettingZoo module for SwarmInformed v0: ``parallel_env``, ``env``, ``raw_env``, ``vec_env``.

Navigation when only ``informed_fraction`` of the agents observe the goal (0.3 by
default); the others see their neighbours and which of them are informed.
The env is the SwarmNav env with ``task="informed"`` and that task's defaults
(:mod:`swarm_envs.tasks`); every keyword of ``swarm_nav_v0`` is accepted here too.

>>> from swarm_envs import swarm_informed_v0
>>> par = swarm_informed_v0.parallel_env(n_agents=4)
>>> par.cfg.task
'informed'
"""

from __future__ import annotations

from typing import Any

from pettingzoo.utils.env import AECEnv

from swarm_envs import swarm_nav_v0
from swarm_envs.envs.swarm_nav import SwarmNavParallelEnv

TASK = "informed"


def parallel_env(**kwargs: Any) -> SwarmNavParallelEnv:
    """The PettingZoo ``ParallelEnv`` of the informed task (kwargs as ``swarm_nav_v0``)."""
    return swarm_nav_v0.parallel_env(**swarm_nav_v0.for_task(TASK, __name__, kwargs))


def raw_env(**kwargs: Any) -> AECEnv:
    """The AEC env of :func:`parallel_env` (``swarm_nav_v0.raw_env``)."""
    return swarm_nav_v0.raw_env(**swarm_nav_v0.for_task(TASK, __name__, kwargs))


def env(**kwargs: Any) -> AECEnv:
    """The AEC env with PettingZoo's order-enforcing wrapper."""
    return swarm_nav_v0.env(**swarm_nav_v0.for_task(TASK, __name__, kwargs))


def vec_env(n_swarms: int = 1, **kwargs: Any):
    """A batched SB3 ``VecEnv`` with ``n_swarms × n_agents`` slots (one shared policy)."""
    return swarm_nav_v0.vec_env(n_swarms, **swarm_nav_v0.for_task(TASK, __name__, kwargs))


__all__ = ["TASK", "env", "parallel_env", "raw_env", "vec_env"]
