"""Policies for the SwarmNav environments: analytic baselines and trivial references.

All share Stable-Baselines3's protocol, ``predict(obs, state=None, episode_start=None,
deterministic=True) -> (action, state)``, so evaluation treats them and trained SB3
models alike (DESIGN.md principle 6: baselines are policies, not env methods). One
module per source paper:

- :class:`PotentialFieldController` (:mod:`agents.mabrouk_mcinnes`): the goal sink of
  Mabrouk & McInnes, eqs. 19–21, applied as the control force.
- :class:`ZeroController`, :class:`RandomController` (:mod:`agents.trivial`).

Build one from any environment of the package or from a config::

    ctrl = PotentialFieldController(env)              # gym / PettingZoo / VecEnv
    ctrl = PotentialFieldController.from_config(cfg)  # a SwarmConfig
    ctrl = make_controller("potential", env)          # by name, as ``swarm-eval`` does
"""

from __future__ import annotations

from typing import Any

from agents.base import Controller, swarm_config_of
from agents.mabrouk_mcinnes import PotentialFieldController
from agents.trivial import RandomController, ZeroController

#: Names of the built-in policies, as ``swarm-eval --policies`` accepts them.
CONTROLLERS: dict[str, type[Controller]] = {
    "potential": PotentialFieldController,
    "zero": ZeroController,
    "random": RandomController,
}


def make_controller(name: str, env: Any, *, seed: int | None = None) -> Controller:
    """The built-in policy ``name`` (a key of :data:`CONTROLLERS`) for ``env``.

    ``seed`` seeds :class:`RandomController` (the others are deterministic). An unknown
    name raises :class:`ValueError` listing the known ones.
    """
    if name not in CONTROLLERS:
        raise ValueError(f"unknown policy {name!r}; known: {', '.join(CONTROLLERS)}")
    cls = CONTROLLERS[name]
    if cls is RandomController:
        return RandomController(env, seed=seed)
    return cls(env)


__all__ = [
    "CONTROLLERS",
    "Controller",
    "PotentialFieldController",
    "RandomController",
    "ZeroController",
    "make_controller",
    "swarm_config_of",
]
