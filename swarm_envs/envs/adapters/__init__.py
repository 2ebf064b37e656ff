"""The APIs over the cores: PettingZoo, Gymnasium and the batched SB3 VecEnv.

- :mod:`~swarm_envs.envs.adapters.swarm_nav`: :class:`SwarmNavParallelEnv` (PettingZoo)
  and :class:`SwarmNavEnv` (Gymnasium, one central controller), one swarm each, and the
  env docstring;
- :mod:`~swarm_envs.envs.adapters.swarm_view`: what both share (state accessors,
  rendering);
- :mod:`~swarm_envs.envs.adapters.gym_vector`: :class:`SwarmNavVectorEnv`, Gymnasium's
  ``VectorEnv`` over one batched core;
- :mod:`~swarm_envs.envs.adapters.vec_env`: :class:`SwarmNavVecEnv`, the SB3 ``VecEnv``
  with one slot per agent, and its infos (:mod:`~swarm_envs.envs.adapters.vec_infos`);
- :mod:`~swarm_envs.envs.adapters.inputs`: the one input rule of every API.

Nothing is imported here: the SB3 VecEnv needs SB3 (and torch), loaded only by its own
module.
"""
