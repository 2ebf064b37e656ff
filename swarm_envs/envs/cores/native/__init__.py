"""The SwarmNav step in C: an execution strategy for the shared definitions.

- :mod:`~swarm_envs.envs.cores.native.contract`: the parameter struct and output columns,
  generated from the config dataclasses, and what a config needs of the kernel;
- :mod:`~swarm_envs.envs.cores.native.variants`: the variants compiled at install, and
  which one a CPU runs;
- :mod:`~swarm_envs.envs.cores.native.build`: loading the kernel (a prebuilt variant,
  else compiled at first use into a checked cache);
- :mod:`~swarm_envs.envs.cores.native.core`: :class:`NativeSwarmNavCore`, the core that runs it.
"""

from swarm_envs.envs.cores.native.build import NATIVE_ENV, native_support, resolve_native
from swarm_envs.envs.cores.native.core import NativeSwarmNavCore

__all__ = ["NATIVE_ENV", "NativeSwarmNavCore", "native_support", "resolve_native"]
