"""``swarm_envs.envs.native``: the C step's public names, an import path that stays.

The C step is defined in :mod:`swarm_envs.envs.cores.native`.
"""

from swarm_envs.envs.cores.native import (
    NATIVE_ENV,
    NativeSwarmNavCore,
    native_support,
    resolve_native,
)

__all__ = ["NATIVE_ENV", "NativeSwarmNavCore", "native_support", "resolve_native"]
