"""Which policies fit the env, and how: the ``shared`` / ``central`` layouts; SB3 loading.

A policy without ``observation_space`` / ``action_space`` (a plain object with
``predict``) is taken to be per-agent (``"shared"``), as the :mod:`agents` controllers
are. Stable-Baselines3 is imported by :func:`load_sb3_model` only.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from swarm_envs.config import SwarmConfig
from swarm_envs.envs.core import observation_size

__all__ = ["SpaceMismatchError", "load_sb3_model", "policy_mode"]


class SpaceMismatchError(ValueError):
    """A policy's observation/action spaces do not fit the environment."""


def policy_mode(policy: Any, cfg: SwarmConfig) -> str:
    """``"shared"`` or ``"central"``: how ``policy`` sees the swarm of ``cfg``.

    Read from ``policy.observation_space`` and ``policy.action_space`` (SB3 models and
    the :mod:`agents` controllers have them); a policy without them is ``"shared"``.

    Raises:
        SpaceMismatchError: the spaces fit neither the per-agent layout (``Box(-10, 10,
            (obs_dim,))`` → ``Box(-1, 1, (d,))``) nor the flat one (``(N·obs_dim,)`` →
            ``(N·d,)``).
    """
    obs_space = getattr(policy, "observation_space", None)
    act_space = getattr(policy, "action_space", None)
    if obs_space is None and act_space is None:
        return "shared"
    n, d, k = cfg.n_agents, cfg.dim, observation_size(cfg)
    layouts = {"shared": ((k,), (d,)), "central": ((n * k,), (n * d,))}
    obs_shape = getattr(obs_space, "shape", None)
    act_shape = getattr(act_space, "shape", None)
    expected = (
        f"the env's per-agent spaces (observation ({k},), action ({d},)) or its flat "
        f"spaces (observation ({n * k},), action ({n * d},)), both with actions in [-1, 1]"
    )
    found = (
        f"observation space {obs_space}, action space {act_space}"
        if obs_space is not None
        else f"action space {act_space}"
    )
    for mode, (o, a) in layouts.items():
        if tuple(obs_shape or ()) == o and tuple(act_shape or ()) == a:
            low = np.asarray(getattr(act_space, "low", -1.0), dtype=np.float64)
            high = np.asarray(getattr(act_space, "high", 1.0), dtype=np.float64)
            if not (np.allclose(low, -1.0) and np.allclose(high, 1.0)):
                break
            return mode
    raise SpaceMismatchError(f"{found}; expected {expected}")


def _detect_sb3_algorithm(data: Mapping[str, Any]) -> str:
    """Guess the SB3 algorithm of a saved model from its ``data`` JSON."""
    module = str(data.get("policy_class", {}).get("__module__", ""))
    for name in ("sac", "td3", "dqn", "ddpg"):
        if f".{name}." in module:
            return name.upper()
    return "PPO" if "clip_range" in data else "A2C"


def load_sb3_model(path: str | Path, device: str = "cpu") -> Any:
    """Load a Stable-Baselines3 model zip, detecting its algorithm.

    The algorithm is read from the zip's ``data`` JSON (the policy class's module and
    algorithm-specific keys), then PPO, SAC, A2C, TD3 and DQN are tried in turn.

    Raises:
        FileNotFoundError: no file at ``path``.
        ValueError: the file is not a model zip any of those algorithms can load.
    """
    import zipfile

    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"model file not found: {p}")
    try:
        with zipfile.ZipFile(p) as zf:
            data = json.loads(zf.read("data"))
    except (zipfile.BadZipFile, KeyError, json.JSONDecodeError, UnicodeDecodeError) as err:
        raise ValueError(f"{p} is not a Stable-Baselines3 model zip ({err})") from None
    import stable_baselines3 as sb3

    first = _detect_sb3_algorithm(data)
    order = [first] + [a for a in ("PPO", "SAC", "A2C", "TD3", "DQN") if a != first]
    errors = []
    for name in order:
        cls = getattr(sb3, name)
        try:
            return cls.load(p, device=device)
        except Exception as err:  # wrong algorithm: try the next one
            errors.append(f"{name}: {type(err).__name__}: {err}")
    raise ValueError(f"could not load {p} with any SB3 algorithm: " + "; ".join(errors))
