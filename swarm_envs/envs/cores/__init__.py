"""The cores: how a step of ``B`` swarms is computed, one package or module per backend.

Every core implements :class:`~swarm_envs.envs.protocol.Core` under the one task layer
(:mod:`swarm_envs.envs.task.layer`) and executes the shared definitions;
:func:`~swarm_envs.envs.backends.make_core` picks one (``SwarmConfig.backend``):

- :mod:`~swarm_envs.envs.cores.numpy`: ``"numpy"``, dense ``(B, N, N)`` pair arrays,
  every model; the reference;
- :mod:`~swarm_envs.envs.cores.cutoff`: ``"cutoff"``, a cut-off radius and an ``O(N)``
  cell list, for large swarms;
- :mod:`~swarm_envs.envs.cores.torch`: ``"torch"``, the step as one compiled torch
  function, CPU or CUDA;
- :mod:`~swarm_envs.envs.cores.native`: ``"native"``, the step in C.

Nothing is imported here: each core loads its own dependencies (torch, the C compiler)
when its package is imported.
"""
