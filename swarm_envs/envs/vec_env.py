"""``swarm_envs.envs.vec_env``: the batched SB3 VecEnv, an import path that stays.

:class:`SwarmNavVecEnv` and its :class:`SlotEpisodesWarning` are defined in
:mod:`swarm_envs.envs.adapters.vec_env`.
"""

from swarm_envs.envs.adapters.vec_env import SlotEpisodesWarning, SwarmNavVecEnv

__all__ = ["SlotEpisodesWarning", "SwarmNavVecEnv"]
