"""The sweep config: a task, a grid × seeds and the fixed setup, validated strictly.

:class:`SweepConfig` checks every key and every grid point when it is built (unknown
keys and bad values raise ``ValueError`` naming them) and turns the grid into one
plain-data spec per trial (:meth:`SweepConfig.trial_specs`), the input of
:func:`train.sweep.trials.run_trial`.

>>> sc = sweep_config_from_mapping({"grid": {"l_r": [0.2, 0.4]}, "seeds": [5]})
>>> [(s["index"], s["point"], s["entropy"]) for s in sc.trial_specs()]
[(0, {'l_r': 0.2}, [0, 5]), (1, {'l_r': 0.4}, [0, 5])]
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import math
import typing
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from swarm_envs.config import (
    SwarmConfig,
    as_dict,
    config_from_mapping,
    load_swarm_config,
    resolve_config_path,
)
from swarm_envs.physics import INTEGRATORS, SocialPotentialParams
from train.config import read_yaml_mapping
from train.sweep.measures import DEFAULT_PLOT, TASKS, measure_columns

__all__ = [
    "NavigateSetup",
    "RelaxSetup",
    "SweepConfig",
    "load_sweep_config",
    "sweep_config_from_mapping",
]

_PHYSICS_KEYS = tuple(f.name for f in fields(SocialPotentialParams))


def _finite(owner: str, name: str, value: Any, *, positive: bool, allow_zero: bool = False) -> None:
    ok = (
        not isinstance(value, bool)
        and isinstance(value, (int, float))
        and math.isfinite(value)
        and (value > 0 or (allow_zero and value == 0) or not positive)
    )
    if not ok:
        bound = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{owner}.{name} must be a finite number {bound}, got {value!r}")


def _integer(owner: str, name: str, value: Any, low: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise ValueError(f"{owner}.{name} must be an integer >= {low}, got {value!r}")


@dataclass(frozen=True)
class RelaxSetup:
    """The fixed setup of a ``relax`` trial (grid keys may replace any field)."""

    n_agents: int = 30
    """Swarm size N."""
    dim: int = 2
    """Spatial dimension d (2 or 3)."""
    dt: float = 0.05
    """Integration step (as the paper reproductions: 0.05)."""
    duration: float = 50.0
    """Run length in time units (``round(duration / dt)`` steps)."""
    init_radius: float = 2.0
    """Start positions uniform in a disc (ball) of this radius."""
    init_speed: float = 0.1
    """Start velocities uniform in a disc (ball) of this radius."""
    samples: int = 50
    """Evenly spaced times (end included) averaged into the ``time_mean_*`` statistics."""
    integrator: str = "semi_implicit_euler"
    """One of :data:`swarm_envs.physics.INTEGRATORS`."""
    physics: SocialPotentialParams = field(default_factory=SocialPotentialParams)
    """The fixed physics (default: the paper's Fig. 1–10 set); grid keys override it."""

    def __post_init__(self) -> None:
        _integer("relax", "n_agents", self.n_agents, 1)
        _integer("relax", "samples", self.samples, 1)
        if self.dim not in (2, 3) or isinstance(self.dim, bool):
            raise ValueError(f"relax.dim must be 2 or 3, got {self.dim!r}")
        for name in ("dt", "duration", "init_radius"):
            _finite("relax", name, getattr(self, name), positive=True)
        _finite("relax", "init_speed", self.init_speed, positive=True, allow_zero=True)
        if self.integrator not in INTEGRATORS:
            raise ValueError(
                f"relax.integrator must be one of {INTEGRATORS}, got {self.integrator!r}"
            )
        if not isinstance(self.physics, SocialPotentialParams):
            raise ValueError("relax.physics must be a mapping of SocialPotentialParams fields")

    @property
    def steps(self) -> int:
        """Integration steps, ``round(duration / dt)``, at least 1."""
        return max(1, round(self.duration / self.dt))


@dataclass(frozen=True)
class NavigateSetup:
    """The fixed setup of a ``navigate`` trial: the env and the controller."""

    env_config: str | None = None
    """Env YAML (``configs/env/...``) or null for the SwarmNav defaults."""
    env: dict = field(default_factory=dict)
    """Overrides of :class:`~swarm_envs.config.SwarmConfig` keys."""
    policy: str = "potential"
    """Built-in controller (``potential``, ``zero``, ``random``; :data:`agents.CONTROLLERS`)."""

    def __post_init__(self) -> None:
        from agents import CONTROLLERS

        if not isinstance(self.env, Mapping):
            raise ValueError(f"navigate.env must be a mapping, got {self.env!r}")
        if self.policy not in CONTROLLERS:
            raise ValueError(
                f"navigate.policy must be one of {', '.join(CONTROLLERS)}, got {self.policy!r}"
            )

    def swarm_config(self, point: Mapping[str, Any] | None = None) -> SwarmConfig:
        """The env config with the grid ``point`` applied (physics keys go to ``physics``)."""
        overrides: dict[str, Any] = {k: v for k, v in self.env.items()}
        physics = {k: v for k, v in (point or {}).items() if k in _PHYSICS_KEYS}
        top = {k: v for k, v in (point or {}).items() if k not in _PHYSICS_KEYS}
        overrides.update(top)
        if physics:
            base = overrides.get("physics", {})
            if not isinstance(base, Mapping):
                raise ValueError("navigate.env.physics must be a mapping")
            overrides["physics"] = {**base, **physics}
        return load_swarm_config(self.env_config, overrides)


def _grid_keys(task: str) -> tuple[str, ...]:
    """The parameters a grid of ``task`` may vary: physics fields, then setup fields."""
    if task == "relax":
        setup = tuple(f.name for f in fields(RelaxSetup) if f.name not in ("physics", "samples"))
        return _PHYSICS_KEYS + setup
    hints = typing.get_type_hints(SwarmConfig)
    scalar = tuple(
        f.name
        for f in fields(SwarmConfig)
        if not (isinstance(hints[f.name], type) and dataclasses.is_dataclass(hints[f.name]))
    )
    return _PHYSICS_KEYS + scalar


@dataclass(frozen=True)
class SweepConfig:
    """A sweep: ``task``, ``grid`` × ``seeds``, the fixed setup, and how to run it."""

    task: str = "relax"
    """``relax`` (passive physics, group statistics) or ``navigate`` (a controller's
    episode on SwarmNav)."""
    grid: dict[str, tuple[Any, ...]] = field(default_factory=dict)
    """Parameter → list of values; the trials are the product of the lists × seeds."""
    seeds: tuple[int, ...] = (0, 1, 2, 3)
    """The seeds: a number ``n`` (the seeds ``0 … n−1``) or an explicit list of integers
    >= 0; held as the tuple of seeds."""
    base_seed: int = 0
    """First entry of every trial's ``SeedSequence``."""
    common_random_numbers: bool = True
    """True: a seed's start state is the same at every grid point (seeded from
    ``[base_seed, seed]``); false: the grid point enters the seed too."""
    relax: RelaxSetup = field(default_factory=RelaxSetup)
    """Fixed setup of the ``relax`` task."""
    navigate: NavigateSetup = field(default_factory=NavigateSetup)
    """Fixed setup of the ``navigate`` task."""
    plot: tuple[str, ...] = ()
    """Measures drawn in ``sweep.png`` (empty: a default per task)."""
    cpus_per_trial: float = 1.0
    """Ray engine: CPUs reserved per trial."""
    max_concurrent_trials: int | None = None
    """Ray engine: at most this many trials at once (null: as many as CPUs allow)."""

    def __post_init__(self) -> None:
        if self.task not in TASKS:
            raise ValueError(f"task must be one of {TASKS}, got {self.task!r}")
        if not isinstance(self.grid, Mapping) or not self.grid:
            raise ValueError(
                "grid must be a non-empty mapping of parameter -> list of values, "
                f"got {self.grid!r}"
            )
        allowed = _grid_keys(self.task)
        grid: dict[str, tuple[Any, ...]] = {}
        for key, values in self.grid.items():
            if key not in allowed:
                raise ValueError(
                    f"grid.{key} is not a parameter of the {self.task} task; "
                    f"allowed: {', '.join(allowed)}"
                )
            if isinstance(values, (str, bytes)) or not isinstance(values, Sequence) or not values:
                raise ValueError(f"grid.{key} must be a non-empty list of values, got {values!r}")
            for v in values:
                if not isinstance(v, (int, float, str, bool)) or (
                    isinstance(v, float) and not math.isfinite(v)
                ):
                    raise ValueError(f"grid.{key} values must be finite scalars, got {v!r}")
            if len(set(values)) != len(values):
                raise ValueError(f"grid.{key} has repeated values: {list(values)!r}")
            grid[key] = tuple(values)
        object.__setattr__(self, "grid", grid)
        seeds: Any = self.seeds  # a number or a list until checked
        if isinstance(seeds, int) and not isinstance(seeds, bool):
            if seeds < 1:
                raise ValueError(f"seeds must be an integer >= 1 or a list, got {seeds!r}")
            seeds = tuple(range(seeds))
        elif isinstance(seeds, Sequence) and not isinstance(seeds, (str, bytes)) and seeds:
            if any(isinstance(s, bool) or not isinstance(s, int) or s < 0 for s in seeds):
                raise ValueError(f"seeds must be integers >= 0, got {list(seeds)!r}")
            if len(set(seeds)) != len(seeds):
                raise ValueError(f"seeds has repeated values: {list(seeds)!r}")
            seeds = tuple(seeds)
        else:
            raise ValueError(f"seeds must be an integer >= 1 or a list, got {seeds!r}")
        object.__setattr__(self, "seeds", seeds)
        _integer("sweep", "base_seed", self.base_seed, 0)
        if not isinstance(self.common_random_numbers, bool):
            raise ValueError(
                f"common_random_numbers must be true or false, got {self.common_random_numbers!r}"
            )
        columns = measure_columns(self.task)
        plot = tuple(self.plot) if isinstance(self.plot, (list, tuple)) else (self.plot,)
        for name in plot:
            if name not in columns:
                raise ValueError(
                    f"plot: {name!r} is not a measure of the {self.task} task; "
                    f"allowed: {', '.join(columns)}"
                )
        object.__setattr__(self, "plot", plot)
        _finite("sweep", "cpus_per_trial", self.cpus_per_trial, positive=True)
        if self.max_concurrent_trials is not None:
            _integer("sweep", "max_concurrent_trials", self.max_concurrent_trials, 1)
        for point in self.points():  # every grid point must be valid before any trial runs
            try:
                self._setup(point)
            except ValueError as err:
                raise ValueError(f"grid point {point}: {err}") from None

    # ------------------------------------------------------------------ trials
    def points(self) -> list[dict[str, Any]]:
        """The grid points, in order (the first key varies slowest)."""
        keys = list(self.grid)
        return [
            dict(zip(keys, combo, strict=True)) for combo in itertools.product(*self.grid.values())
        ]

    def _setup(self, point: Mapping[str, Any]) -> dict[str, Any]:
        """The fully resolved setup of one grid point, as plain data."""
        if self.task == "relax":
            physics = {k: v for k, v in point.items() if k in _PHYSICS_KEYS}
            top = {k: v for k, v in point.items() if k not in _PHYSICS_KEYS}
            try:
                setup = replace(self.relax, physics=replace(self.relax.physics, **physics), **top)
            except TypeError as err:
                raise ValueError(str(err)) from None
            return as_dict(setup)
        cfg = self.navigate.swarm_config(point)
        return {"env": as_dict(cfg), "policy": self.navigate.policy}

    def trial_specs(self) -> list[dict[str, Any]]:
        """One plain-data spec per trial (grid point × seed), the input of :func:`run_trial`."""
        specs: list[dict[str, Any]] = []
        for point in self.points():
            setup = self._setup(point)
            for seed in self.seeds:
                entropy = [self.base_seed, seed]
                if not self.common_random_numbers:
                    entropy.append(_point_hash(point))
                specs.append(
                    {
                        "index": len(specs),
                        "task": self.task,
                        "point": dict(point),
                        "seed": seed,
                        "entropy": entropy,
                        "setup": setup,
                    }
                )
        return specs

    def plot_measures(self) -> tuple[str, ...]:
        """The measures ``sweep.png`` draws."""
        return self.plot or DEFAULT_PLOT[self.task]

    def to_dict(self) -> dict[str, Any]:
        """Plain data for YAML / JSON."""
        out = as_dict(self)
        out["grid"] = {k: list(v) for k, v in self.grid.items()}
        out["seeds"] = list(self.seeds)
        out["plot"] = list(self.plot)
        return out


def _point_hash(point: Mapping[str, Any]) -> int:
    """A stable 63-bit hash of a grid point (independent of process and Python hash seed)."""
    text = json.dumps(dict(point), sort_keys=True)
    return int.from_bytes(hashlib.sha256(text.encode()).digest()[:8], "little") >> 1


def sweep_config_from_mapping(data: Mapping[str, Any]) -> SweepConfig:
    """Build a :class:`SweepConfig` strictly (unknown keys name themselves).

    >>> sweep_config_from_mapping({"grid": {"l_r": [0.2]}, "relax": {"n_agent": 3}})
    Traceback (most recent call last):
    ...
    ValueError: unknown config key 'relax.n_agent'; allowed keys: ...
    """
    return config_from_mapping(SweepConfig, data)


def load_sweep_config(
    path: str | Path | None, overrides: Mapping[str, Any] | None = None
) -> SweepConfig:
    """Load ``configs/sweeps/<name>.yaml`` and merge ``overrides`` (sections merge)."""
    data: dict[str, Any] = {}
    if path is not None:
        data = read_yaml_mapping(
            resolve_config_path(path, "sweeps", "sweep config"), "sweep config"
        )
    for key, value in (overrides or {}).items():
        if isinstance(value, Mapping) and isinstance(data.get(key), Mapping):
            data[key] = {**data[key], **value}
        else:
            data[key] = value
    return sweep_config_from_mapping(data)
