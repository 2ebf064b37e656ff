"""Ray RLlib training of the PettingZoo SwarmNav env: past one machine.

Install with ``pip install -e ".[distributed]"`` (``ray[rllib,tune]``). Nothing here
imports Ray at module import time, so the package (and its docstrings) load without it;
the functions that need Ray import it when called and raise :class:`ImportError` with
the install command when it is absent.

Modules:

- :mod:`train.rllib.config`: :class:`RLlibTrainConfig`, strict YAML config
  (``configs/train/*_rllib.yaml``).
- :mod:`train.rllib.cluster`: starting a local Ray or joining a cluster (``--address``).
- :mod:`train.rllib.env`: the thin RLlib ``MultiAgentEnv`` adapter over
  ``swarm_nav_v0.parallel_env``.
- :mod:`train.rllib.train`: PPO on the new API stack, one policy shared by all agents;
  checkpoints and metadata (``swarm-train --engine rllib``).
- :mod:`train.rllib.policy`: a trained checkpoint as a policy with SB3's ``predict``,
  for ``swarm-eval``.
"""

from __future__ import annotations

#: Module id of the one policy every agent maps to.
POLICY_ID = "shared"

#: What to install when Ray is missing.
INSTALL_HINT = 'Ray is not installed; install the extra: pip install -e ".[distributed]"'

__all__ = ["INSTALL_HINT", "POLICY_ID"]
