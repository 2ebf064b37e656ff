"""BenchMARL and TorchRL over the batched core: MAPPO, IPPO, MASAC, ... on the swarm tasks.

Install with ``pip install -e ".[benchmarl]"`` (BenchMARL with the TorchRL and
TensorDict it supports). Nothing here imports TorchRL or BenchMARL at module import
time, so the package (and its docstrings) load without them; the names below import
them when first used and raise :class:`ImportError` with the install command when they
are absent.

- :class:`SwarmTorchRLEnv` (:mod:`train.benchmarl.torchrl_env`): a TorchRL ``EnvBase``
  with ``batch_size=[B]`` over one batched core (B swarms × N agents in one step), in
  TorchRL's multi-agent layout: the group ``"agents"`` holds ``observation``,
  ``action`` and ``reward`` of every agent; ``done``, ``terminated`` and ``truncated``
  are per swarm; ``state`` (optional) is every observation of the swarm.
- :class:`SwarmTask` (:mod:`train.benchmarl.task`): the BenchMARL task enum,
  ``SWARM_NAV``, ``SWARM_INFORMED`` and ``SWARM_MILL``; ``SwarmTask.SWARM_NAV.get_task()``
  is the task with its defaults, ``get_task(config={"n_agents": 8})`` with keywords of
  the env.
"""

from __future__ import annotations

from typing import Any

#: What to install when TorchRL or BenchMARL is missing.
INSTALL_HINT = (
    'BenchMARL/TorchRL is not installed; install the extra: pip install -e ".[benchmarl]"'
)

_LAZY = {
    "SwarmTorchRLEnv": "train.benchmarl.torchrl_env",
    "SwarmTask": "train.benchmarl.task",
    "SwarmTaskClass": "train.benchmarl.task",
}

__all__ = ["INSTALL_HINT", "SwarmTask", "SwarmTaskClass", "SwarmTorchRLEnv"]


def __getattr__(name: str) -> Any:
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    import importlib

    return getattr(importlib.import_module(_LAZY[name]), name)
