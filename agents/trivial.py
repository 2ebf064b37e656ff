"""Trivial reference policies: the passive swarm and uniform random actions.

- :class:`ZeroController`: zero action, i.e. the passive social-potential swarm of
  Mabrouk & McInnes (eqs. 9–12) without the goal sink: what the physics alone does.
- :class:`RandomController`: actions uniform in ``[-1, 1]^d``, from a seeded
  ``numpy.random.Generator`` (never global state).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from agents.base import Controller

__all__ = ["RandomController", "ZeroController"]


class ZeroController(Controller):
    """The passive swarm: every action is zero, so the control force ``u_i = 0``.

    >>> from swarm_envs.config import SwarmConfig
    >>> ctrl = ZeroController(SwarmConfig(n_agents=3))
    >>> ctrl.predict(np.ones((3, ctrl.obs_dim), np.float32))[0].tolist()
    [[0.0, 0.0], [0.0, 0.0], [0.0, 0.0]]
    """

    def _actions(self, obs: np.ndarray, deterministic: bool) -> np.ndarray:
        return np.zeros((obs.shape[0], self.dim))


class RandomController(Controller):
    """Actions drawn independently and uniformly from ``[-1, 1]^d`` per agent and call.

    ``deterministic`` is ignored: a uniform policy has no mode, and returning zeros
    would make it the passive swarm (SB3's ``evaluate_policy`` passes
    ``deterministic=True``).

    Args:
        env: any swarm_envs environment (possibly wrapped) or a ``SwarmConfig``.
        seed: seed (or a ``numpy.random.Generator``) of the policy's own generator.

    >>> from swarm_envs.config import SwarmConfig
    >>> ctrl = RandomController(SwarmConfig(), seed=0)
    >>> a, _ = ctrl.predict(np.zeros(ctrl.obs_dim, np.float32))
    >>> a.shape, bool(np.abs(a).max() <= 1.0)
    ((2,), True)
    """

    acts_informed_only = False  # random for every agent, informed or not

    def __init__(self, env: Any, seed: int | np.random.Generator | None = None) -> None:
        super().__init__(env)
        self.seed(seed)

    def seed(self, seed: int | np.random.Generator | None = None) -> None:
        """Re-seed the policy's generator (a Generator is used as given)."""
        self.rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)

    def _actions(self, obs: np.ndarray, deterministic: bool) -> np.ndarray:
        return self.rng.uniform(-1.0, 1.0, size=(obs.shape[0], self.dim))
