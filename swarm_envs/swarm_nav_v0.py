"""PettingZoo-style module for SwarmNav v0: ``parallel_env``, ``env``, ``raw_env``, ``vec_env``.

>>> from swarm_envs import swarm_nav_v0
>>> par = swarm_nav_v0.parallel_env(n_agents=4)
>>> obs, infos = par.reset(seed=0)
>>> sorted(obs)[:2], obs["agent_0"].dtype
(['agent_0', 'agent_1'], dtype('float32'))
"""

from __future__ import annotations

from typing import Any

from pettingzoo.utils import parallel_to_aec, wrappers
from pettingzoo.utils.env import AECEnv

from swarm_envs.envs.swarm_nav import SwarmNavParallelEnv


def parallel_env(**kwargs: Any) -> SwarmNavParallelEnv:
    """The PettingZoo ``ParallelEnv`` (the source of truth); kwargs as in the env docstring."""
    return SwarmNavParallelEnv(**kwargs)


def raw_env(**kwargs: Any) -> AECEnv:
    """The AEC env from :func:`parallel_env` via ``parallel_to_aec``, without wrappers."""
    return parallel_to_aec(parallel_env(**kwargs))


def env(**kwargs: Any) -> AECEnv:
    """The AEC env with PettingZoo's order-enforcing wrapper."""
    return wrappers.OrderEnforcingWrapper(raw_env(**kwargs))


def vec_env(n_swarms: int = 1, **kwargs: Any):
    """A batched SB3 ``VecEnv`` with ``n_swarms × n_agents`` slots (one shared policy).

    See :class:`swarm_envs.envs.vec_env.SwarmNavVecEnv`. Imported lazily (it needs SB3,
    and so torch).
    """
    from swarm_envs.envs.vec_env import SwarmNavVecEnv

    return SwarmNavVecEnv(n_swarms, **kwargs)


__all__ = ["env", "parallel_env", "raw_env", "vec_env"]
