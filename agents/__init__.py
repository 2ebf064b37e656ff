"""Policies for the SwarmNav environments: analytic baselines and trivial references.

All share Stable-Baselines3's protocol, ``predict(obs, state=None, episode_start=None,
deterministic=True) -> (action, state)``, so evaluation treats them and trained SB3
models alike (``docs/design.md`` principle 6: baselines are policies, not env methods).
One module per source paper:

- :class:`PotentialFieldController` (:mod:`agents.mabrouk_mcinnes`): the goal sink of
  Mabrouk & McInnes, eqs. 19–21, applied as the control force.
- :class:`InformedIndividualController` (:mod:`agents.naterop`): Couzin's informed
  individuals (Naterop eq. 6), for the zone model.
- :class:`GoalForceController` (:mod:`agents.naterop`): the goal-sink force on top of
  Viscido's piecewise force model.
- :class:`LyapunovTargetController` (:mod:`agents.vanualailai_sharma`): the target
  term of Vanualailai & Sharma's Lyapunov construction, for the Lagrangian model.
- :class:`MillController` (:mod:`agents.mill`): the mill task's controller, straight to
  the goal, then a tangential push about it.
- :class:`SaturatedPDController` (:mod:`agents.pd`): the saturated PD law toward the
  goal, the strongest simple controller for navigation, every dynamics.
- :class:`InformedFollowerController` (:mod:`agents.follow`): informed agents steer with
  the PD law, the others follow their informed neighbours (the informed task).
- :class:`ZeroController`, :class:`RandomController` (:mod:`agents.trivial`).

The papers' controllers are weak by design (their pull decays with the distance to the
goal); the simple controllers are what a practitioner would write with the same
observation. Their gains are tuned on training seeds by ``swarm-tune`` and read from
``configs/baselines/tuned.yaml`` (:mod:`agents.tuned`). :func:`baseline_names` lists, per
task, every baseline an evaluation compares a learned policy with.

Each model names its analytic baseline in its registry entry (``ModelSpec.baseline`` of
:mod:`swarm_envs.models`, a name in :data:`CONTROLLERS`; :data:`ANALYTIC` lists the
shipped models'); the name ``"analytic"`` picks the one that matches the environment's
``dynamics`` and task (the mill task has its own, :data:`TASK_ANALYTIC`; in the informed
task the model's controller acts through the informed agents only).

Build one from any environment of the package or from a config::

    ctrl = PotentialFieldController(env)              # gym / PettingZoo / VecEnv
    ctrl = PotentialFieldController.from_config(cfg)  # a SwarmConfig
    ctrl = make_controller("potential", env)          # by name, as ``swarm-eval`` does
"""

from __future__ import annotations

from typing import Any

from agents.base import Controller, swarm_config_of
from agents.follow import InformedFollowerController
from agents.mabrouk_mcinnes import PotentialFieldController
from agents.mill import MillController
from agents.naterop import GoalForceController, InformedIndividualController
from agents.pd import SaturatedPDController
from agents.trivial import RandomController, ZeroController
from agents.vanualailai_sharma import LyapunovTargetController
from swarm_envs.config import SwarmConfig
from swarm_envs.models import SHIPPED, model_spec

#: Names of the built-in policies, as ``swarm-eval --policies`` accepts them (plus
#: ``"analytic"``, the entry of :data:`ANALYTIC` for the environment's dynamics).
CONTROLLERS: dict[str, type[Controller]] = {
    "potential": PotentialFieldController,
    "informed": InformedIndividualController,
    "goal_force": GoalForceController,
    "lyapunov": LyapunovTargetController,
    "mill": MillController,
    "pd": SaturatedPDController,
    "follow": InformedFollowerController,
    "zero": ZeroController,
    "random": RandomController,
}

#: The analytic baseline of each shipped ``SwarmConfig.dynamics``, as a name in
#: :data:`CONTROLLERS`: their registry entries' ``ModelSpec.baseline`` (a model
#: registered later is read from its entry by :func:`analytic_name`).
ANALYTIC: dict[str, str] = {
    name: baseline for name in SHIPPED if (baseline := model_spec(name).baseline) is not None
}


#: Tasks whose analytic baseline is their own, whatever the dynamics.
TASK_ANALYTIC: dict[str, str] = {"mill": "mill"}


#: The simple controllers of each task, tuned on training seeds: every evaluation compares
#: a learned policy with these as well as with the analytic baseline.
SIMPLE: dict[str, tuple[str, ...]] = {
    "navigation": ("pd",),
    "informed": ("pd", "follow"),
    "mill": ("mill",),
}


def baseline_names(env: Any) -> list[str]:
    """Every baseline of ``env``'s task: the analytic controller (by its own name; a
    model without one has none), then the task's simple controllers (:data:`SIMPLE`).

    >>> from swarm_envs.tasks import task_config
    >>> baseline_names(task_config("informed"))
    ['potential', 'pd', 'follow']
    """
    cfg = swarm_config_of(env)
    analytic = _analytic_or_none(cfg)
    simple = SIMPLE.get(cfg.task, ())  # a user's task: none tuned
    names = [*([] if analytic is None else [analytic]), *simple]
    return list(dict.fromkeys(names))  # the mill's analytic controller is its simple one


def analytic_name(env: Any) -> str:
    """The name of the analytic baseline matching ``env``'s task and dynamics
    (:data:`TASK_ANALYTIC`, else the model's ``ModelSpec.baseline``); :class:`ValueError`
    where there is none.

    >>> from swarm_envs.config import SwarmConfig
    >>> analytic_name(SwarmConfig(dynamics="zone"))
    'informed'
    """
    cfg = swarm_config_of(env)
    name = _analytic_or_none(cfg)
    if name is None:
        raise ValueError(
            f"dynamics {cfg.dynamics!r} has no analytic baseline (its ModelSpec.baseline is "
            f"None); name a policy instead: {', '.join(CONTROLLERS)}"
        )
    return name


def _analytic_or_none(cfg: SwarmConfig) -> str | None:
    """The task's own analytic controller, else the model's (``None``: neither has one)."""
    return TASK_ANALYTIC.get(cfg.task, model_spec(cfg.dynamics).baseline)


def make_controller(name: str, env: Any, *, seed: int | None = None) -> Controller:
    """The built-in policy ``name`` for ``env``: a key of :data:`CONTROLLERS` or ``"analytic"``.

    ``"analytic"`` is the baseline of ``env``'s dynamics (:func:`analytic_name`). ``seed``
    seeds :class:`RandomController` (the others are deterministic). An unknown name
    raises :class:`ValueError` listing the known ones.
    """
    if name == "analytic":
        name = analytic_name(env)
    if name not in CONTROLLERS:
        known = ", ".join([*CONTROLLERS, "analytic"])
        raise ValueError(f"unknown policy {name!r}; known: {known}")
    cls = CONTROLLERS[name]
    if cls is RandomController:
        return RandomController(env, seed=seed)
    return cls(env)


__all__ = [
    "ANALYTIC",
    "CONTROLLERS",
    "SIMPLE",
    "TASK_ANALYTIC",
    "Controller",
    "GoalForceController",
    "InformedFollowerController",
    "InformedIndividualController",
    "LyapunovTargetController",
    "MillController",
    "PotentialFieldController",
    "RandomController",
    "SaturatedPDController",
    "ZeroController",
    "analytic_name",
    "baseline_names",
    "make_controller",
    "swarm_config_of",
]
