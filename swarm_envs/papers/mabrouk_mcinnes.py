"""Reproductions of Mabrouk & McInnes' figures 1, 4–5, 6–8, 9, 10 and 11.

Paper: M. H. Mabrouk and C. R. McInnes, *Social potential model to simulate emergent
behaviour for swarm robots* (seeds ``000``/``001``; section 4 and the figure captions).
The model is the reading fixed in ``MODELS.md`` §1 (:mod:`swarm_envs.physics`), the
statistics those of ``MODELS.md`` §2 (:mod:`swarm_envs.metrics`).

Every ``fig*`` function runs the physics for several random seeds at once (leading
batch dimension), and returns a plain, JSON-ready ``dict`` of numbers:

``figure``, ``title``
    identifiers.
``paper``
    what the paper states and the parameters its caption gives.
``setup``
    the choices made where the paper is silent (:class:`RunSetup`).
``x``, ``metrics`` (sweeps)
    the swept values and, per statistic, ``time_mean`` / ``final`` (mean over seeds)
    with ``*_std`` (standard deviation over seeds).
``claims``
    one entry per trend the paper states, per statistic form: what was expected,
    what was observed (:func:`classify_trend`), and whether it ``holds``.
``verdict``
    from the claims on the paper's own statistic forms (``paper_form``):
    ``"reproduced"`` (all hold), ``"partly reproduced"`` or ``"not reproduced"``
    (none holds). Claims on other forms are reported beside them but not counted.

Choices where the paper is silent (the same for every figure, :class:`RunSetup`):

- **Time step and run length.** The paper runs "500 simulation steps (time enough to
  reach the minimum-energy state)" and gives no ``dt``. We read this as 500 steps of
  ``dt = 0.1``, i.e. **50 time units**: with the default ``β = 0.1`` that is five
  e-folding times of the momentum, enough to relax, which is what the sentence claims.
  We integrate those 50 time units with ``dt = 0.05`` (1000 semi-implicit Euler
  steps) because the stiffest settings of the sweeps (``C_o = 1``, ``l_r = 0.1``,
  ``C_r = 3``) need the margin: at the default parameters ``dt = 0.1`` gives the
  same expanse and NND to about 1 %, but at ``l_r = 0.1`` its relaxed expanse is 17 %
  too large, while ``dt = 0.05`` and ``dt = 0.025`` agree to 0.1 %.
- **Initial conditions.** Positions uniform in a disc of radius 2 around the origin,
  velocities uniform in a disc of radius 0.1 (small random velocities), drawn from
  ``numpy.random.default_rng(base_seed)``. The same initial conditions (common random
  numbers) are used for every value of a sweep, so differences along a sweep come from
  the parameter, not from the draw.
- **Seeds.** 8 by default (``RunSetup.seeds``); all statistics are averaged over them.
- **Statistics over time.** Each statistic is reported at the end of the run
  (``final``, t = 50) and averaged over the run (``time_mean``, t ∈ [0, 50], sampled
  every few steps). The paper does not say which it plots; where they differ, both
  are reported and the docs say which one carries the trend.
- **Polarization and angular momentum.** The paper's eq. 2 (``|Σ v_i|/N``) and eq. 3
  (``|Σ r̂_ic × v_i|/N``) scale with the speed: they are
  :func:`~swarm_envs.metrics.velocity_polarization` and
  :func:`~swarm_envs.metrics.velocity_angular_momentum`. The unit-heading (Couzin)
  forms :func:`~swarm_envs.metrics.polarization` and
  :func:`~swarm_envs.metrics.angular_momentum` are reported beside them. Claims on
  the paper's forms carry ``"paper_form": true``.

A structural fact worth knowing when reading the results: the pair forces
(cohesion and alignment) are central and antisymmetric, so they conserve the total
linear and angular momentum; only ``−βv`` changes them. Hence
``Σ v_i(t) = Σ v_i(0) · (1 − β dt)^n ≈ Σ v_i(0) e^{−βt}`` exactly, whatever ``C_o``,
``C``, ``l``: eq. 2 polarization depends only on the initial momentum and on ``β``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from swarm_envs import metrics
from swarm_envs.papers._io import to_jsonable
from swarm_envs.physics import SocialPotentialParams, random_swarm, simulate

__all__ = [
    "DEFAULT_BETAS",
    "DEFAULT_C_OS",
    "DEFAULT_C_RATIOS",
    "DEFAULT_L_RATIOS",
    "FIGURES",
    "NAV_GOAL",
    "NAV_SNAPSHOT_TIMES",
    "PAPER",
    "RELAX_SPEED",
    "FigureSpec",
    "RunSetup",
    "classify_trend",
    "fig1_polarization_vs_beta",
    "fig4_5_variance_and_angular_momentum",
    "fig6_8_alignment_sweep",
    "fig9_range_ratio_sweep",
    "fig10_amplitude_ratio_sweep",
    "fig11_navigation",
    "plot_fig1",
    "plot_fig4_5",
    "plot_fig6_8",
    "plot_fig9",
    "plot_fig10",
    "plot_fig11",
    "to_jsonable",
    "write_fig11_gif",
]

PAPER = (
    "M. H. Mabrouk and C. R. McInnes, Social potential model to simulate emergent "
    "behaviour for swarm robots"
)

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

_SERIES_POINTS = 101  # time-series points written to JSON per curve


# --------------------------------------------------------------------------- setup


@dataclass(frozen=True)
class RunSetup:
    """The choices the paper leaves open, shared by every figure.

    Attributes:
        n_agents: swarm size N (paper: 30 for Figs. 1–10).
        seeds: number of random initial conditions averaged over.
        dt: integration step (semi-implicit Euler).
        duration: run length in time units (the paper's "500 steps", read as
            500 × 0.1; see the module docstring).
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
    """``round(duration / dt)``, at least 1."""
    return max(1, round(duration / dt))


# --------------------------------------------------------------------------- helpers


#: Statistics computed from a trajectory slice ``(x, v)`` shaped ``(T, S, N, d)``.
_STATISTICS: dict[str, Callable[[np.ndarray, np.ndarray], np.ndarray]] = {
    "velocity_polarization": lambda x, v: metrics.velocity_polarization(v),
    "polarization": lambda x, v: metrics.polarization(v),
    "spherical_variance": lambda x, v: metrics.spherical_variance(v),
    "velocity_angular_momentum": metrics.velocity_angular_momentum,
    "angular_momentum": metrics.angular_momentum,
    "expanse": lambda x, v: metrics.expanse(x),
    "nearest_neighbor_distance": lambda x, v: metrics.nearest_neighbor_distance(x),
    "mean_speed": lambda x, v: np.sqrt(np.einsum("...k,...k->...", v, v)).mean(axis=-1),
}

_LABELS = {
    "velocity_polarization": "polarization |Σv|/N (eq. 2)",
    "polarization": "polarization |Σv̂|/N (unit headings)",
    "spherical_variance": "spherical variance 1 − |Σv̂|/N (eq. 4)",
    "velocity_angular_momentum": "angular momentum |Σr̂×v|/N (eq. 3)",
    "angular_momentum": "angular momentum |Σr̂×v̂|/N (unit headings)",
    "expanse": "expanse (mean distance to centre)",
    "nearest_neighbor_distance": "average NND (eq. 5)",
    "mean_speed": "mean speed",
}


def _sample_indices(steps: int, max_samples: int) -> np.ndarray:
    """Evenly strided step indices from 0 to ``steps`` inclusive (the end always in)."""
    stride = max(1, math.ceil(steps / max_samples))
    idx = np.arange(0, steps + 1, stride)
    if idx[-1] != steps:
        idx = np.append(idx, steps)
    return idx


def _run(
    params: SocialPotentialParams,
    x0: np.ndarray,
    v0: np.ndarray,
    *,
    dt: float,
    duration: float,
    goal: Any = None,
) -> tuple[np.ndarray, np.ndarray]:
    return simulate(params, x0, v0, dt=dt, steps=steps_for(duration, dt), goal=goal)


def _series(
    xs: np.ndarray, vs: np.ndarray, idx: np.ndarray, names: Sequence[str]
) -> dict[str, np.ndarray]:
    """Statistics at the sampled steps, each shaped ``(len(idx), seeds)``."""
    x, v = xs[idx], vs[idx]
    return {name: np.asarray(_STATISTICS[name](x, v), dtype=np.float64) for name in names}


def _summary(series: np.ndarray) -> dict[str, float]:
    """``time_mean``/``final`` (mean over seeds) and their std over seeds."""
    per_seed_mean = series.mean(axis=0)
    return {
        "time_mean": float(per_seed_mean.mean()),
        "time_mean_std": float(per_seed_mean.std()),
        "final": float(series[-1].mean()),
        "final_std": float(series[-1].std()),
    }


def _thin(n: int, points: int = _SERIES_POINTS) -> np.ndarray:
    """At most ``points`` evenly spaced indices into a length-``n`` axis, ends included."""
    return np.unique(np.rint(np.linspace(0, n - 1, min(n, points))).astype(int))


def _spearman(x: np.ndarray, y: np.ndarray) -> float:
    """Spearman rank correlation (no ties expected; 0 for a constant input)."""
    rx = np.argsort(np.argsort(x)).astype(np.float64)
    ry = np.argsort(np.argsort(y)).astype(np.float64)
    rx -= rx.mean()
    ry -= ry.mean()
    den = math.sqrt(float((rx * rx).sum() * (ry * ry).sum()))
    return float((rx * ry).sum() / den) if den > 0 else 0.0


def classify_trend(
    x: Sequence[float],
    y: Sequence[float],
    *,
    flat_tol: float = 0.05,
    rho_min: float = 0.8,
) -> dict[str, Any]:
    """Direction of ``y`` along ``x``: increasing, decreasing, flat or non-monotonic.

    ``increasing``/``decreasing`` when the Spearman rank correlation is at least
    ``rho_min`` in size (however small the change: the paper's "slowly increases"
    counts; ``relative_change`` says how much), ``flat`` when it is not but the spread
    ``max y − min y`` is below ``flat_tol`` times ``max |y|`` (or ``y`` is constant
    to 1e-9), else ``non-monotonic``.

    Returns ``{"direction", "spearman", "relative_change"}``, the last being
    ``(y[-1] − y[0]) / max |y|``.

    >>> classify_trend([1, 2, 3, 4], [0.1, 0.2, 0.25, 0.4])["direction"]
    'increasing'
    >>> classify_trend([1, 2, 3], [1.0, 1.01, 0.99])["direction"]
    'flat'
    """
    xa = np.asarray(x, dtype=np.float64)
    ya = np.asarray(y, dtype=np.float64)
    if xa.shape != ya.shape or xa.ndim != 1 or xa.size < 2:
        raise ValueError(
            "classify_trend needs two 1-D sequences of equal length >= 2, "
            f"got shapes {xa.shape} and {ya.shape}"
        )
    scale = float(np.max(np.abs(ya)))
    spread = float(ya.max() - ya.min())
    rho = _spearman(xa, ya)
    rel = float((ya[-1] - ya[0]) / scale) if scale > 0 else 0.0
    if scale == 0 or spread <= 1e-9 * scale:
        direction = "flat"
    elif rho >= rho_min:
        direction = "increasing"
    elif rho <= -rho_min:
        direction = "decreasing"
    elif spread < flat_tol * scale:
        direction = "flat"
    else:
        direction = "non-monotonic"
    return {"direction": direction, "spearman": rho, "relative_change": rel}


def _trend_claim(
    statement: str,
    x: Sequence[float],
    y: Sequence[float],
    *,
    measure: str,
    statistic: str,
    expected: str,
    paper_form: bool,
) -> dict[str, Any]:
    trend = classify_trend(x, y)
    return {
        "claim": statement,
        "measure": measure,
        "statistic": statistic,
        "expected": expected,
        "observed": trend["direction"],
        "spearman": trend["spearman"],
        "relative_change": trend["relative_change"],
        "holds": trend["direction"] == expected,
        "paper_form": paper_form,
    }


def _verdict(claims: Sequence[dict[str, Any]]) -> str:
    """From the claims on the paper's own statistic forms (``paper_form``)."""
    held = [bool(c["holds"]) for c in claims if c["paper_form"]]
    if held and all(held):
        return "reproduced"
    if any(held):
        return "partly reproduced"
    return "not reproduced"


def _sweep_values(name: str, values: Sequence[float]) -> list[float]:
    """``values`` as floats; a sweep needs at least two finite values."""
    out = [float(v) for v in values]
    if len(out) < 2 or not all(math.isfinite(v) for v in out):
        raise ValueError(f"{name} must hold at least two finite values, got {values!r}")
    return out


def _setup_for(setup: RunSetup | None) -> RunSetup:
    return RunSetup() if setup is None else setup


def _sweep(
    param_list: Sequence[SocialPotentialParams],
    setup: RunSetup,
    names: Sequence[str],
) -> dict[str, dict[str, list[float]]]:
    """Run every parameter set from the same initial batch; summary lists per statistic."""
    x0, v0 = setup.initial()
    idx = _sample_indices(setup.steps, setup.max_samples)
    out: dict[str, dict[str, list[float]]] = {
        n: {"time_mean": [], "time_mean_std": [], "final": [], "final_std": []} for n in names
    }
    for params in param_list:
        xs, vs = _run(params, x0, v0, dt=setup.dt, duration=setup.duration)
        series = _series(xs, vs, idx, names)
        for n in names:
            for key, value in _summary(series[n]).items():
                out[n][key].append(value)
    return out


def _params_dict(p: SocialPotentialParams, keys: Sequence[str]) -> dict[str, float]:
    return {k: getattr(p, k) for k in keys}


_COHESION_KEYS = ("C_a", "C_r", "l_a", "l_r", "C_o", "l_o", "beta", "m")


# --------------------------------------------------------------------------- Fig. 1


def fig1_polarization_vs_beta(
    betas: Sequence[float] = DEFAULT_BETAS, *, setup: RunSetup | None = None
) -> dict[str, Any]:
    """Fig. 1: group polarization against the dissipation coefficient β.

    **Paper.** "Higher dissipation will lead to a lower polarization"; "β = 0.1
    [is] the workable value of dissipation before a rapid leak of the system's energy".
    Caption parameters: ``C_a = 1, C_r = 1.2, C_o = 0.1, l_a = 1, l_r = 0.2,
    l_o = 1.5, m = 1`` (N = 30 from the text), β swept; polarization is eq. 2,
    ``|Σ v_i|/N``.

    **Here.** β in :data:`DEFAULT_BETAS` (the paper's values are not legible), all
    other parameters the caption's; :class:`RunSetup` for ``dt``, run length and
    initial conditions. Reported per β: eq. 2 and unit-heading polarization
    (``time_mean``, ``final``), the mean speed at the end, whether the swarm relaxed
    (final mean speed below :data:`RELAX_SPEED`), and the fitted decay rate of the
    total momentum, which the model fixes at ``−ln(1 − β dt)/dt ≈ β`` (so eq. 2
    polarization is the initial one times ``e^{−βt}``, independent of everything else).
    """
    setup = _setup_for(setup)
    betas = _sweep_values("betas", betas)
    base = SocialPotentialParams()
    x0, v0 = setup.initial()
    idx = _sample_indices(setup.steps, setup.max_samples)
    names = ("velocity_polarization", "polarization", "mean_speed")
    stats: dict[str, dict[str, list[float]]] = {
        n: {"time_mean": [], "time_mean_std": [], "final": [], "final_std": []} for n in names
    }
    curves: dict[str, list[list[float]]] = {n: [] for n in names[:2]}
    thin = _thin(idx.size)
    decay_rates: list[float] = []
    for beta in betas:
        xs, vs = _run(replace(base, beta=beta), x0, v0, dt=setup.dt, duration=setup.duration)
        series = _series(xs, vs, idx, names)
        for n in names:
            for key, value in _summary(series[n]).items():
                stats[n][key].append(value)
        for n in curves:
            curves[n].append(series[n].mean(axis=1)[thin].tolist())
        # Fit window: until the momentum would have fallen by 1e-8 (below that the
        # rounding noise of a sum of N velocities dominates).
        n_fit = setup.steps
        if beta > 0:
            n_fit = min(n_fit, max(1, int(math.log(1e8) / -math.log1p(-min(beta * setup.dt, 0.5)))))
        total = vs[[0, n_fit]].sum(axis=-2)
        momentum = np.sqrt(np.einsum("...k,...k->...", total, total))
        ok = (momentum[0] > 0) & (momentum[1] > 0)
        rate = -np.log(momentum[1][ok] / momentum[0][ok]) / (n_fit * setup.dt)
        decay_rates.append(float(np.mean(rate)) if rate.size else float("nan"))
    relaxed = [s < RELAX_SPEED for s in stats["mean_speed"]["final"]]
    claims = [
        _trend_claim(
            "higher dissipation leads to lower polarization (Fig. 1)",
            betas,
            stats["velocity_polarization"][stat],
            measure="velocity_polarization",
            statistic=stat,
            expected="decreasing",
            paper_form=True,
        )
        for stat in ("time_mean", "final")
    ] + [
        _trend_claim(
            "higher dissipation leads to lower polarization (Fig. 1)",
            betas,
            stats["polarization"][stat],
            measure="polarization",
            statistic=stat,
            expected="decreasing",
            paper_form=False,
        )
        for stat in ("time_mean", "final")
    ]
    relaxed_betas = [b for b, r in zip(betas, relaxed, strict=True) if r]
    return {
        "figure": "fig1",
        "title": "Polarization vs dissipation β",
        "paper": {
            "claim": "higher β gives lower polarization; β ≈ 0.1 is the workable value",
            "parameters": _params_dict(base, [k for k in _COHESION_KEYS if k != "beta"])
            | {"N": setup.n_agents},
        },
        "setup": setup.as_dict(),
        "x": {"name": "beta", "values": betas},
        "metrics": stats,
        "relaxed": relaxed,
        "smallest_relaxed_beta": min(relaxed_betas) if relaxed_betas else None,
        "momentum_decay_rate": decay_rates,
        "momentum_decay_rate_expected": [
            -math.log(1 - b * setup.dt) / setup.dt if b * setup.dt < 1 else float("nan")
            for b in betas
        ],
        "time_series": {"t": (idx[thin] * setup.dt).tolist(), **curves},
        "claims": claims,
        "verdict": _verdict(claims),
    }


# --------------------------------------------------------------------------- Fig. 4–5


def _settle_time(ok: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Per column of ``ok`` (time first), the time from which it stays true to the end.

    ``inf`` for a column that is false at the last sample.
    """
    stays = np.flip(np.logical_and.accumulate(np.flip(ok, axis=0), axis=0), axis=0)
    return np.where(stays[-1], t[stays.argmax(axis=0)], np.inf)


def _median_time(times: np.ndarray) -> float:
    """Median over seeds, ``inf`` if more than half never got there."""
    return float(np.median(times))


def fig4_5_variance_and_angular_momentum(
    betas: Sequence[float] = (0.01, 1.8), *, setup: RunSetup | None = None
) -> dict[str, Any]:
    """Figs. 4–5: spherical variance and angular momentum against time, β = 0.01 and 1.8.

    **Paper.** With the larger β the speeds fall, "the value of spherical variance
    approaches unity very soon" and "the group angular momentum decreases rapidly
    with time until reaching zero". Caption parameters: ``C_a = 1, C_r = 1.2,
    C_o = 0.1, l_a = 1, l_r = 0.2, l_o = 1.5, m = 1``, β = 0.01 (Fig. 4) and 1.8
    (Fig. 5). Spherical variance is eq. 4 (needs unit headings), angular momentum
    eq. 3 (speed-weighted).

    **Here.** :class:`RunSetup` (50 time units). Per β: the seed-mean time series of
    spherical variance, eq. 3 and unit-heading angular momentum and mean speed; the
    median over seeds of the time from which the spherical variance stays at or above
    0.9 to the end of the run (``t_sigma_settle_0.9``, ``None``/inf if it never
    settles), of the time from which eq. 3 angular momentum stays below 10 % of its
    peak (``t_L_10pct``), and the run-mean and end values. (The *first* time
    σ reaches 0.9 says nothing: random initial headings and the radial collapse give
    σ ≈ 0.9–1 at the start for every β.) With β = 0.01 the swarm
    is far from relaxed after 50 time units (momentum ``e^{−0.5}`` of the start).
    """
    setup = _setup_for(setup)
    betas = _sweep_values("betas", betas)
    base = SocialPotentialParams()
    x0, v0 = setup.initial()
    idx = _sample_indices(setup.steps, setup.max_samples)
    t = idx * setup.dt
    thin = _thin(idx.size)
    names = ("spherical_variance", "velocity_angular_momentum", "angular_momentum", "mean_speed")
    per_beta: list[dict[str, Any]] = []
    for beta in betas:
        xs, vs = _run(replace(base, beta=beta), x0, v0, dt=setup.dt, duration=setup.duration)
        series = _series(xs, vs, idx, names)
        sigma_t = _settle_time(series["spherical_variance"] >= 0.9, t)
        lam = series["velocity_angular_momentum"]
        l_t = _settle_time(lam <= 0.1 * lam.max(axis=0, keepdims=True), t)
        entry: dict[str, Any] = {
            "beta": beta,
            "t_sigma_settle_0.9": _median_time(sigma_t),
            "t_L_10pct": _median_time(l_t),
            "summary": {n: _summary(series[n]) for n in names},
            "series_mean": {n: series[n].mean(axis=1)[thin].tolist() for n in names},
            "series_std": {n: series[n].std(axis=1)[thin].tolist() for n in names},
        }
        per_beta.append(entry)
    lo, hi = per_beta[0], per_beta[-1]

    def sooner(a: float, b: float) -> bool:
        return a < b or (math.isfinite(a) and not math.isfinite(b))

    def comparison(statement: str, measure: str, statistic: str, holds: bool, obs: str):
        return {
            "claim": statement,
            "measure": measure,
            "statistic": statistic,
            "expected": f"β = {hi['beta']:g} below/sooner than β = {lo['beta']:g}",
            "observed": obs,
            "holds": bool(holds),
            "paper_form": True,
        }

    s_lo, s_hi = lo["t_sigma_settle_0.9"], hi["t_sigma_settle_0.9"]
    sm_lo = lo["summary"]["spherical_variance"]["time_mean"]
    sm_hi = hi["summary"]["spherical_variance"]["time_mean"]
    l_lo = lo["summary"]["velocity_angular_momentum"]["final"]
    l_hi = hi["summary"]["velocity_angular_momentum"]["final"]
    tl_lo, tl_hi = lo["t_L_10pct"], hi["t_L_10pct"]
    sv_hi = hi["summary"]["spherical_variance"]["final"]
    claims = [
        comparison(
            "higher β: spherical variance approaches 1 very soon",
            "spherical_variance",
            "time from which σ stays ≥ 0.9; run mean; final",
            sooner(s_hi, s_lo) and sm_hi > sm_lo and sv_hi >= 0.9,
            f"settles at t = {s_hi:.3g} (β = {hi['beta']:g}) vs {s_lo:.3g} "
            f"(β = {lo['beta']:g}); run mean {sm_hi:.3g} vs {sm_lo:.3g}; "
            f"final σ = {sv_hi:.3g}",
        ),
        comparison(
            "higher β: angular momentum decreases rapidly to zero",
            "velocity_angular_momentum",
            "time from which L stays < 10 % of its peak; final",
            sooner(tl_hi, tl_lo) and l_hi < l_lo,
            f"t = {tl_hi:.3g} vs {tl_lo:.3g}; final {l_hi:.3g} vs {l_lo:.3g}",
        ),
    ]
    return {
        "figure": "fig4_5",
        "title": "Spherical variance and angular momentum vs time",
        "paper": {
            "claim": "high β: spherical variance → 1 soon, angular momentum → 0 rapidly",
            "parameters": _params_dict(base, [k for k in _COHESION_KEYS if k != "beta"])
            | {"beta": betas, "N": setup.n_agents},
        },
        "setup": setup.as_dict(),
        "t": t[thin].tolist(),
        "runs": per_beta,
        "claims": claims,
        "verdict": _verdict(claims),
    }


# --------------------------------------------------------------------------- Fig. 6–8


def fig6_8_alignment_sweep(
    c_os: Sequence[float] = DEFAULT_C_OS, *, setup: RunSetup | None = None
) -> dict[str, Any]:
    """Figs. 6–8: angular momentum, polarization, expanse and NND against ``C_o``.

    **Paper.** As ``C_o`` increases the angular momentum "noticeably increases"
    (Fig. 6), the polarization decreases (Fig. 7), and the expanse and average NND
    "slowly increase" (Fig. 8, centrifugal action). Caption parameters: ``l_r = 0.2,
    l_a = 1, C_r = 1.2, C_a = 1, β = 0.1`` (``l_o = 1.5``, ``m = 1``, N = 30).

    **Here.** ``C_o`` in :data:`DEFAULT_C_OS`; :class:`RunSetup`. Both statistic forms
    and both ``time_mean`` and ``final`` are reported and tested. Expect: eq. 2
    polarization is *exactly* the same for every ``C_o`` (alignment conserves
    momentum); the relaxed end state (``final`` expanse/NND) is the same minimum-
    energy cluster for every ``C_o``; alignment slows the collapse, so the run-averaged
    expanse and NND grow with ``C_o``.
    """
    setup = _setup_for(setup)
    c_os = _sweep_values("c_os", c_os)
    base = SocialPotentialParams()
    names = (
        "velocity_angular_momentum",
        "angular_momentum",
        "velocity_polarization",
        "polarization",
        "expanse",
        "nearest_neighbor_distance",
    )
    stats = _sweep([replace(base, C_o=c) for c in c_os], setup, names)
    plan = [
        ("Fig. 6: angular momentum increases with C_o", "velocity_angular_momentum",
         "increasing", True),
        ("Fig. 6: angular momentum increases with C_o", "angular_momentum", "increasing", False),
        ("Fig. 7: polarization decreases with C_o", "velocity_polarization", "decreasing", True),
        ("Fig. 7: polarization decreases with C_o", "polarization", "decreasing", False),
        ("Fig. 8: expanse slowly increases with C_o", "expanse", "increasing", True),
        ("Fig. 8: average NND slowly increases with C_o", "nearest_neighbor_distance",
         "increasing", True),
    ]  # fmt: skip
    claims = [
        _trend_claim(
            text,
            c_os,
            stats[measure][stat],
            measure=measure,
            statistic=stat,
            expected=expected,
            paper_form=paper_form,
        )
        for text, measure, expected, paper_form in plan
        for stat in ("time_mean", "final")
    ]
    # C_o = 0 is a different regime (nothing damps the relative motion but β, so the
    # collapsed cluster keeps vibrating); the same run-mean trends over C_o > 0 only:
    positive = [k for k, c in enumerate(c_os) if c > 0]
    if len(positive) >= 2:
        claims += [
            _trend_claim(
                f"{text} (C_o > 0 only)",
                [c_os[k] for k in positive],
                [stats[measure]["time_mean"][k] for k in positive],
                measure=measure,
                statistic="time_mean",
                expected=expected,
                paper_form=False,
            )
            for text, measure, expected, _ in plan
        ]
    return {
        "figure": "fig6_8",
        "title": "Alignment strength C_o sweep",
        "paper": {
            "claim": "C_o up: angular momentum up, polarization down, expanse and NND slowly up",
            "parameters": _params_dict(base, [k for k in _COHESION_KEYS if k != "C_o"])
            | {"N": setup.n_agents},
        },
        "setup": setup.as_dict(),
        "x": {"name": "C_o", "values": c_os},
        "metrics": stats,
        "claims": claims,
        "verdict": _verdict(claims),
    }


# --------------------------------------------------------------------------- Fig. 9–10


def _ratio_claims(
    fig: str, x: Sequence[float], series: dict[str, Any], label: str, primary: bool
) -> list[dict[str, Any]]:
    return [
        _trend_claim(
            f"{fig}: {measure} increases with the ratio ({label})",
            x,
            series[measure]["final"],
            measure=measure,
            statistic="final",
            expected="increasing",
            paper_form=primary,
        )
        for measure in ("expanse", "nearest_neighbor_distance")
    ]


def fig9_range_ratio_sweep(
    ratios: Sequence[float] = DEFAULT_L_RATIOS, *, setup: RunSetup | None = None
) -> dict[str, Any]:
    """Fig. 9: group expanse and average NND against the range ratio ``l = l_r / l_a``.

    **Paper.** As ``l`` increases, "which can be due to either l_r increasing and/or
    l_a decreasing", the expanse and NND increase: a more dispersed group. Caption
    parameters: ``C_r = 1.2, C_a = 1, β = 0.1`` (``C_o = 0.1``, ``l_o = 1.5``, N = 30).

    **Here.** Two series over ``l`` in :data:`DEFAULT_L_RATIOS`: ``vary_l_r``
    (``l_a = 1``, ``l_r = l``; the primary one, the paper's defaults have ``l_a = 1``)
    and ``vary_l_a`` (``l_r = 0.2``, ``l_a = 0.2 / l``). The equilibrium shape depends
    on ``C`` and ``l`` only and its size scales with ``l_a``, so the second series is
    also reported in units of ``l_a`` (``expanse_over_l_a``). Claims use the relaxed
    end state (``final``). ``C·l²`` (H-stability, > 1 needed in 2-D) is listed per
    point: every point is in the collapsing regime.
    """
    setup = _setup_for(setup)
    ratios = _sweep_values("ratios", ratios)
    base = SocialPotentialParams()
    names = ("expanse", "nearest_neighbor_distance")
    vary_l_r = _sweep([replace(base, l_a=1.0, l_r=r) for r in ratios], setup, names)
    l_as = [base.l_r / r for r in ratios]
    vary_l_a = _sweep([replace(base, l_a=la) for la in l_as], setup, names)
    scaled = {
        f"{n}_over_l_a": {
            k: [v / la for v, la in zip(vary_l_a[n][k], l_as, strict=True)]
            for k in ("time_mean", "final", "time_mean_std", "final_std")
        }
        for n in names
    }
    vary_l_a.update(scaled)
    claims = _ratio_claims("Fig. 9", ratios, vary_l_r, "l_r varied, l_a = 1", True)
    claims += _ratio_claims("Fig. 9", ratios, vary_l_a, "l_a varied, l_r = 0.2", False)
    claims.append(
        _trend_claim(
            "Fig. 9: expanse in units of l_a increases with the ratio (l_a varied)",
            ratios,
            vary_l_a["expanse_over_l_a"]["final"],
            measure="expanse_over_l_a",
            statistic="final",
            expected="increasing",
            paper_form=False,
        )
    )
    return {
        "figure": "fig9",
        "title": "Range ratio l = l_r/l_a sweep",
        "paper": {
            "claim": "expanse and average NND increase with l = l_r/l_a",
            "parameters": _params_dict(base, ("C_a", "C_r", "C_o", "l_o", "beta", "m"))
            | {"N": setup.n_agents},
        },
        "setup": setup.as_dict(),
        "x": {"name": "l = l_r/l_a", "values": ratios},
        "h_stability": [base.amplitude_ratio * r * r for r in ratios],
        "series": {"vary_l_r": vary_l_r, "vary_l_a": vary_l_a},
        "series_parameters": {
            "vary_l_r": {"l_a": 1.0, "l_r": ratios},
            "vary_l_a": {"l_r": base.l_r, "l_a": l_as},
        },
        "claims": claims,
        "verdict": _verdict(claims),
    }


def fig10_amplitude_ratio_sweep(
    ratios: Sequence[float] = DEFAULT_C_RATIOS, *, setup: RunSetup | None = None
) -> dict[str, Any]:
    """Fig. 10: group expanse and average NND against the amplitude ratio ``C = C_r/C_a``.

    **Paper.** "When the values of C increase so does the value of group expanse and
    average NND's." Caption parameters: ``l_r = 0.2, l_a = 1, β = 0.1`` (``C_o = 0.1``,
    ``l_o = 1.5``, N = 30).

    **Here.** Two series over ``C`` in :data:`DEFAULT_C_RATIOS`: ``vary_C_r``
    (``C_a = 1``, ``C_r = C``; primary) and ``vary_C_a`` (``C_r = 1.2``,
    ``C_a = 1.2 / C``). Both have the same equilibria (only ``C`` matters to the
    minimum-energy shape; the amplitudes also set the time scale, so the transients
    differ). Claims use the relaxed end state (``final``).
    """
    setup = _setup_for(setup)
    ratios = _sweep_values("ratios", ratios)
    base = SocialPotentialParams()
    names = ("expanse", "nearest_neighbor_distance")
    vary_c_r = _sweep([replace(base, C_a=1.0, C_r=c) for c in ratios], setup, names)
    c_as = [base.C_r / c for c in ratios]
    vary_c_a = _sweep([replace(base, C_a=ca) for ca in c_as], setup, names)
    claims = _ratio_claims("Fig. 10", ratios, vary_c_r, "C_r varied, C_a = 1", True)
    claims += _ratio_claims("Fig. 10", ratios, vary_c_a, "C_a varied, C_r = 1.2", True)
    return {
        "figure": "fig10",
        "title": "Amplitude ratio C = C_r/C_a sweep",
        "paper": {
            "claim": "expanse and average NND increase with C = C_r/C_a",
            "parameters": _params_dict(base, ("l_a", "l_r", "C_o", "l_o", "beta", "m"))
            | {"N": setup.n_agents},
        },
        "setup": setup.as_dict(),
        "x": {"name": "C = C_r/C_a", "values": ratios},
        "h_stability": [c * base.range_ratio**2 for c in ratios],
        "series": {"vary_C_r": vary_c_r, "vary_C_a": vary_c_a},
        "series_parameters": {
            "vary_C_r": {"C_a": 1.0, "C_r": ratios},
            "vary_C_a": {"C_r": base.C_r, "C_a": c_as},
        },
        "claims": claims,
        "verdict": _verdict(claims),
    }


# --------------------------------------------------------------------------- Fig. 11


def _fig11_initial(setup: RunSetup, n_agents: int) -> tuple[np.ndarray, np.ndarray]:
    return setup.initial(n_agents=n_agents)


def fig11_navigation(
    *,
    setup: RunSetup | None = None,
    goal: Sequence[float] = NAV_GOAL,
    duration: float = 318.0,
    snapshot_times: Sequence[float] = NAV_SNAPSHOT_TIMES,
    goal_radius: float = 1.0,
    n_agents: int = 31,
) -> dict[str, Any]:
    """Fig. 11: a swarm in a "vortex like shape pattern" approaching a potential sink.

    **Paper.** N = 31, ``C_g = 15, l_g = 5, C_a = 1, C_r = 1, C_o = 0.7, l_a = 1,
    l_r = 0.2, l_o = 1.5, m = 1, β = 1``
    (:meth:`SocialPotentialParams.navigation`); snapshots at t = 0, 28, 86, 135, 204,
    318 (seed 001; seed 000 lists 0, 28, 86, 318). No goal position, start region or
    time unit is given.

    **Here.** The goal force is the gradient of eq. 19 (unit vector, range ``l_g``;
    MODELS.md §1), not the printed eq. 21. Start: :class:`RunSetup`'s disc of radius 2
    at the origin with 31 agents; goal :data:`NAV_GOAL`, 25 length units away, chosen
    so that the approach (drift speed ``(C_g/l_g) e^{−D/l_g}/β`` at distance D) fills
    the paper's t = 0…318 window when t is read in time units; ``dt`` from the setup
    (6360 steps). Reported: first-passage times (centroid within ``goal_radius``,
    first agent within it, 90 % of agents within it; median over seeds), the
    statistics at the snapshot times (seed means), the mean unit-heading angular
    momentum during the approach (t from 5 to arrival; 1 for a rotating ring, about
    ``1/√N ≈ 0.18`` for random headings) as the vortex indicator, and seed 0's
    positions at the snapshots (for the figure).
    """
    setup = _setup_for(setup)
    params = SocialPotentialParams.navigation()
    g = np.asarray(goal, dtype=np.float64)
    x0, v0 = _fig11_initial(setup, n_agents)
    steps = steps_for(duration, setup.dt)
    xs, vs = _run(params, x0, v0, dt=setup.dt, duration=duration, goal=g)
    t_all = np.arange(steps + 1) * setup.dt
    centroid_dist = np.linalg.norm(metrics.centroid(xs) - g, axis=-1)  # (T, S)
    agent_dist = np.linalg.norm(xs - g, axis=-1)  # (T, S, N)
    frac = metrics.fraction_within(xs, g, goal_radius)  # (T, S)
    t_centroid = metrics.first_passage_time(centroid_dist, setup.dt, goal_radius)
    t_first = metrics.first_passage_time(agent_dist.min(axis=-1), setup.dt, goal_radius)
    t_90 = metrics.first_passage_time(frac, setup.dt, 0.9, below=False)

    idx = _sample_indices(steps, setup.max_samples * 2)
    names = (
        "angular_momentum",
        "velocity_angular_momentum",
        "polarization",
        "expanse",
        "nearest_neighbor_distance",
        "mean_speed",
    )
    series = _series(xs, vs, idx, names)
    t = idx * setup.dt
    arrival = np.where(np.isfinite(t_centroid), t_centroid, duration)
    approach = (t[:, None] >= min(5.0, duration / 2)) & (t[:, None] <= arrival[None, :])
    am = series["angular_momentum"]
    vortex = [
        float(am[approach[:, s], s].mean()) if approach[:, s].any() else float("nan")
        for s in range(am.shape[1])
    ]

    snaps = [float(s) for s in snapshot_times if s <= duration + 1e-9]
    snap_idx = [min(steps, round(s / setup.dt)) for s in snaps]
    snap_stats = _series(xs, vs, np.asarray(snap_idx), names)
    snapshot_metrics = {n: snap_stats[n].mean(axis=1).tolist() for n in names}
    snapshot_metrics["centroid_distance"] = centroid_dist[snap_idx].mean(axis=1).tolist()
    snapshot_metrics["fraction_within"] = frac[snap_idx].mean(axis=1).tolist()

    thin = _thin(t_all.size, 2 * _SERIES_POINTS)
    reached = np.isfinite(t_centroid)
    vortex_mean = float(np.nanmean(vortex)) if np.isfinite(vortex).any() else float("nan")
    claims = [
        {
            "claim": "the swarm approaches and reaches the potential sink at G",
            "measure": "centroid distance to G",
            "statistic": f"centroid within {goal_radius:g} by t = {duration:g}",
            "expected": "all seeds",
            "observed": f"{int(reached.sum())}/{reached.size} seeds",
            "holds": bool(reached.all()),
            "paper_form": True,
        },
        {
            "claim": "the swarm moves in a vortex-like pattern while approaching",
            "measure": "angular_momentum",
            "statistic": "mean during the approach",
            "expected": "> 0.5 (rotating ring ≈ 1, random headings ≈ 0.18)",
            "observed": f"{vortex_mean:.3g}",
            "holds": bool(vortex_mean > 0.5),
            "paper_form": True,
        },
    ]
    return {
        "figure": "fig11",
        "title": "Navigation to a potential sink (N = 31)",
        "paper": {
            "claim": "a swarm in a vortex-like pattern approaching a potential sink at G",
            "parameters": asdict(params) | {"N": n_agents},
            "snapshot_times": list(NAV_SNAPSHOT_TIMES),
        },
        "setup": setup.as_dict() | {"n_agents": n_agents, "duration": duration, "steps": steps},
        "goal": g.tolist(),
        "start_distance": float(np.linalg.norm(g)),
        "goal_radius": goal_radius,
        "first_passage": {
            "centroid_within_radius": {
                "median": float(np.median(t_centroid)),
                "per_seed": t_centroid.tolist(),
            },
            "first_agent_within_radius": {
                "median": float(np.median(t_first)),
                "per_seed": t_first.tolist(),
            },
            "ninety_percent_within_radius": {
                "median": float(np.median(t_90)),
                "per_seed": t_90.tolist(),
            },
        },
        "reached_fraction": float(reached.mean()),
        "vortex_indicator": {"mean": vortex_mean, "per_seed": vortex},
        "snapshots": {
            "t": snaps,
            "metrics": snapshot_metrics,
            "positions_seed0": xs[snap_idx, 0].tolist(),
            "velocities_seed0": vs[snap_idx, 0].tolist(),
        },
        "time_series": {
            "t": t_all[thin].tolist(),
            "centroid_distance": centroid_dist[thin].mean(axis=1).tolist(),
            "centroid_distance_per_seed": centroid_dist[thin].T.tolist(),
            "fraction_within": frac[thin].mean(axis=1).tolist(),
            "centroid_path_seed0": metrics.centroid(xs[thin, 0]).tolist(),
        },
        "sampled_series": {
            "t": t[_thin(t.size)].tolist(),
            **{n: series[n].mean(axis=1)[_thin(t.size)].tolist() for n in names},
        },
        "claims": claims,
        "verdict": _verdict(claims),
    }


def write_fig11_gif(
    path: str | Path,
    *,
    setup: RunSetup | None = None,
    goal: Sequence[float] = NAV_GOAL,
    duration: float = 318.0,
    goal_radius: float = 1.0,
    n_agents: int = 31,
    frames: int = 64,
    size: tuple[int, int] = (300, 300),
    fps: float = 12,
) -> Path:
    """GIF of seed 0 of :func:`fig11_navigation` (same initial condition, re-simulated).

    The view is centred between the swarm's centroid and the goal and zooms in as the
    swarm approaches (half-width ``0.6·distance + 1.5``), so that the goal stays in
    view and the swarm's shape becomes visible near the sink. The ``frames`` frames
    are spaced evenly in a progress variable that mixes elapsed time and distance
    covered (half each), so the slow far-away drift does not take up the whole
    animation; each frame has a trail of the previous four frames' positions.
    """
    from swarm_envs.render import Viewport, draw_swarm, write_gif

    setup = _setup_for(setup)
    g = np.asarray(goal, dtype=np.float64)
    x0, v0 = _fig11_initial(setup, n_agents)
    xs, _ = _run(
        SocialPotentialParams.navigation(), x0[0], v0[0], dt=setup.dt, duration=duration, goal=g
    )
    centres = xs.mean(axis=1)
    dist = np.linalg.norm(centres - g, axis=-1)
    covered = np.maximum.accumulate(dist[0] - dist)
    span = max(float(covered[-1]), 1e-12)
    progress = 0.5 * np.arange(dist.size) / max(1, dist.size - 1) + 0.5 * covered / span
    pick = np.unique(np.searchsorted(progress, np.linspace(0.0, progress[-1], frames)))
    pick = np.minimum(pick, dist.size - 1)
    images = []
    for k, i in enumerate(pick):
        vp = Viewport(center=tuple((centres[i] + g) / 2), half_width=0.6 * dist[i] + 1.5, size=size)
        trail = xs[pick[max(0, k - 4) : k]] if k > 0 else None
        images.append(
            draw_swarm(
                xs[i],
                goal=g,
                goal_radius=goal_radius,
                trails=trail,
                viewport=vp,
                agent_radius_px=max(2.0, min(size) / 110),
            )
        )
    return write_gif(images, path, fps=fps, max_frames=None)


# --------------------------------------------------------------------------- plots


def _figure(width: float, height: float, ncols: int, nrows: int = 1):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False)
    return fig, axes


def _save(fig: Any, path: str | Path, dpi: int) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    return path


def _errorline(ax: Any, x: Sequence[float], stat: dict[str, list[float]], key: str, **kw: Any):
    y = np.asarray(stat[key], dtype=float)
    err = np.asarray(stat[f"{key}_std"], dtype=float)
    ax.errorbar(x, y, yerr=err, capsize=2, marker="o", ms=3, **kw)


def plot_fig1(result: dict[str, Any], path: str | Path, *, dpi: int = 80) -> Path:
    """Fig. 1 as three panels: eq. 2 polarization over time per β; both forms vs β."""
    fig, axes = _figure(11.5, 3.4, 3)
    ax0, ax1, ax2 = axes[0]
    betas = result["x"]["values"]
    ts = result["time_series"]
    from matplotlib import colormaps

    cmap = colormaps["viridis"]
    for k, (beta, curve) in enumerate(zip(betas, ts["velocity_polarization"], strict=True)):
        y = np.maximum(np.asarray(curve, dtype=float), 1e-12)
        ax0.semilogy(ts["t"], y, color=cmap(k / max(1, len(betas) - 1)), label=f"β={beta:g}")
    ax0.set(xlabel="t", ylabel="|Σv|/N (eq. 2)", title="polarization (eq. 2) vs time")
    ax0.set_ylim(bottom=1e-6)
    ax0.legend(fontsize=6, ncol=2)
    for ax, name, title in (
        (ax1, "velocity_polarization", "eq. 2 polarization vs β"),
        (ax2, "polarization", "unit-heading polarization vs β"),
    ):
        stat = result["metrics"][name]
        _errorline(ax, betas, stat, "time_mean", label="time mean")
        _errorline(ax, betas, stat, "final", label="final (t = T)", ls="--")
        ax.set_xscale("symlog", linthresh=0.01)
        ax.set(xlabel="β", title=title)
        ax.axvline(0.1, color="0.7", lw=0.8)
        ax.legend(fontsize=7)
    ax1.set_yscale("log")
    ax1.set_ylim(bottom=1e-10)  # below: rounding noise of a momentum that is zero
    fig.suptitle("Fig. 1 — polarization vs dissipation β (mean ± sd over seeds)", fontsize=10)
    return _save(fig, path, dpi)


def plot_fig4_5(result: dict[str, Any], path: str | Path, *, dpi: int = 80) -> Path:
    """Figs. 4–5: spherical variance, eq. 3 and unit angular momentum vs time, per β."""
    fig, axes = _figure(11.5, 3.4, 3)
    t = np.asarray(result["t"])
    for run, color in zip(result["runs"], ("tab:blue", "tab:red"), strict=False):
        for ax, name in zip(
            axes[0],
            ("spherical_variance", "velocity_angular_momentum", "angular_momentum"),
            strict=True,
        ):
            m = np.asarray(run["series_mean"][name])
            s = np.asarray(run["series_std"][name])
            ax.plot(t, m, color=color, label=f"β = {run['beta']:g}")
            ax.fill_between(t, m - s, m + s, color=color, alpha=0.2, lw=0)
    for ax, name in zip(
        axes[0],
        ("spherical_variance", "velocity_angular_momentum", "angular_momentum"),
        strict=True,
    ):
        ax.set(xlabel="t", title=_LABELS[name])
        ax.title.set_fontsize(9)
        ax.legend(fontsize=7)
    fig.suptitle("Figs. 4–5 — β = 0.01 vs β = 1.8 (mean ± sd over seeds)", fontsize=10)
    return _save(fig, path, dpi)


def plot_fig6_8(result: dict[str, Any], path: str | Path, *, dpi: int = 80) -> Path:
    """Figs. 6–8: angular momentum, polarization, expanse and NND vs ``C_o``."""
    fig, axes = _figure(11.5, 3.4, 3)
    x = result["x"]["values"]
    m = result["metrics"]
    panels = (
        ("velocity_angular_momentum", "angular_momentum", "Fig. 6 — angular momentum"),
        ("velocity_polarization", "polarization", "Fig. 7 — polarization"),
    )
    for ax, (paper, unit, title) in zip(axes[0][:2], panels, strict=True):
        _errorline(ax, x, m[paper], "time_mean", color="tab:blue", label="eq. form, time mean")
        ax.set_ylabel("eq. 2/3 form (speed-weighted)", color="tab:blue", fontsize=8)
        twin = ax.twinx()
        _errorline(twin, x, m[unit], "time_mean", color="tab:orange", label="unit, time mean")
        _errorline(twin, x, m[unit], "final", color="tab:orange", ls="--", label="unit, final")
        twin.set_ylabel("unit-heading form", color="tab:orange", fontsize=8)
        ax.set(xlabel="C_o", title=title)
        lines = ax.get_legend_handles_labels()
        lines2 = twin.get_legend_handles_labels()
        ax.legend(lines[0] + lines2[0], lines[1] + lines2[1], fontsize=6, loc="center right")
    ax = axes[0][2]
    for name, color in (("expanse", "tab:green"), ("nearest_neighbor_distance", "tab:purple")):
        short = "expanse" if name == "expanse" else "NND"
        _errorline(ax, x, m[name], "time_mean", color=color, label=f"{short}, time mean")
        _errorline(ax, x, m[name], "final", color=color, ls="--", label=f"{short}, final")
    ax.set(xlabel="C_o", title="Fig. 8 — expanse and average NND")
    ax.legend(fontsize=6)
    fig.suptitle("Figs. 6–8 — alignment strength C_o (β = 0.1; mean ± sd over seeds)", fontsize=10)
    return _save(fig, path, dpi)


def _plot_ratio(
    result: dict[str, Any], path: str | Path, dpi: int, keys: tuple[str, str], title: str
) -> Path:
    fig, axes = _figure(9.0, 3.4, 2)
    x = result["x"]["values"]
    for ax, stat in zip(axes[0], ("final", "time_mean"), strict=True):
        for key, ls in zip(keys, ("-", "--"), strict=True):
            series = result["series"][key]
            _errorline(ax, x, series["expanse"], stat, color="tab:green", ls=ls,
                       label=f"expanse ({key})")  # fmt: skip
            _errorline(ax, x, series["nearest_neighbor_distance"], stat, color="tab:purple",
                       ls=ls, label=f"NND ({key})")  # fmt: skip
        ax.set(xlabel=result["x"]["name"], title=f"{stat.replace('_', ' ')} of the run")
        ax.legend(fontsize=7)
    fig.suptitle(title, fontsize=10)
    return _save(fig, path, dpi)


def plot_fig9(result: dict[str, Any], path: str | Path, *, dpi: int = 80) -> Path:
    """Fig. 9: expanse and NND vs ``l``, for ``l_r`` varied and for ``l_a`` varied."""
    return _plot_ratio(
        result, path, dpi, ("vary_l_r", "vary_l_a"),
        "Fig. 9 — range ratio l = l_r/l_a (C = 1.2, β = 0.1; mean ± sd over seeds)",
    )  # fmt: skip


def plot_fig10(result: dict[str, Any], path: str | Path, *, dpi: int = 80) -> Path:
    """Fig. 10: expanse and NND vs ``C``, for ``C_r`` varied and for ``C_a`` varied."""
    return _plot_ratio(
        result, path, dpi, ("vary_C_r", "vary_C_a"),
        "Fig. 10 — amplitude ratio C = C_r/C_a (l = 0.2, β = 0.1; mean ± sd over seeds)",
    )  # fmt: skip


def plot_fig11(result: dict[str, Any], path: str | Path, *, dpi: int = 80) -> Path:
    """Fig. 11: overview of the approach, zoomed snapshots of seed 0, and time series."""
    snaps = result["snapshots"]
    n_snap = len(snaps["t"])
    ncols = 4
    nrows = 2
    fig, axes = _figure(12.0, 6.0, ncols, nrows)
    flat = list(axes.ravel())
    g = np.asarray(result["goal"])
    radius = result["goal_radius"]
    overview = flat[0]
    ts = result["time_series"]
    path_c = np.asarray(ts["centroid_path_seed0"])
    overview.plot(path_c[:, 0], path_c[:, 1], color="0.6", lw=0.8)
    pos = np.asarray(snaps["positions_seed0"])
    for k in range(n_snap):
        overview.scatter(pos[k, :, 0], pos[k, :, 1], s=2, label=f"t = {snaps['t'][k]:g}")
    overview.plot(*g, marker="x", color="tab:red", ms=8, mew=2)
    overview.add_patch(_circle(g, radius))
    overview.set_aspect("equal", adjustable="datalim")
    overview.set_title("seed 0 at the snapshot times; G = ×", fontsize=8)
    overview.legend(fontsize=5, markerscale=3)
    panels = flat[1 : 1 + min(n_snap, 6)]
    vel = np.asarray(snaps["velocities_seed0"])
    for ax, k in zip(panels, range(n_snap), strict=False):
        p = pos[k]
        c = p.mean(axis=0)
        ax.scatter(p[:, 0], p[:, 1], s=8)
        speed = np.linalg.norm(vel[k], axis=-1, keepdims=True)
        u = vel[k] / np.maximum(speed, 1e-12)
        ax.quiver(p[:, 0], p[:, 1], u[:, 0], u[:, 1], angles="xy", scale=25, width=0.006,
                  color="0.4")  # fmt: skip
        half = max(0.8, 1.3 * float(np.abs(p - c).max()))
        ax.set_xlim(c[0] - half, c[0] + half)
        ax.set_ylim(c[1] - half, c[1] + half)
        ax.set_aspect("equal")
        if np.all(np.abs(g - c) <= half):
            ax.plot(*g, marker="x", color="tab:red", ms=8, mew=2)
            ax.add_patch(_circle(g, radius))
        d = snaps["metrics"]["centroid_distance"][k]
        am = snaps["metrics"]["angular_momentum"][k]
        ax.set_title(f"t = {snaps['t'][k]:g}: |c − G| = {d:.2f}, L̂ = {am:.2f}", fontsize=8)
        ax.tick_params(labelsize=6)
    ax = flat[-1]
    ax.plot(ts["t"], ts["centroid_distance"], color="tab:blue", label="|centroid − G|")
    ax.set(xlabel="t", ylabel="distance")
    twin = ax.twinx()
    ss = result["sampled_series"]
    twin.plot(ss["t"], ss["angular_momentum"], color="tab:orange", label="unit ang. mom.")
    twin.plot(ss["t"], ss["polarization"], color="tab:green", label="unit polarization")
    twin.set_ylim(0, 1.05)
    lines = ax.get_legend_handles_labels()
    lines2 = twin.get_legend_handles_labels()
    ax.legend(lines[0] + lines2[0], lines[1] + lines2[1], fontsize=6, loc="center left")
    ax.set_title("seed means", fontsize=8)
    for extra in flat[1 + min(n_snap, 6) : -1]:
        extra.set_axis_off()
    fig.suptitle(
        "Fig. 11 — navigation to a sink (N = 31, C_g = 15, l_g = 5, C_o = 0.7, β = 1)",
        fontsize=10,
    )
    return _save(fig, path, dpi)


def _circle(center: np.ndarray, radius: float) -> Any:
    from matplotlib.patches import Circle

    return Circle(tuple(center), radius, fill=False, color="tab:red", lw=0.8)


# --------------------------------------------------------------------------- registry


@dataclass(frozen=True)
class FigureSpec:
    """One reproduced figure: how to compute it (full or quick) and how to plot it."""

    name: str
    title: str
    compute: Callable[[RunSetup, bool], dict[str, Any]]
    plot: Callable[..., Path]


def _quick_values(values: Sequence[float]) -> tuple[float, ...]:
    return (values[0], values[len(values) // 2], values[-1])


FIGURES: dict[str, FigureSpec] = {
    spec.name: spec
    for spec in (
        FigureSpec(
            "fig1",
            "polarization vs β",
            lambda s, q: fig1_polarization_vs_beta(
                _quick_values(DEFAULT_BETAS) if q else DEFAULT_BETAS, setup=s
            ),
            plot_fig1,
        ),
        FigureSpec(
            "fig4_5",
            "spherical variance, angular momentum vs t",
            lambda s, q: fig4_5_variance_and_angular_momentum(setup=s),
            plot_fig4_5,
        ),
        FigureSpec(
            "fig6_8",
            "C_o sweep",
            lambda s, q: fig6_8_alignment_sweep(
                _quick_values(DEFAULT_C_OS) if q else DEFAULT_C_OS, setup=s
            ),
            plot_fig6_8,
        ),
        FigureSpec(
            "fig9",
            "l = l_r/l_a sweep",
            lambda s, q: fig9_range_ratio_sweep(
                _quick_values(DEFAULT_L_RATIOS) if q else DEFAULT_L_RATIOS, setup=s
            ),
            plot_fig9,
        ),
        FigureSpec(
            "fig10",
            "C = C_r/C_a sweep",
            lambda s, q: fig10_amplitude_ratio_sweep(
                _quick_values(DEFAULT_C_RATIOS) if q else DEFAULT_C_RATIOS, setup=s
            ),
            plot_fig10,
        ),
        FigureSpec(
            "fig11",
            "navigation to a sink",
            lambda s, q: fig11_navigation(
                setup=s,
                duration=20.0 if q else 318.0,
                snapshot_times=(0.0, 5.0, 10.0, 20.0) if q else NAV_SNAPSHOT_TIMES,
            ),
            plot_fig11,
        ),
    )
}
