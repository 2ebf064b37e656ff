"""The interface every swarm_envs policy shares: Stable-Baselines3's ``predict``.

An analytic controller and a trained SB3 model are used the same way::

    action, state = policy.predict(obs, state=None, episode_start=None, deterministic=True)

so that evaluation (:mod:`train.evaluate`) treats them alike. :class:`Controller` adds
what the analytic controllers need on top of that protocol:

- construction from any of the package's environments (the Gymnasium env, possibly
  wrapped; the PettingZoo parallel or AEC env; the SB3 ``VecEnv``, possibly wrapped; the
  batched core) or from a :class:`~swarm_envs.config.SwarmConfig` directly
  (:meth:`Controller.from_config`); the controller reads ``dim``, ``n_agents``,
  ``u_max``, the observation scales and the physics parameters from that config;
- the per-agent spaces, as attributes ``observation_space`` (``Box(-10, 10,
  (obs_dim,))``) and ``action_space`` (``Box(-1, 1, (d,))``), as an SB3 model trained
  with one slot per agent has them;
- shape handling: the last axis of ``obs`` is either one agent's observation
  (``obs_dim`` → an action of ``d``) or all N agents' observations concatenated
  agent-major, as the Gymnasium env returns them (``N·obs_dim`` → ``N·d``); any leading
  batch axes are kept. A PettingZoo observation dict ``{agent: obs}`` gives an action
  dict. Any other size raises :class:`ValueError`.

Subclasses implement :meth:`Controller._actions` on a ``(n, obs_dim)`` float64 array
of per-agent observations, vectorised over agents (no Python loop per agent). In the
informed task (``task="informed"``) the agents that do not observe the goal get zero
actions (:attr:`Controller.acts_informed_only`): the analytic controllers then become
Couzin's informed individuals, and the rest of the swarm follows through the passive
physics alone.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

from swarm_envs.config import SwarmConfig
from swarm_envs.envs.task import OBS_BOUND, observation_size

__all__ = ["Controller", "swarm_config_of"]

#: Attributes followed, in order, to reach the SwarmNav env inside wrappers.
_INNER_ATTRS = ("unwrapped", "env", "venv", "par_env", "aec_env")


def swarm_config_of(env: Any) -> SwarmConfig:
    """The :class:`SwarmConfig` of a swarm_envs environment, through any wrappers.

    Accepts a ``SwarmConfig`` itself, or any object that has one as ``.cfg`` directly or
    behind ``.unwrapped`` / ``.env`` / ``.venv`` (Gymnasium, PettingZoo and SB3
    wrappers). Anything else raises :class:`ValueError`.

    >>> import gymnasium, swarm_envs
    >>> swarm_config_of(gymnasium.make("swarm_envs/SwarmNav-v0", n_agents=5)).n_agents
    5
    """
    seen: set[int] = set()
    frontier = [env]
    while frontier:
        obj = frontier.pop(0)
        if obj is None or id(obj) in seen:
            continue
        seen.add(id(obj))
        if isinstance(obj, SwarmConfig):
            return obj
        try:
            cfg = getattr(obj, "cfg", None)
        except Exception:  # a wrapper that refuses attribute forwarding
            cfg = None
        if isinstance(cfg, SwarmConfig):
            return cfg
        for name in _INNER_ATTRS:
            try:
                inner = getattr(obj, name, None)
            except Exception:
                inner = None
            if inner is not None and inner is not obj:
                frontier.append(inner)
    raise ValueError(
        f"expected a swarm_envs environment (Gymnasium, PettingZoo or VecEnv, possibly "
        f"wrapped) or a SwarmConfig, got {type(env).__name__}"
    )


class Controller(ABC):
    """Base class of the analytic controllers: SB3's ``predict`` protocol on SwarmNav.

    Args:
        env: any swarm_envs environment (possibly wrapped) or a ``SwarmConfig``.

    Attributes:
        cfg: the environment's configuration.
        n_agents, dim, obs_dim, u_max: read from ``cfg``.
        observation_space, action_space: the per-agent spaces (shared-policy layout).
    """

    #: With ``task="informed"``, only the informed agents act (the others get zero):
    #: the goal-seeking controllers' informed-individual reading.
    acts_informed_only: bool = True

    def __init__(self, env: Any) -> None:
        self.cfg: SwarmConfig = swarm_config_of(env)
        self.n_agents: int = self.cfg.n_agents
        self.dim: int = self.cfg.dim
        self.obs_dim: int = observation_size(self.cfg)
        self.u_max: float = self.cfg.u_max
        self.observation_space = spaces.Box(-OBS_BOUND, OBS_BOUND, (self.obs_dim,), np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, (self.dim,), np.float32)

    @classmethod
    def from_config(cls, cfg: SwarmConfig, **kwargs: Any) -> Controller:
        """Build the controller from a configuration instead of an environment."""
        if not isinstance(cfg, SwarmConfig):
            raise ValueError(f"from_config expects a SwarmConfig, got {type(cfg).__name__}")
        return cls(cfg, **kwargs)

    def __repr__(self) -> str:
        return f"{type(self).__name__}(n_agents={self.n_agents}, dim={self.dim})"

    # ------------------------------------------------------------------ protocol
    def predict(
        self,
        observation: Any,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = True,
    ) -> tuple[Any, Any]:
        """Actions for the given observations, SB3-style: returns ``(action, state)``.

        Args:
            observation: ``(..., obs_dim)`` per-agent observations (→ ``(..., d)``), or
                ``(..., N·obs_dim)`` whole-swarm observations of the Gymnasium env
                (→ ``(..., N·d)``), or a PettingZoo dict ``{agent: (obs_dim,)}``
                (→ ``{agent: (d,)}``).
            state: passed through unchanged (the controllers are memoryless).
            episode_start: ignored (accepted for SB3 compatibility).
            deterministic: see the subclass (only :class:`RandomController` samples).

        Returns:
            ``(action, state)``; actions lie in ``[-1, 1]`` and are float32 for float32
            observations (as the environments produce), float64 otherwise.

        Raises:
            ValueError: the observation's last axis is neither ``obs_dim`` nor
                ``N·obs_dim``, or it is not numeric.
        """
        del episode_start
        if isinstance(observation, Mapping):
            keys = list(observation)
            stacked = np.stack([np.asarray(observation[k]) for k in keys]) if keys else None
            if stacked is None:
                return {}, state
            actions, _ = self.predict(stacked, deterministic=deterministic)
            return {k: actions[i] for i, k in enumerate(keys)}, state
        obs = np.asarray(observation)
        if obs.dtype == object or not (
            np.issubdtype(obs.dtype, np.floating) or np.issubdtype(obs.dtype, np.integer)
        ):
            raise ValueError(f"observation must be a numeric array, got dtype {obs.dtype}")
        last = obs.shape[-1] if obs.ndim else None
        if last == self.obs_dim:
            out_last = self.dim
        elif last == self.n_agents * self.obs_dim:
            out_last = self.n_agents * self.dim
        else:
            raise ValueError(
                f"observation has shape {obs.shape}; its last axis must be {self.obs_dim} "
                f"(one agent) or {self.n_agents * self.obs_dim} (all {self.n_agents} agents, "
                "the Gymnasium env)"
            )
        out_dtype = obs.dtype if obs.dtype == np.float32 else np.dtype(np.float64)
        per_agent = obs.reshape(-1, self.obs_dim).astype(np.float64, copy=False)
        actions = self._actions(per_agent, deterministic)
        if self.cfg.informs_agents and self.acts_informed_only:
            # Informed individuals: an agent that does not observe the goal leaves the
            # passive physics alone (its goal offset reads zero anyway).
            actions = actions * (per_agent[:, 2 * self.dim : 2 * self.dim + 1] > 0.5)
        return actions.reshape((*obs.shape[:-1], out_last)).astype(out_dtype, copy=False), state

    @abstractmethod
    def _actions(self, obs: np.ndarray, deterministic: bool) -> np.ndarray:
        """Actions ``(n, d)`` in [-1, 1] for per-agent observations ``(n, obs_dim)``."""
