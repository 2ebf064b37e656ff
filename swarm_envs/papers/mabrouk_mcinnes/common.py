"""The run setup and the statistics shared by the Mabrouk & McInnes figures.

:class:`RunSetup` holds the choices the paper leaves open (the package docstring gives
the reasons); the helpers below run the physics (:mod:`swarm_envs.physics`) for a
batch of seeds and reduce the statistics (:mod:`swarm_envs.metrics`, ``docs/models.md``
§2) to the ``time_mean`` / ``final`` summaries the figures report.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from swarm_envs import metrics
from swarm_envs.physics import SocialPotentialParams, random_swarm, simulate

__all__ = [
    "DEFAULT_BETAS",
    "DEFAULT_C_OS",
    "DEFAULT_C_RATIOS",
    "DEFAULT_L_RATIOS",
    "NAV_GOAL",
    "NAV_SNAPSHOT_TIMES",
    "RELAX_SPEED",
    "SERIES_POINTS",
    "STATISTICS",
    "RunSetup",
    "params_dict",
    "run_physics",
    "sample_indices",
    "series",
    "setup_for",
    "steps_for",
    "summary",
    "sweep",
    "sweep_values",
    "thin",
]

#: β values of the Fig. 1 sweep (the paper's abscissa is not legible in the seed).
DEFAULT_BETAS = (0.0, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 1.8)
#: C_o values of the Fig. 6–8 sweep (0 to 1; ``C_o`` above ~1.5 needs ``dt < 0.05``).
DEFAULT_C_OS = (0.0, 0.05, 0.1, 0.2, 0.3, 0.5, 0.7, 1.0)
#: ``l = l_r / l_a`` values of Fig. 9 (``l = 1`` with ``C = 1.2`` has no attractive
#: well at all, the swarm disperses; the sweep stops at 0.8).
DEFAULT_L_RATIOS = (0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.6, 0.8)
#: ``C = C_r / C_a`` values of Fig. 10 (``C > l = 0.2`` keeps a repulsive core).
DEFAULT_C_RATIOS = (0.4, 0.6, 0.8, 1.0, 1.2, 1.5, 2.0, 3.0)
#: Goal of the Fig. 11 run, 25 length units from the start (the paper gives no position).
NAV_GOAL = (20.0, 15.0)
#: Snapshot times of Fig. 11 (caption of seed 001; seed 000 lists 0, 28, 86, 318).
NAV_SNAPSHOT_TIMES = (0.0, 28.0, 86.0, 135.0, 204.0, 318.0)
#: A run counts as relaxed when the mean agent speed at its end is below this.
RELAX_SPEED = 0.01
#: Time-series points written to JSON per curve.
SERIES_POINTS = 101


@dataclass(frozen=True)
class RunSetup:
    """The choices the paper leaves open, shared by every figure.

    Attributes:
        n_agents: swarm size N (paper: 30 for Figs. 1–10).
        seeds: number of random initial conditions averaged over.
        dt: integration step (semi-implicit Euler).
        duration: run length in time units (the paper's "500 steps", read as
            500 × 0.1; see the package docstring).
        init_radius: initial positions uniform in a disc of this radius.
        init_speed: initial velocities uniform in a disc of this radius.
        base_seed: seed of ``numpy.random.default_rng`` for the initial conditions.
        max_samples: at most this many time samples enter the time averages.

    >>> RunSetup().steps
    1000
    """

    n_agents: int = 30
    seeds: int = 8
    dt: float = 0.05
    duration: float = 50.0
    init_radius: float = 2.0
    init_speed: float = 0.1
    base_seed: int = 0
    max_samples: int = 400

    def __post_init__(self) -> None:
        for name in ("n_agents", "seeds", "max_samples"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f"RunSetup.{name} must be an integer >= 1, got {value!r}")
        for name in ("dt", "duration", "init_radius"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"RunSetup.{name} must be finite and > 0, got {value!r}")
        if not (math.isfinite(self.init_speed) and self.init_speed >= 0):
            raise ValueError(f"RunSetup.init_speed must be finite and >= 0, got {self.init_speed}")

    @classmethod
    def quick(cls) -> RunSetup:
        """Tiny sizes for smoke tests: 8 agents, 2 seeds, 5 time units."""
        return cls(n_agents=8, seeds=2, duration=5.0, max_samples=50)

    @property
    def steps(self) -> int:
        """Number of integration steps, ``round(duration / dt)``."""
        return steps_for(self.duration, self.dt)

    def initial(self, n_agents: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Initial ``(x0, v0)`` shaped ``(seeds, N, 2)``, the same on every call."""
        rng = np.random.default_rng(self.base_seed)
        n = self.n_agents if n_agents is None else n_agents
        return random_swarm(
            rng,
            n,
            radius=self.init_radius,
            speed=self.init_speed,
            batch_shape=(self.seeds,),
        )

    def as_dict(self) -> dict[str, Any]:
        """The fields plus ``steps``, for the JSON files."""
        out = asdict(self)
        out["steps"] = self.steps
        out["initial_conditions"] = (
            f"positions uniform in a disc of radius {self.init_radius:g} at the origin, "
            f"velocities uniform in a disc of radius {self.init_speed:g}; "
            f"numpy default_rng({self.base_seed}); the same draw for every swept value"
        )
        out["integrator"] = "semi_implicit_euler"
        return out


def steps_for(duration: float, dt: float) -> int:
    """``round(duration / dt)``, at least 1.

    >>> steps_for(318.0, 0.05)
    6360
    """
    return max(1, round(duration / dt))


def setup_for(setup: RunSetup | None) -> RunSetup:
    """``setup``, or the default :class:`RunSetup` for ``None``."""
    return RunSetup() if setup is None else setup


#: Statistics computed from a trajectory slice ``(x, v)`` shaped ``(T, S, N, d)``.
STATISTICS: dict[str, Callable[[np.ndarray, np.ndarray], np.ndarray]] = {
    "velocity_polarization": lambda x, v: metrics.velocity_polarization(v),
    "polarization": lambda x, v: metrics.polarization(v),
    "spherical_variance": lambda x, v: metrics.spherical_variance(v),
    "velocity_angular_momentum": metrics.velocity_angular_momentum,
    "angular_momentum": metrics.angular_momentum,
    "expanse": lambda x, v: metrics.expanse(x),
    "nearest_neighbor_distance": lambda x, v: metrics.nearest_neighbor_distance(x),
    "mean_speed": lambda x, v: np.sqrt(np.einsum("...k,...k->...", v, v)).mean(axis=-1),
}


def sample_indices(steps: int, max_samples: int) -> np.ndarray:
    """Evenly strided step indices from 0 to ``steps`` inclusive (the end always in).

    >>> sample_indices(10, 4).tolist()
    [0, 3, 6, 9, 10]
    """
    stride = max(1, math.ceil(steps / max_samples))
    idx = np.arange(0, steps + 1, stride)
    if idx[-1] != steps:
        idx = np.append(idx, steps)
    return idx


def run_physics(
    params: SocialPotentialParams,
    x0: np.ndarray,
    v0: np.ndarray,
    *,
    dt: float,
    duration: float,
    goal: Any = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Trajectories ``(xs, vs)`` of :func:`swarm_envs.physics.simulate` over ``duration``."""
    return simulate(params, x0, v0, dt=dt, steps=steps_for(duration, dt), goal=goal)


def series(
    xs: np.ndarray, vs: np.ndarray, idx: np.ndarray, names: Sequence[str]
) -> dict[str, np.ndarray]:
    """Statistics at the sampled steps, each shaped ``(len(idx), seeds)``."""
    x, v = xs[idx], vs[idx]
    return {name: np.asarray(STATISTICS[name](x, v), dtype=np.float64) for name in names}


def summary(values: np.ndarray) -> dict[str, float]:
    """``time_mean``/``final`` (mean over seeds) and their std over seeds."""
    per_seed_mean = values.mean(axis=0)
    return {
        "time_mean": float(per_seed_mean.mean()),
        "time_mean_std": float(per_seed_mean.std()),
        "final": float(values[-1].mean()),
        "final_std": float(values[-1].std()),
    }


def thin(n: int, points: int = SERIES_POINTS) -> np.ndarray:
    """At most ``points`` evenly spaced indices into a length-``n`` axis, ends included.

    >>> thin(10, 4).tolist()
    [0, 3, 6, 9]
    """
    return np.unique(np.rint(np.linspace(0, n - 1, min(n, points))).astype(int))


def sweep_values(name: str, values: Sequence[float]) -> list[float]:
    """``values`` as floats; a sweep needs at least two finite values."""
    out = [float(v) for v in values]
    if len(out) < 2 or not all(math.isfinite(v) for v in out):
        raise ValueError(f"{name} must hold at least two finite values, got {values!r}")
    return out


def sweep(
    param_list: Sequence[SocialPotentialParams],
    setup: RunSetup,
    names: Sequence[str],
) -> dict[str, dict[str, list[float]]]:
    """Run every parameter set from the same initial batch; summary lists per statistic."""
    x0, v0 = setup.initial()
    idx = sample_indices(setup.steps, setup.max_samples)
    out: dict[str, dict[str, list[float]]] = {
        n: {"time_mean": [], "time_mean_std": [], "final": [], "final_std": []} for n in names
    }
    for params in param_list:
        xs, vs = run_physics(params, x0, v0, dt=setup.dt, duration=setup.duration)
        stats = series(xs, vs, idx, names)
        for n in names:
            for key, value in summary(stats[n]).items():
                out[n][key].append(value)
    return out


def params_dict(p: SocialPotentialParams, keys: Sequence[str]) -> dict[str, float]:
    """The named fields of ``p``."""
    return {k: getattr(p, k) for k in keys}
