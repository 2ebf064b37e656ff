"""Parameter sweeps: a grid of physics (or task) parameters × seeds, run locally or on Ray Tune.

A sweep (``configs/sweeps/*.yaml`` → :class:`SweepConfig`) names a **task**, a
**grid** (parameter → list of values; the trials are the Cartesian product of the
lists, times the seeds) and the fixed setup. Two tasks:

``relax``
    The passive social-potential swarm of Mabrouk & McInnes (Figs. 1–10): agents start
    uniform in a disc, the physics runs for ``duration`` time units, and the group
    statistics of :mod:`swarm_envs.metrics` are recorded at the end (``final_*``) and
    averaged over ``samples`` evenly spaced times (``time_mean_*``). Grid keys: any
    :class:`~swarm_envs.physics.SocialPotentialParams` field (``l_r``, ``C_r``,
    ``C_o``, ``beta``, …) or a :class:`RelaxSetup` field (``n_agents``, ``dt``, …).
``navigate``
    One SwarmNav episode of an analytic controller (default ``potential``, the paper's
    goal sink, eq. 21) per trial, measured as :mod:`train.evaluate` measures it. Grid
    keys: ``SocialPotentialParams`` fields (the controller's ``C_g``, ``l_g``) or scalar
    :class:`~swarm_envs.config.SwarmConfig` fields (``n_agents``, ``u_max``, …).

Every trial is the same pure function, :func:`run_trial`, of a plain-data spec
(:meth:`SweepConfig.trial_specs`); its random start comes from
``numpy.random.SeedSequence([base_seed, seed])`` (common random numbers: every grid
point sees the same starts for a seed, as in the paper's sweeps), or with
``common_random_numbers: false`` from ``[base_seed, seed, hash(grid point)]``. So the
two engines give the same numbers for the same grid and seeds:

- ``local``: the trials one after another in this process (no Ray);
- ``ray``: one Ray Tune trial per grid point × seed, spread over a local Ray or a
  cluster (``address``), ``cpus_per_trial`` CPUs each.

Results (:func:`write_outputs`): ``trials.csv`` (one row per trial), ``summary.csv``
(per grid point: mean and population std over seeds of every measure),
``results.json`` (both, with the config), ``sweep.png`` (the ``plot`` measures against
the first grid key, one line per value of the others, error bars ± std over seeds) and
``sweep_config.yaml``.

>>> sc = sweep_config_from_mapping({"grid": {"l_r": [0.2, 0.4]}, "seeds": 2,
...     "relax": {"n_agents": 5, "duration": 0.5, "dt": 0.05, "samples": 3}})
>>> [(s["point"], s["seed"]) for s in sc.trial_specs()]
[({'l_r': 0.2}, 0), ({'l_r': 0.2}, 1), ({'l_r': 0.4}, 0), ({'l_r': 0.4}, 1)]
>>> rows = run_local(sc.trial_specs())
>>> rows == run_local(sc.trial_specs()), rows[0]["final_expanse"] > 0
(True, True)
"""

from __future__ import annotations

import csv
import dataclasses
import hashlib
import itertools
import json
import math
import time
import typing
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from swarm_envs import metrics
from swarm_envs.config import (
    SwarmConfig,
    as_dict,
    config_from_mapping,
    load_swarm_config,
    resolve_config_path,
)
from swarm_envs.physics import INTEGRATORS, SocialPotentialParams, random_swarm, simulate

__all__ = [
    "ENGINES",
    "NAVIGATE_MEASURES",
    "RELAX_STATISTICS",
    "TASKS",
    "NavigateSetup",
    "RelaxSetup",
    "SweepConfig",
    "SweepResult",
    "load_sweep_config",
    "measure_columns",
    "run_local",
    "run_ray",
    "run_sweep",
    "run_trial",
    "summarize_rows",
    "sweep_config_from_mapping",
    "trial_seed",
    "write_outputs",
]

TASKS = ("relax", "navigate")
ENGINES = ("local", "ray")

#: Group statistics of the ``relax`` task, each from ``(x, v)`` shaped ``(T, N, d)``.
RELAX_STATISTICS: dict[str, Callable[..., np.ndarray]] = {
    "polarization": lambda x, v, p: metrics.polarization(v),
    "velocity_polarization": lambda x, v, p: metrics.velocity_polarization(v),
    "angular_momentum": lambda x, v, p: metrics.angular_momentum(x, v),
    "velocity_angular_momentum": lambda x, v, p: metrics.velocity_angular_momentum(x, v),
    "expanse": lambda x, v, p: metrics.expanse(x),
    "nearest_neighbor_distance": lambda x, v, p: metrics.nearest_neighbor_distance(x),
    "mean_speed": lambda x, v, p: np.sqrt(np.einsum("...k,...k->...", v, v)).mean(axis=-1),
    "energy": lambda x, v, p: metrics.total_energy(x, v, p),
}

#: Measures of one ``navigate`` episode (``time_to_goal`` is empty when it failed).
NAVIGATE_MEASURES = (
    "return",
    "success",
    "time_to_goal",
    "episode_length",
    "collisions",
    "control_effort",
    "final_expanse",
    "final_polarization",
    "final_angular_momentum",
    "final_nearest_neighbor_distance",
    "final_centroid_distance",
    "final_fraction_arrived",
)

#: Measures plotted when the config's ``plot`` is empty.
DEFAULT_PLOT = {
    "relax": (
        "final_expanse",
        "final_nearest_neighbor_distance",
        "final_velocity_polarization",
        "final_velocity_angular_momentum",
    ),
    "navigate": ("success", "time_to_goal", "return", "final_expanse"),
}

_PHYSICS_KEYS = tuple(f.name for f in fields(SocialPotentialParams))


def measure_columns(task: str) -> tuple[str, ...]:
    """The measure columns a trial of ``task`` reports, in order.

    >>> measure_columns("relax")[:2]
    ('final_polarization', 'time_mean_polarization')
    """
    if task == "relax":
        return tuple(
            col for name in RELAX_STATISTICS for col in (f"final_{name}", f"time_mean_{name}")
        )
    if task == "navigate":
        return NAVIGATE_MEASURES
    raise ValueError(f"task must be one of {TASKS}, got {task!r}")


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


# --------------------------------------------------------------------------- config


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
    grid: dict = field(default_factory=dict)
    """Parameter → list of values; the trials are the product of the lists × seeds."""
    seeds: int | list = 4
    """Number of seeds (``0 … seeds−1``) or an explicit list of seeds (integers >= 0)."""
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
        seeds = self.seeds
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
        specs = []
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


def trial_seed(entropy: Sequence[int]) -> int:
    """The integer seed of a trial: ``SeedSequence(entropy)``'s first 63-bit word.

    >>> trial_seed([0, 1]) == trial_seed([0, 1]) != trial_seed([0, 2])
    True
    """
    state = np.random.SeedSequence([int(e) for e in entropy]).generate_state(1, np.uint64)
    return int(state[0]) >> 1


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
        p = resolve_config_path(path, "sweeps", "sweep config")
        data = yaml.safe_load(p.read_text()) or {}
        if not isinstance(data, dict):
            raise ValueError(f"sweep config {p} must hold a mapping")
    for key, value in (overrides or {}).items():
        if isinstance(value, Mapping) and isinstance(data.get(key), Mapping):
            data[key] = {**data[key], **value}
        else:
            data[key] = value
    return sweep_config_from_mapping(data)


# --------------------------------------------------------------------------- one trial


def _sample_indices(steps: int, samples: int) -> np.ndarray:
    """``samples`` evenly spaced step indices in ``[0, steps]``, the end always included."""
    return np.unique(np.rint(np.linspace(0, steps, min(samples, steps + 1))).astype(np.int64))


def _relax(setup: Mapping[str, Any], seed: int) -> dict[str, float]:
    rs = config_from_mapping(RelaxSetup, setup)
    rng = np.random.default_rng(seed)
    x0, v0 = random_swarm(rng, rs.n_agents, dim=rs.dim, radius=rs.init_radius, speed=rs.init_speed)
    xs, vs = simulate(rs.physics, x0, v0, dt=rs.dt, steps=rs.steps, integrator=rs.integrator)
    idx = _sample_indices(rs.steps, rs.samples)
    x, v = xs[idx], vs[idx]
    out: dict[str, float] = {}
    for name, fn in RELAX_STATISTICS.items():
        series = np.asarray(fn(x, v, rs.physics), dtype=np.float64)
        out[f"final_{name}"] = float(series[-1])
        out[f"time_mean_{name}"] = float(series.mean())
    return out


def _navigate(setup: Mapping[str, Any], seed: int) -> dict[str, Any]:
    from agents import make_controller
    from train.evaluate import FINAL_KEYS, run_episodes

    cfg = config_from_mapping(SwarmConfig, setup["env"])
    policy = make_controller(setup["policy"], cfg, seed=seed)
    batch = run_episodes(policy, cfg, 1, seed, name="sweep", record_episode=False)
    success = bool(batch.success[0])
    length = int(batch.lengths[0])
    out: dict[str, Any] = {
        "return": float(batch.returns[0]),
        "success": float(success),
        "time_to_goal": length * cfg.dt if success else None,
        "episode_length": float(length),
        "collisions": float(batch.collisions[0]),
        "control_effort": float(batch.effort[0]),
    }
    for k in FINAL_KEYS:
        out[f"final_{k}"] = float(batch.final[k][0])
    return out


def run_trial(spec: Mapping[str, Any]) -> dict[str, Any]:
    """Run one trial: a pure function of its spec (see :meth:`SweepConfig.trial_specs`).

    Returns the row ``{"index", <grid keys>, "seed", <measures>}`` of plain Python
    values (floats, ints, ``None`` for a missing time to goal).
    """
    seed = trial_seed(spec["entropy"])
    if spec["task"] == "relax":
        measures = _relax(spec["setup"], seed)
    elif spec["task"] == "navigate":
        measures = _navigate(spec["setup"], seed)
    else:
        raise ValueError(f"task must be one of {TASKS}, got {spec['task']!r}")
    return {"index": int(spec["index"]), **spec["point"], "seed": int(spec["seed"]), **measures}


# --------------------------------------------------------------------------- engines


def run_local(specs: Sequence[Mapping[str, Any]], *, progress: bool = False) -> list[dict]:
    """Every trial in this process, one after another (no Ray). Rows in spec order."""
    from tqdm.auto import tqdm

    return [run_trial(s) for s in tqdm(specs, desc="trials", disable=not progress)]


def _tune_trial(config: dict[str, Any], specs: Sequence[Mapping[str, Any]]) -> None:
    """Ray Tune function trainable: one trial, reported as one JSON row (exact floats)."""
    from ray import tune

    row = run_trial(specs[config["index"]])
    tune.report({"index": row["index"], "row_json": json.dumps(row)})


def _progress_callback(total: int) -> Any:
    """A Ray Tune callback that advances a tqdm bar (stderr) as trials finish."""
    from ray.tune import Callback
    from tqdm.auto import tqdm

    class _Progress(Callback):
        def __init__(self) -> None:
            self.bar = tqdm(total=total, desc="trials", unit="trial")

        def on_trial_complete(self, iteration: int, trials: list, trial: Any, **info: Any) -> None:
            self.bar.update(1)

        def on_trial_error(self, iteration: int, trials: list, trial: Any, **info: Any) -> None:
            self.bar.update(1)

        def on_experiment_end(self, trials: list, **info: Any) -> None:
            self.bar.close()

    return _Progress()


def run_ray(
    specs: Sequence[Mapping[str, Any]],
    *,
    name: str = "sweep",
    address: str | None = None,
    num_cpus: int | None = None,
    cpus_per_trial: float = 1.0,
    max_concurrent_trials: int | None = None,
    storage_path: str | Path | None = None,
    progress: bool = False,
) -> list[dict]:
    """Every trial as a Ray Tune trial, on a local Ray or the cluster at ``address``.

    Args:
        specs: the trial specs (:meth:`SweepConfig.trial_specs`); Ray ships them once
            (``tune.with_parameters``) and each trial picks its own by index.
        name: Tune experiment name (a folder under ``storage_path``).
        address: a running Ray cluster (``HOST:PORT``, ``auto``); ``None`` starts a
            local Ray with ``num_cpus`` CPUs.
        num_cpus: CPUs of the local Ray (``None``: all).
        cpus_per_trial: CPUs Ray reserves per trial.
        max_concurrent_trials: cap on simultaneous trials (``None``: what CPUs allow).
        storage_path: where Tune keeps its per-trial logs (default ``~/ray_results``);
            on a multi-machine cluster a shared folder or a cloud URI. The rows come
            back to this process in any case.
        progress: a progress bar of finished trials (Tune's own tables stay off).

    Returns:
        The rows, in spec order.

    Raises:
        ImportError: Ray is not installed.
        RuntimeError: a trial failed (its error is included).
    """
    from train.rllib.cluster import ray_session, require_ray

    require_ray()
    with ray_session(address, num_cpus=num_cpus, verbose=progress):
        from ray import tune

        trainable = tune.with_resources(
            tune.with_parameters(_tune_trial, specs=list(specs)), {"cpu": cpus_per_trial}
        )
        run_config: dict[str, Any] = {"name": name, "verbose": 0}
        if progress:
            run_config["callbacks"] = [_progress_callback(len(specs))]
        if storage_path is not None:
            sp = str(storage_path)
            run_config["storage_path"] = sp if "://" in sp else str(Path(sp).resolve())
        tuner = tune.Tuner(
            trainable,
            param_space={"index": tune.grid_search(list(range(len(specs))))},
            tune_config=tune.TuneConfig(
                max_concurrent_trials=max_concurrent_trials, reuse_actors=True
            ),
            run_config=tune.RunConfig(**run_config),
        )
        grid = tuner.fit()
        if grid.errors:
            raise RuntimeError(f"{len(grid.errors)} sweep trial(s) failed; first: {grid.errors[0]}")
        rows = [json.loads(result.metrics["row_json"]) for result in grid]
    rows.sort(key=lambda r: r["index"])
    if [r["index"] for r in rows] != [int(s["index"]) for s in specs]:
        raise RuntimeError("Ray Tune returned a different set of trials than it was given")
    return rows


# --------------------------------------------------------------------------- results


@dataclass
class SweepResult:
    """What a sweep produced: the per-trial ``rows`` and the per-point ``summary``."""

    config: SweepConfig
    engine: str
    rows: list[dict[str, Any]]
    summary: list[dict[str, Any]]
    seconds: float


def summarize_rows(sc: SweepConfig, rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Per grid point: ``<measure>_mean`` and ``<measure>_std`` (population) over seeds.

    Missing values (a failed episode's ``time_to_goal``) are left out of that measure;
    ``n_seeds`` counts the trials of the point. A measure with no value is ``None``.
    """
    keys = list(sc.grid)
    groups: dict[tuple, list[Mapping[str, Any]]] = {}
    for row in rows:
        groups.setdefault(tuple(row[k] for k in keys), []).append(row)
    out = []
    for point in sc.points():
        members = groups.get(tuple(point[k] for k in keys), [])
        entry: dict[str, Any] = {**point, "n_seeds": len(members)}
        for col in measure_columns(sc.task):
            values = np.array([r[col] for r in members if r.get(col) is not None], np.float64)
            entry[f"{col}_mean"] = float(values.mean()) if values.size else None
            entry[f"{col}_std"] = float(values.std()) if values.size else None
        out.append(entry)
    return out


def run_sweep(
    sc: SweepConfig,
    *,
    engine: str = "local",
    name: str = "sweep",
    address: str | None = None,
    num_cpus: int | None = None,
    storage_path: str | Path | None = None,
    progress: bool = False,
) -> SweepResult:
    """Run every trial of ``sc`` with ``engine`` (``local`` or ``ray``) and summarise.

    ``address``, ``num_cpus`` and ``storage_path`` apply to the ``ray`` engine
    (:func:`run_ray`).
    """
    if engine not in ENGINES:
        raise ValueError(f"engine must be one of {ENGINES}, got {engine!r}")
    if engine == "local" and address is not None:
        raise ValueError("address applies only to the ray engine")
    specs = sc.trial_specs()
    start = time.perf_counter()
    if engine == "local":
        rows = run_local(specs, progress=progress)
    else:
        rows = run_ray(
            specs,
            name=name,
            address=address,
            num_cpus=num_cpus,
            cpus_per_trial=sc.cpus_per_trial,
            max_concurrent_trials=sc.max_concurrent_trials,
            storage_path=storage_path,
            progress=progress,
        )
    seconds = time.perf_counter() - start
    return SweepResult(sc, engine, rows, summarize_rows(sc, rows), seconds)


def _write_csv(path: Path, rows: Sequence[Mapping[str, Any]]) -> None:
    columns = list(rows[0]) if rows else []
    with path.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=columns)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: ("" if row.get(k) is None else row.get(k)) for k in columns})


def write_outputs(result: SweepResult, out_dir: str | Path, *, plot: bool = True) -> Path:
    """Write ``trials.csv``, ``summary.csv``, ``results.json``, ``sweep_config.yaml`` and
    (``plot``) ``sweep.png`` into ``out_dir``; returns the folder."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    sc = result.config
    _write_csv(out / "trials.csv", result.rows)
    _write_csv(out / "summary.csv", result.summary)
    (out / "sweep_config.yaml").write_text(yaml.safe_dump(sc.to_dict(), sort_keys=False))
    payload = {
        "config": sc.to_dict(),
        "engine": result.engine,
        "trials": len(result.rows),
        "seconds": round(result.seconds, 3),
        "measures": list(measure_columns(sc.task)),
        "summary": result.summary,
        "rows": result.rows,
    }
    (out / "results.json").write_text(json.dumps(payload, indent=1) + "\n")
    if plot:
        plot_summary(sc, result.summary, out / "sweep.png")
    return out


def plot_summary(sc: SweepConfig, summary: Sequence[Mapping[str, Any]], path: Path) -> None:
    """One panel per plotted measure: mean ± std over seeds against the first grid key,
    one line per combination of the other keys."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    keys = list(sc.grid)
    xkey, others = keys[0], keys[1:]
    xs = list(sc.grid[xkey])
    numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in xs)
    measures = sc.plot_measures()
    cols = min(2, len(measures))
    rows_n = math.ceil(len(measures) / cols)
    fig, axes = plt.subplots(rows_n, cols, figsize=(5.2 * cols, 3.6 * rows_n), squeeze=False)
    combos = list(itertools.product(*(sc.grid[k] for k in others))) or [()]
    for ax, measure in zip(axes.flat, measures, strict=False):
        for combo in combos:
            fixed = dict(zip(others, combo, strict=True))
            line = [e for e in summary if all(e[k] == v for k, v in fixed.items())]
            line.sort(key=lambda e: xs.index(e[xkey]))
            ys = [e[f"{measure}_mean"] for e in line]
            es = [e[f"{measure}_std"] for e in line]
            xv = [e[xkey] for e in line] if numeric else list(range(len(line)))
            y = np.array([np.nan if v is None else v for v in ys], np.float64)
            err = np.array([0.0 if v is None else v for v in es], np.float64)
            label = ", ".join(f"{k} = {v}" for k, v in fixed.items()) or None
            ax.errorbar(xv, y, yerr=err, marker="o", ms=3, capsize=2, label=label)
        if not numeric:
            ax.set_xticks(range(len(xs)), [str(v) for v in xs])
        ax.set_xlabel(xkey)
        ax.set_ylabel(measure.replace("_", " "))
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(measures) :]:
        ax.set_visible(False)
    if others and len(combos) <= 10:
        axes.flat[0].legend(fontsize=7)
    fig.suptitle(f"{sc.task} sweep: mean ± std over {len(sc.seeds)} seeds", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
