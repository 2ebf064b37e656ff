"""Reproduction of the Naterop report's force-model failure (§5.1, Fig. 3) and its fix.

Report: Naterop, Petrides & Prasad, *Implementing two mathematical swarm models…*
(seed ``003``). §4.2 defines a Viscido-style force model (eqs. 15–18, table 2); §5.1
finds that "the expanse value of the swarm continuously increases with time (after a
certain point) for all cases": the agents "escape the influential zones, and then
continue with their same velocities". §5.1 and §6 blame "very high velocities" from the
scaling of units and time step and propose "to reduce the time-step, and add a drag
force". The physics is :mod:`swarm_envs.physics.piecewise` (``docs/models.md`` §4),
the expanse :func:`swarm_envs.metrics.expanse` (Naterop eq. 11). :func:`run` is the
common entry point of the reproductions (:mod:`swarm_envs.papers.result`), with one
part, ``piecewise_dispersal``; the claims are in :mod:`swarm_envs.papers.naterop.claims`,
the plot in :mod:`swarm_envs.papers.naterop.plots`.

What :func:`run` does: table 2 (``N = 100``, ``λ = 8``, ``F_max = 100``, ``r_r = 1``,
``r_a = 20``, ``R = 30``, random force ``σ = F_max/6``, unit mass), for
``r_0 ∈ {1, 5, 10, 15}`` (the report's range 1–15), in four settings that cross the two
remedies the report names:

============  =====  ========  ================================================
setting       β      dt [s]    role
============  =====  ========  ================================================
``report``    0      0.1       the report's model with a large step: must disperse
``fixed``     0.5    0.01      drag and a 10× smaller step: must stay bounded
``small_dt``  0      0.01      the smaller step alone (diagnostic)
``drag``      0.5    0.1       the drag alone (diagnostic)
============  =====  ========  ================================================

Choices where the report is silent:

- **Time step.** The report gives none. ``dt = 0.1 s`` is "report-like": one maximal
  kick moves an agent ``F_max dt² / m = 1 m = r_r`` in one step (up to ``λ`` times that
  with all neighbours pulling), so agents cross the zones of eq. 16 in a few steps, as
  §5.1 describes; it is also past the explicit-stability limit of a crowded repulsion
  zone (``g_r = F_max/r_r = 100 s⁻²`` per neighbour, ``ω ≈ 10 √λ ≈ 28 s⁻¹``,
  semi-implicit Euler needs ``ω dt < 2``). ``dt = 0.01 s`` gives ``ω dt ≈ 0.3``.
- **Drag.** ``β = 0.5 s⁻¹`` (velocity relaxation time ``m/β = 2 s``, ``β dt ≤ 0.05``):
  weak enough that the random force still moves the agents (mean speed ≈ 2 m/s) and
  that the swarm reaches its plateau within the run at every ``r_0``; larger ``β``
  freezes the swarm near its start for large ``r_0`` (the zero-force band
  ``[r_r, r_0)`` is then crossed only by slow diffusion).
- **Initial state.** Positions uniform in a square of area ``3N`` (side
  ``√(3N) ≈ 17.3 m``; the report: "within an area of 3N"), zero velocities (not
  stated), drawn from ``numpy.random.default_rng(seed)``; the random forces from a
  second generator ``default_rng(seed + 1)``. The same initial states and noise
  streams are used for every setting and ``r_0`` (common random numbers). Seeds run
  as a batch dimension.
- **Duration.** ``T = 200 s`` (the report's time axis is not legible in the seed).
- **Criteria.** A run *disperses* when its final expanse is at least 5× the initial one
  and still rising: ``E(T) ≥ 1.3 E(T/2)``. A run is *bounded* when it has plateaued:
  the mean expanse over ``[T/2, T]`` is at most 1.2× the mean over ``[T/4, T/2]``, and
  its maximum over ``[T/2, T]`` is below ``R``. The verdict needs every ``r_0`` and
  every seed.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, TypedDict

import numpy as np

from swarm_envs import metrics
from swarm_envs.papers._io import to_jsonable, write_json
from swarm_envs.papers.claims import verdict
from swarm_envs.papers.naterop.claims import dispersal_claims
from swarm_envs.papers.naterop.plots import plot_dispersal
from swarm_envs.papers.result import (
    PaperResult,
    PartResult,
    check_seeds,
    finish,
    output_dir,
    select_parts,
)
from swarm_envs.physics.piecewise import PiecewiseParams, simulate_piecewise

__all__ = [
    "DEFAULT_R_0S",
    "NAME",
    "PARTS",
    "SETTINGS",
    "TITLE",
    "Setting",
    "bounded",
    "dispersed",
    "run",
]

NAME = "naterop_piecewise"
TITLE = (
    "Naterop, Petrides & Prasad, Implementing two mathematical swarm models "
    "(force-based model: §4.2, table 2; results: §5.1, Fig. 3)"
)

#: The one part: the dispersal figure (``piecewise_dispersal.json``, ``.png``).
PARTS: tuple[str, ...] = ("piecewise_dispersal",)

#: Equilibrium distances swept (the report's table 2 gives the range 1–15 m).
DEFAULT_R_0S = (1.0, 5.0, 10.0, 15.0)


class _Table2(TypedDict):
    """The report's table 2, less ``r_0`` (swept) and ``σ`` (``F_max / 6``)."""

    N: int
    n_neighbors: int
    F_max: float
    r_r: float
    r_a: float
    R: float


#: Table 2 values other than ``r_0``.
TABLE_2: _Table2 = {"N": 100, "n_neighbors": 8, "F_max": 100.0, "r_r": 1.0, "r_a": 20.0, "R": 30.0}

#: Dispersal: ``E(T) ≥ DISPERSE_FACTOR E(0)`` and ``E(T) ≥ RISING_FACTOR E(T/2)``.
DISPERSE_FACTOR = 5.0
RISING_FACTOR = 1.3
#: Plateau: ``mean E[T/2, T] ≤ PLATEAU_FACTOR · mean E[T/4, T/2]``.
PLATEAU_FACTOR = 1.2


@dataclass(frozen=True)
class Setting:
    """One integration setting: drag ``β`` and time step ``dt`` (seconds)."""

    name: str
    beta: float
    dt: float
    role: str


SETTINGS = (
    Setting("report", 0.0, 0.1, "report-like: no drag, large step (expected to disperse)"),
    Setting("fixed", 0.5, 0.01, "drag and a 10x smaller step (expected to stay bounded)"),
    Setting("small_dt", 0.0, 0.01, "diagnostic: the smaller step alone, no drag"),
    Setting("drag", 0.5, 0.1, "diagnostic: the drag alone, large step"),
)


def _window_mean(e: np.ndarray, t: np.ndarray, lo: float, hi: float) -> np.ndarray:
    sel = (t >= lo) & (t <= hi)
    return e[sel].mean(axis=0)


def dispersed(e: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Per seed: ``E(T) ≥ 5 E(0)`` and ``E(T) ≥ 1.3 E(T/2)`` (still rising at the end).

    ``e`` is the expanse shaped ``(samples, seeds)`` at times ``t`` (``t[0] = 0``).
    """
    half = int(np.argmin(np.abs(t - t[-1] / 2)))
    return (e[-1] >= DISPERSE_FACTOR * e[0]) & (e[-1] >= RISING_FACTOR * e[half])


def bounded(e: np.ndarray, t: np.ndarray, R: float) -> np.ndarray:
    """Per seed: mean ``E`` over ``[T/2, T]`` ≤ 1.2 × mean over ``[T/4, T/2]`` (a plateau)
    and ``max E`` over ``[T/2, T]`` below ``R``."""
    T = t[-1]
    late = _window_mean(e, t, T / 2, T)
    early = _window_mean(e, t, T / 4, T / 2)
    return (late <= PLATEAU_FACTOR * early) & (e[t >= T / 2].max(axis=0) < R)


def _isolated_fraction(x: np.ndarray, R: float) -> np.ndarray:
    """Per seed, the fraction of agents with no other agent within ``R`` (none acts on them)."""
    diff = x[..., None, :, :] - x[..., :, None, :]
    rho2 = np.einsum("...k,...k->...", diff, diff)
    n = x.shape[-2]
    rho2[..., np.arange(n), np.arange(n)] = np.inf
    return (rho2.min(axis=-1) >= R * R).mean(axis=-1)


def _simulate_expanse(
    params: PiecewiseParams,
    x0: np.ndarray,
    v0: np.ndarray,
    rng: np.random.Generator,
    *,
    dt: float,
    steps: int,
    sample_every: int,
    chunk: int = 1000,
) -> dict[str, np.ndarray]:
    """Run in chunks (bounded memory, same result as one call); sample the expanse."""
    x, v = x0, v0
    samples = [np.asarray(metrics.expanse(x), dtype=np.float64)]
    done = 0
    while done < steps:
        n = min(chunk, steps - done)
        xs, vs = simulate_piecewise(params, x, v, dt=dt, steps=n, rng=rng)
        idx = np.arange(done + 1, done + n + 1)
        keep = idx[idx % sample_every == 0] - done
        if len(keep):
            samples.extend(np.asarray(metrics.expanse(xs[keep]), dtype=np.float64))
        x, v = xs[-1], vs[-1]
        done += n
    speed = np.linalg.norm(v, axis=-1).mean(axis=-1)
    return {
        "expanse": np.stack(samples),
        "final_speed": speed,
        "final_nnd": np.asarray(metrics.nearest_neighbor_distance(x), dtype=np.float64),
        "final_isolated": _isolated_fraction(x, params.R),
        "finite": np.asarray(bool(np.isfinite(x).all() and np.isfinite(v).all())),
    }


def _compute(quick: bool, seeds: int) -> dict[str, Any]:
    """The document of :func:`run`, with numpy values and without ``runtime_s``."""
    n_agents = 40 if quick else TABLE_2["N"]
    duration = 20.0 if quick else 200.0
    r_0s = (1.0, 10.0) if quick else DEFAULT_R_0S
    n_seeds = min(int(seeds), 2) if quick else int(seeds)
    sample_dt = 0.2 if quick else 1.0
    base_seed = 0

    init_rng = np.random.default_rng(base_seed)
    side = math.sqrt(3.0 * n_agents)
    x0 = init_rng.uniform(0.0, side, size=(n_seeds, n_agents, 2))
    v0 = np.zeros_like(x0)

    results: dict[str, Any] = {}
    t_samples = np.linspace(0.0, duration, round(duration / sample_dt) + 1)
    per_setting_flags: dict[str, dict[str, np.ndarray]] = {}
    for setting in SETTINGS:
        steps = round(duration / setting.dt)
        every = max(1, round(sample_dt / setting.dt))
        per_r0: dict[str, Any] = {}
        flags_d, flags_b = [], []
        for r_0 in r_0s:
            params = PiecewiseParams(
                F_max=TABLE_2["F_max"],
                r_r=TABLE_2["r_r"],
                r_0=r_0,
                r_a=TABLE_2["r_a"],
                R=TABLE_2["R"],
                n_neighbors=TABLE_2["n_neighbors"],
                beta=setting.beta,
            )
            noise_rng = np.random.default_rng(base_seed + 1)
            out = _simulate_expanse(
                params, x0, v0, noise_rng, dt=setting.dt, steps=steps, sample_every=every
            )
            e = out["expanse"]
            t = np.arange(e.shape[0]) * every * setting.dt
            d = dispersed(e, t)
            b = bounded(e, t, params.R)
            flags_d.append(d)
            flags_b.append(b)
            half = int(np.argmin(np.abs(t - t[-1] / 2)))
            per_r0[f"{r_0:g}"] = {
                "r_0": r_0,
                "expanse_mean": np.interp(t_samples, t, e.mean(axis=1)),
                "expanse_initial": e[0],
                "expanse_half": e[half],
                "expanse_final": e[-1],
                "late_growth": e[-1] / e[half],
                "final_mean_speed": out["final_speed"],
                "final_nnd": out["final_nnd"],
                "final_isolated_fraction": out["final_isolated"],
                "dispersed": d,
                "bounded": b,
                "finite": out["finite"],
            }
        per_setting_flags[setting.name] = {
            "dispersed": np.stack(flags_d),
            "bounded": np.stack(flags_b),
        }
        results[setting.name] = {**asdict(setting), "steps": steps, "r_0": per_r0}

    flags = per_setting_flags
    reproduced = bool(flags["report"]["dispersed"].all())
    fixed = bool(flags["fixed"]["bounded"].all())
    summary = (
        ("reproduced: " if reproduced else "NOT reproduced: ")
        + "without drag at dt = 0.1 s the expanse "
        + ("grows without bound" if reproduced else "does not grow without bound")
        + " for every r_0 and seed; "
        + ("fixed: " if fixed else "NOT fixed: ")
        + "with β = 0.5 and dt = 0.01 s it "
        + ("plateaus" if fixed else "does not plateau")
        + " for every r_0 and seed"
    )
    small_disperses = bool(flags["small_dt"]["dispersed"].all())
    small_bounded = bool(flags["small_dt"]["bounded"].all())
    drag_bounded = bool(flags["drag"]["bounded"].all())
    notes = [
        "the smaller step alone (no drag): "
        + ("still disperses" if small_disperses else "bounded" if small_bounded else "mixed"),
        "the drag alone (dt = 0.1 s): " + ("bounded" if drag_bounded else "not bounded everywhere"),
    ]
    if small_disperses:
        notes.append(
            "without drag the model has no dissipation (the random force heats it and the "
            "non-reciprocal λ-nearest forces are not conservative), so a smaller step only "
            "slows the dispersal"
        )
    if not drag_bounded:
        notes.append(
            "with β = 0.5 the large step keeps the swarm hot (the explicit step is past the "
            "stability limit of a crowded repulsion zone and the held random force injects "
            "σ² dt per unit time): both remedies are needed, as the report proposes"
        )
    findings = {
        "small_dt_alone_disperses": small_disperses,
        "small_dt_alone_bounded": small_bounded,
        "drag_alone_bounded": drag_bounded,
        "drag_alone_bounded_fraction": float(flags["drag"]["bounded"].mean()),
        "note": "; ".join(notes),
        "diagnostics": "; ".join(notes[:2]),
    }
    result = {
        "title": "Naterop piecewise force model: dispersal without drag, bounded with drag",
        "paper": {
            "reference": TITLE,
            "claim": (
                "§5.1: the expanse increases continuously with time for all cases; §5.1/§6: "
                "reduce the time step and add a drag force"
            ),
            "table_2": {**TABLE_2, "r_0": "1-15", "sigma": "F_max/6"},
        },
        "setup": {
            "quick": quick,
            "n_agents": n_agents,
            "seeds": n_seeds,
            "duration_s": duration,
            "r_0": list(r_0s),
            "initial": f"uniform in a square of area 3N (side {side:.4g} m), zero velocity",
            "rng": "positions default_rng(0); random force default_rng(1), same for all runs",
            "integrator": "semi-implicit Euler, random force drawn per step and held",
            "criteria": {
                "dispersed": f"E(T) >= {DISPERSE_FACTOR:g} E(0) and E(T) >= "
                f"{RISING_FACTOR:g} E(T/2)",
                "bounded": f"mean E[T/2,T] <= {PLATEAU_FACTOR:g} mean E[T/4,T/2] and "
                "max E[T/2,T] < R",
            },
            "settings": [asdict(s) for s in SETTINGS],
        },
        "t": t_samples,
        "results": results,
        "verdict": {"reproduced": reproduced, "fixed": fixed, "summary": summary},
        "findings": findings,
        "claims": dispersal_claims(flags["report"]["dispersed"], flags["fixed"]["bounded"]),
    }
    return result


def run(
    out_dir: str | Path | None = None,
    *,
    quick: bool = False,
    seeds: int | None = None,
    only: Sequence[str] | None = None,
) -> PaperResult:
    """Reproduce the dispersal of the report's force model and show the drag fix.

    Args:
        out_dir: where to write ``piecewise_dispersal.json``,
            ``piecewise_dispersal.png`` and ``summary.json``; ``None`` writes nothing.
        quick: a small version for tests (``N = 40``, ``T = 20 s``, ``r_0 ∈ {1, 10}``,
            at most 2 seeds); its verdict is not meaningful.
        seeds: number of random initial states and noise streams (batched), ``≥ 1``
            (``None``: 3).
        only: ``None`` or ``["piecewise_dispersal"]`` (the only part).

    Returns:
        The verdict of ``piecewise_dispersal`` and its claims; the result reads as the
        JSON document: ``paper``, ``setup``, ``results`` (per setting and ``r_0``:
        expanse series mean over seeds, initial/half/final expanse per seed, final
        speed, nearest-neighbour distance and isolated fraction, and the ``dispersed``
        and ``bounded`` flags per seed), ``verdict`` (``reproduced``: the report-like
        runs all disperse; ``fixed``: the fixed runs are all bounded; ``summary``),
        ``claims`` (those two), ``findings`` (the diagnostics) and ``runtime_s``.
    """
    select_parts(PARTS, only)
    n_seeds = check_seeds(seeds) or 3
    start = time.perf_counter()
    result = _compute(quick, n_seeds)
    result["runtime_s"] = time.perf_counter() - start
    result = to_jsonable(result)
    out = output_dir(out_dir)
    files: list[Path] = []
    if out is not None:
        files.append(write_json(out / "piecewise_dispersal.json", result))
        files.append(plot_dispersal(result, out / "piecewise_dispersal.png"))
    part = PartResult(
        name="piecewise_dispersal",
        title=result["title"],
        verdict=verdict(result["claims"]),
        claims=result["claims"],
        note=result["findings"]["diagnostics"],
        elapsed_s=time.perf_counter() - start,
        files=tuple(files),
    )
    return finish(
        NAME,
        TITLE,
        quick=quick,
        setup=result["setup"],
        parts={part.name: part},
        data=result,
        files=files,
        out=out,
        order=PARTS,
        started=start,
    )
