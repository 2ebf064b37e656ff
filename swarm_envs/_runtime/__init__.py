"""How the package's functions are executed, apart from what they compute.

- :mod:`~swarm_envs._runtime.torch_compile`: ``torch.compile`` with a fallback, CUDA
  graphs;
- :mod:`~swarm_envs._runtime.allocator`: the optional glibc heap tuning
  (:func:`swarm_envs.tune_allocator`);
- :mod:`~swarm_envs._runtime.fork`: what a forked child of a process that ran OpenMP
  code needs (one OpenMP thread, the cut-off core's pair pass in numpy).
"""
