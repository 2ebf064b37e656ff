"""Reproduction of Naterop's table 3: the four configurations of the zone model.

Report: Naterop, Petrides & Prasad, *Implementing two mathematical swarm models…*
(seed ``003``), §4.1 (model, table 1), §5.2–5.3 (table 3, figs. 6–7). Model:
:mod:`swarm_envs.physics.zone` (``docs/models.md`` §3); statistics:
:mod:`swarm_envs.metrics` (``docs/models.md`` §2). :func:`run` is the common entry
point of the reproductions (:mod:`swarm_envs.papers.result`), with one part,
``zone_table3``; the claims are in :mod:`swarm_envs.papers.naterop.claims`, the plot in
:mod:`swarm_envs.papers.naterop.plots`.

Table 3 (N = 64, r_r = 1 m, r_a = 15 m, speed 2 m/s, φ̄ = 50°, σ = 0.05; averages over
t ∈ [100, 150] s; time to food with 1 in 5 informed, 10 repetitions):

=================  ===  ==========================  ============  ================
configuration      r_o  angular momentum (eq. 10)   polarization  time to food [s]
=================  ===  ==========================  ============  ================
swarm                2  0.52                        0.09          158
torus                5  2.71                        0.22          113
dynamic parallel     9  0.14                        0.95           83
highly parallel     13  0.04                        0.99           71
=================  ===  ==========================  ============  ================

Choices where the report is silent (:class:`ZoneSetup`; ``docs/reproductions_naterop_zone.md``):

- **time step** ``dt = 0.1 s`` (Couzin et al. 2002's τ); with the literal reading of
  φ̄ = 50° *per step* this is a turning rate of 500°/s;
- **λ** = all others (table 1: "up to N"); **ω** = 0.5 (Couzin et al. 2005);
- **initial conditions**: positions uniform in a square of area 3N centred on the origin
  (the report's §4.3 "random within an area of 3N"), headings uniform on the circle;
  per-agent parameters ``μ_i = μ_0 (1 + 0.05 ξ_i)``; the same draws (common random
  numbers) for every ``r_o``;
- **food**: a point at distance ``food_distance = 100 m`` from the initial centroid in a
  uniformly random direction (one per repetition); "reached" when the first member is
  within ``food_radius = 1 m`` (= r_r) of it (the report's response time, §4.1.4); runs
  stop at ``max_food_time = 400 s`` (a run that has not arrived counts as ``inf`` and is
  reported in ``reached``);
- **states**: our label from the unit-heading polarization P and angular momentum M
  (Couzin et al. 2002's order parameters), with thresholds of our own: P ≥ 0.97 highly
  parallel, 0.5 ≤ P < 0.97 dynamic parallel, P < 0.5 and M ≥ 0.3 torus, else swarm.

Because the torus depends on how fast agents may turn, the table is run under two
readings of φ̄ at once (one batch): ``"per_step"`` (50° per step, the report's words,
eq. 5) and ``"per_second"`` (50°/s, i.e. 5° per 0.1 s step, near Couzin's 40°/s).
The ``per_step`` reading is the one the verdicts are about: its claims count toward
the verdict of ``zone_table3``, those of the ``per_second`` reading are reported beside
them.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from swarm_envs import metrics
from swarm_envs.papers._io import to_jsonable, write_json
from swarm_envs.papers.claims import verdict
from swarm_envs.papers.naterop.claims import zone_row_claims, zone_trend_claims
from swarm_envs.papers.naterop.plots import plot_table3
from swarm_envs.papers.result import (
    PaperResult,
    PartResult,
    check_seeds,
    finish,
    output_dir,
    select_parts,
)
from swarm_envs.physics.zone import (
    ZoneAgentParams,
    ZoneParams,
    draw_agent_params,
    draw_informed,
    zone_step,
)

__all__ = [
    "CONFIGURATIONS",
    "NAME",
    "PARTS",
    "READINGS",
    "REPORT",
    "TITLE",
    "ZoneSetup",
    "classify_state",
    "run",
]

NAME = "naterop_zone"
TITLE = "Naterop, Petrides & Prasad, table 3 (§5.3), zone model of §4.1"
#: The one part: table 3 (``zone_table3.json``, ``zone_table3.png``).
PARTS: tuple[str, ...] = ("zone_table3",)

#: Table 3's configurations and their orientation radii r_o [m].
CONFIGURATIONS: tuple[tuple[str, float], ...] = (
    ("swarm", 2.0),
    ("torus", 5.0),
    ("dynamic parallel", 9.0),
    ("highly parallel", 13.0),
)

#: Table 3 as printed: raw angular momentum (eq. 10), polarization (eq. 8), time to food.
REPORT: dict[str, dict[str, float]] = {
    "swarm": {"angular_momentum_raw": 0.52, "polarization": 0.09, "time_to_food": 158.0},
    "torus": {"angular_momentum_raw": 2.71, "polarization": 0.22, "time_to_food": 113.0},
    "dynamic parallel": {
        "angular_momentum_raw": 0.14,
        "polarization": 0.95,
        "time_to_food": 83.0,
    },
    "highly parallel": {
        "angular_momentum_raw": 0.04,
        "polarization": 0.99,
        "time_to_food": 71.0,
    },
}

#: The two readings of φ̄ = 50°: per step (the report's eq. 5) or per second.
READINGS = ("per_step", "per_second")


@dataclass(frozen=True)
class ZoneSetup:
    """Run choices where the report is silent (module docstring)."""

    n_agents: int = 64
    dt: float = 0.1
    t_start: float = 100.0
    t_end: float = 150.0
    sample_every: float = 1.0
    seeds: int = 3
    repetitions: int = 10
    food_distance: float = 100.0
    food_radius: float = 1.0
    max_food_time: float = 400.0
    max_turn_degrees: float = 50.0
    omega: float = 0.5
    base_seed: int = 0

    def __post_init__(self) -> None:
        for name in ("n_agents", "seeds", "repetitions"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f"ZoneSetup.{name} must be an integer >= 1, got {value!r}")
        for name in ("dt", "t_end", "sample_every", "food_distance", "food_radius"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"ZoneSetup.{name} must be finite and > 0, got {value!r}")
        if not 0 <= self.t_start <= self.t_end:
            raise ValueError(
                f"ZoneSetup.t_start must be in [0, t_end={self.t_end}], got {self.t_start}"
            )
        if not self.max_food_time > 0:
            raise ValueError(f"ZoneSetup.max_food_time must be > 0, got {self.max_food_time}")

    @classmethod
    def quick(cls, seeds: int = 2) -> ZoneSetup:
        """Tiny sizes for smoke tests (a few seconds at most)."""
        return cls(
            n_agents=12,
            t_start=8.0,
            t_end=12.0,
            seeds=seeds,
            repetitions=2,
            food_distance=10.0,
            max_food_time=30.0,
        )

    def params(self, r_o: float, max_turn_degrees: float | None = None) -> ZoneParams:
        """Naterop's table 1 set for one ``r_o`` (``ω``, φ̄ from this setup)."""
        turn = self.max_turn_degrees if max_turn_degrees is None else max_turn_degrees
        return ZoneParams.naterop(r_o, omega=self.omega, max_turn=math.radians(turn))

    def turn_per_step(self) -> dict[str, float]:
        """φ̄ per step in radians under each reading of :data:`READINGS`."""
        phi = math.radians(self.max_turn_degrees)
        return {"per_step": phi, "per_second": min(phi * self.dt, math.pi)}


def classify_state(polarization: float, angular_momentum: float) -> str:
    """Our label from unit-heading P and M (thresholds in the module docstring).

    >>> classify_state(0.99, 0.01), classify_state(0.2, 0.7), classify_state(0.1, 0.05)
    ('highly parallel', 'torus', 'swarm')
    """
    if polarization >= 0.97:
        return "highly parallel"
    if polarization >= 0.5:
        return "dynamic parallel"
    if angular_momentum >= 0.3:
        return "torus"
    return "swarm"


# --------------------------------------------------------------------------- runs


def _initial(
    rng: np.random.Generator, batch: tuple[int, ...], n: int
) -> tuple[np.ndarray, np.ndarray]:
    """Positions uniform in a square of area 3N at the origin; uniform unit headings."""
    half = 0.5 * math.sqrt(3.0 * n)
    x0 = rng.uniform(-half, half, (*batch, n, 2))
    angle = rng.uniform(0.0, 2.0 * math.pi, (*batch, n))
    return x0, np.stack([np.cos(angle), np.sin(angle)], axis=-1)


def _agent_params(
    setup: ZoneSetup, rng: np.random.Generator, shape: tuple[int, ...]
) -> ZoneAgentParams:
    """Per-agent parameters for a batch ``(readings, configs, runs, N)``.

    The relative deviations ``1 + σ ξ_i`` are drawn once per run (shape ``(runs, N)``)
    and shared by every reading and configuration (common random numbers); the base
    values vary along the first two axes.
    """
    unit = ZoneParams(r_r=1.0, r_o=1.0, r_a=1.0, speed=1.0, max_turn=1.0, param_spread=0.05)
    f = draw_agent_params(unit, rng, shape[2:])
    ro = np.array([r for _, r in CONFIGURATIONS])[None, :, None, None]
    turns = setup.turn_per_step()
    phi = np.array([turns[k] for k in READINGS])[:, None, None, None]
    base = setup.params(9.0)
    full = (*shape[:2], *shape[2:])
    return ZoneAgentParams(
        r_r=np.broadcast_to(base.r_r * f.r_r, full),
        r_o=ro * f.r_o,
        r_a=np.broadcast_to(base.r_a * f.r_a, full),
        speed=np.broadcast_to(base.speed * f.speed, full),
        max_turn=np.minimum(phi * f.max_turn, math.pi),
    )


def _table_statistics(setup: ZoneSetup) -> dict[str, np.ndarray]:
    """P, M (unit), raw L and expanse averaged over ``[t_start, t_end]``, per run.

    Returns arrays shaped ``(readings, configs, seeds)``.
    """
    rng = np.random.default_rng(setup.base_seed)
    n, runs = setup.n_agents, setup.seeds
    shape = (len(READINGS), len(CONFIGURATIONS), runs, n)
    x0, h0 = _initial(rng, (runs,), n)
    ap = _agent_params(setup, rng, shape)
    x = np.broadcast_to(x0, (*shape, 2)).copy()
    h = np.broadcast_to(h0, (*shape, 2)).copy()
    params = setup.params(9.0)
    steps = round(setup.t_end / setup.dt)
    every = max(1, round(setup.sample_every / setup.dt))
    first = math.ceil(setup.t_start / setup.dt - 1e-9)
    speed = ap.speed[..., None]
    names = ("polarization", "angular_momentum", "angular_momentum_raw", "expanse")
    sums: dict[str, float | np.ndarray] = dict.fromkeys(names, 0.0)
    count = 0
    for step in range(1, steps + 1):
        x, h = zone_step(x, h, params, dt=setup.dt, agent_params=ap)
        if step >= first and (step - first) % every == 0:
            v = speed * h
            sums["polarization"] = sums["polarization"] + metrics.polarization(v)
            sums["angular_momentum"] = sums["angular_momentum"] + metrics.angular_momentum(x, v)
            sums["angular_momentum_raw"] = sums["angular_momentum_raw"] + (
                metrics.raw_angular_momentum(x, v)
            )
            sums["expanse"] = sums["expanse"] + metrics.expanse(x)
            count += 1
    return {k: np.asarray(v) / max(count, 1) for k, v in sums.items()}


def _food_times(setup: ZoneSetup) -> np.ndarray:
    """Time until the first member is within ``food_radius`` of the food, per run.

    Shaped ``(readings, configs, repetitions)``; ``inf`` where not reached in time.
    """
    rng = np.random.default_rng(setup.base_seed + 1)
    n, runs = setup.n_agents, setup.repetitions
    shape = (len(READINGS), len(CONFIGURATIONS), runs, n)
    x0, h0 = _initial(rng, (runs,), n)
    ap = _agent_params(setup, rng, shape)
    params = setup.params(9.0)
    informed = np.broadcast_to(draw_informed(params, rng, (runs, n)), shape)
    angle = rng.uniform(0.0, 2.0 * math.pi, runs)
    food = x0.mean(axis=-2) + setup.food_distance * np.stack(
        [np.cos(angle), np.sin(angle)], axis=-1
    )
    # Flatten the batch and drop runs as they arrive (keeps the late steps cheap).
    b = math.prod(shape[:3])
    food = np.broadcast_to(food, (*shape[:3], 2)).reshape(b, 2)
    x = np.broadcast_to(x0, (*shape, 2)).reshape(b, n, 2)
    h = np.broadcast_to(h0, (*shape, 2)).reshape(b, n, 2)
    inf_ = informed.reshape(b, n)
    ap = ZoneAgentParams(*(np.broadcast_to(a, shape).reshape(b, n) for a in ap))
    active = np.arange(b)
    times = np.full(b, np.inf)
    for step in range(1, round(setup.max_food_time / setup.dt) + 1):
        x, h = zone_step(x, h, params, dt=setup.dt, goal=food, informed=inf_, agent_params=ap)
        arrived = np.linalg.norm(x - food[:, None, :], axis=-1).min(axis=-1) <= setup.food_radius
        if arrived.any():
            times[active[arrived]] = step * setup.dt
            keep = ~arrived
            if not keep.any():
                break
            active, x, h, food, inf_ = active[keep], x[keep], h[keep], food[keep], inf_[keep]
            ap = ZoneAgentParams(*(a[keep] for a in ap))
    return times.reshape(shape[:3])


# --------------------------------------------------------------------------- table


def _row(
    name: str,
    r_o: float,
    stats: dict[str, np.ndarray],
    times: np.ndarray,
    reading: int,
    config: int,
) -> dict[str, Any]:
    """One table row: means and spreads over seeds, time to food, our state label."""
    row: dict[str, Any] = {"configuration": name, "r_o": r_o}
    for key, series in stats.items():
        s = series[reading, config]
        row[key] = float(s.mean())
        row[f"{key}_std"] = float(s.std())
    t = times[reading, config]
    reached = np.isfinite(t)
    row["time_to_food_mean"] = float(t[reached].mean()) if reached.any() else math.inf
    row["time_to_food_median"] = float(np.median(t))
    row["time_to_food_std"] = float(t[reached].std()) if reached.any() else math.inf
    row["reached"] = f"{int(reached.sum())}/{t.size}"
    row["state"] = classify_state(row["polarization"], row["angular_momentum"])
    return row


def _table_text(rows: list[dict[str, Any]]) -> str:
    lines = [
        f"{'configuration':17s} {'r_o':>4s} | {'L raw':>12s} {'M unit':>5s} | "
        f"{'P':>11s} | {'time to food [s]':>18s} | state",
    ]
    for r in rows:
        rep = REPORT[r["configuration"]]
        lines.append(
            f"{r['configuration']:17s} {r['r_o']:4.0f} | "
            f"{r['angular_momentum_raw']:5.2f} ({rep['angular_momentum_raw']:4.2f}) "
            f"{r['angular_momentum']:5.2f} | "
            f"{r['polarization']:4.2f} ({rep['polarization']:4.2f}) | "
            f"{r['time_to_food_median']:6.1f} ({rep['time_to_food']:3.0f}) {r['reached']:>5s} | "
            f"{r['state']}"
        )
    return "\n".join(lines)


def _label(reading: str) -> str:
    return "" if reading == "per_step" else f" [φ̄ {reading.replace('_', ' ')}]"


def run(
    out_dir: str | Path | None = None,
    *,
    quick: bool = False,
    seeds: int | None = None,
    only: Sequence[str] | None = None,
) -> PaperResult:
    """Reproduce Naterop's table 3 (§5.3).

    Args:
        out_dir: where to write ``zone_table3.json``, ``zone_table3.png`` and
            ``summary.json``; ``None`` writes nothing.
        quick: tiny sizes (12 agents, 12 s, 2 repetitions) for smoke tests.
        seeds: independent runs averaged for P and L (``None``: 3; the food times use
            ``ZoneSetup.repetitions = 10``, as the report).
        only: ``None`` or ``["zone_table3"]`` (the only part).

    Returns:
        The verdict of ``zone_table3`` and its claims; the result reads as the JSON
        document ``{"paper", "setup", "report", "tables": {reading: rows}, "trends",
        "verdict", "verdict_per_second", "text", "runtime_s"}``. Each row has our means
        and spreads, the state label, the time to food, its ``claims`` and ``verdict`` /
        ``why``; ``verdict`` maps each configuration to its row's verdict under the
        ``per_step`` reading (the report's), ``verdict_per_second`` under the other;
        ``trends`` holds the claims across the configurations, per reading.
    """
    select_parts(PARTS, only)
    n_seeds = check_seeds(seeds) or 3
    start = time.perf_counter()
    setup = ZoneSetup.quick(n_seeds) if quick else ZoneSetup(seeds=n_seeds)
    stats = _table_statistics(setup)
    times = _food_times(setup)
    tables: dict[str, list[dict[str, Any]]] = {}
    part_claims = []
    for i, reading in enumerate(READINGS):
        rows = []
        for j, (name, r_o) in enumerate(CONFIGURATIONS):
            row = _row(name, r_o, stats, times, i, j)
            row["claims"], row["why"] = zone_row_claims(row, REPORT[name], label=_label(reading))
            row["verdict"] = verdict(row["claims"])
            rows.append(row)
            part_claims += [c | {"paper_form": reading == "per_step"} for c in row["claims"]]
        tables[reading] = rows
    trends = {
        reading: zone_trend_claims(rows, label=_label(reading), paper_form=reading == "per_step")
        for reading, rows in tables.items()
    }
    for claims in trends.values():
        part_claims += claims
    main = tables["per_step"]
    text = "\n\n".join(
        f"φ̄ = {setup.max_turn_degrees:g}° {reading.replace('_', ' ')}  "
        "(ours (report); M unit = unit-heading angular momentum)\n" + _table_text(rows)
        for reading, rows in tables.items()
    )
    result: dict[str, Any] = {
        "paper": TITLE,
        "setup": {**asdict(setup), "readings": list(READINGS)},
        "report": REPORT,
        "tables": tables,
        "trends": trends,
        "verdict": {r["configuration"]: r["verdict"] for r in main},
        "verdict_per_second": {r["configuration"]: r["verdict"] for r in tables["per_second"]},
        "text": text,
        "runtime_s": time.perf_counter() - start,
    }
    result = to_jsonable(result)
    out = output_dir(out_dir)
    files: list[Path] = []
    if out is not None:
        files.append(write_json(out / "zone_table3.json", result))
        files.append(plot_table3(result, out / "zone_table3.png"))
    part = PartResult(
        name="zone_table3",
        title="Table 3: the zone model's four configurations",
        verdict=verdict(part_claims),
        claims=to_jsonable(part_claims),
        note="rows (φ̄ per step): " + ", ".join(f"{k}: {v}" for k, v in result["verdict"].items()),
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
