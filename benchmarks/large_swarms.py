"""Large swarms: seconds per SwarmNav step vs N (dense core against cut-off core, and the
crossover N), with the physical state of every timed run; and the regime table.

Usage: ``python benchmarks/large_swarms.py [--dim 2] [--physics large_swarm]
[--repeats 7] [--settle 1] [--max-n 100000] [--sizes N,...] [--dense-max 4000] [--kdtree]
[--accuracy 2000] [--cutoff-tol 0.03] [--regime [--regime-steps 100] [--regime-wall 900]
[--regime-dims 2,3] [--regime-physics navigation,large_swarm]]``

The cut-off core's pair pass is compiled with numba where it imports
(:mod:`swarm_envs.physics.compiled_pairs`); ``SWARM_ENVS_NUMBA=0`` times the numpy pass
instead. The header says which ran, and how many threads numba uses.

Scenarios (:func:`config`): ``--physics navigation`` is the default config (the
paper's navigation set) started at the density of its N = 10 default (10 agents in a
disc of radius 1.5, ``init_density`` 1.41 per unit area in 2-D, 0.71 per unit volume in
3-D); ``--physics large_swarm`` is ``configs/env/large_swarm.yaml``
(:meth:`SocialPotentialParams.large_swarm <swarm_envs.physics.SocialPotentialParams.large_swarm>`,
``init_density`` 0.3). Either way every N starts at the same density.

Timing: a full step is ``core.step(actions)`` followed by ``core.observe()`` (what every
env adapter does), for one swarm (B = 1, float64) with random actions drawn once per row
(not timed). Each cell is the median (and the best) of ``--repeats`` single steps after
``--settle`` untimed steps (default 1, the warm-up; the first steps of a random start
can need more substeps than the settled swarm); on a shared machine the medians are
what a run sees. Beside the time,
each row reports the physical state of the cut-off run at its end: the mean
nearest-neighbour distance, the expanse (mean distance to the centroid), the energy
drift per agent since the reset (``(E − E_0)/N``; dissipation makes it negative, a
diverging integration positive) and the substeps per step; a run that raises
:class:`~swarm_envs.envs.common.SwarmUnstableError` is reported as such.

Rows: N = 100 … ``--max-n``; the dense core only up to ``--dense-max`` (its ``(N, N)``
temporaries need about ``12 · 8 N²`` bytes). The crossover is then bisected
(geometrically) between the largest N where the dense core wins and the smallest where
the cut-off core wins.

``--regime``: instead of the timing table, the regime table of ``docs/large_swarms.md``:
for both parameter sets (``--regime-physics``), N = 10 … ``--max-n`` (or ``--sizes``;
the dense core below :data:`~swarm_envs.envs.cores.cutoff.core.CUTOFF_MIN_AGENTS`, the
cut-off core from there), the passive swarm (zero actions) for ``--regime-steps`` steps of
``dt = 0.1``: its state at the end (as above), the mean and largest substeps per step,
the seconds per step, and the outcome: a run that raises ``SwarmUnstableError``
(``on_unstable="raise"``, the default) is reported with the step and the message, one
that exceeds ``--regime-wall`` seconds stops there and says so; the state is then that
of its last completed step.

``--kdtree``: also time the neighbour work alone (all pairs within ``r_c`` plus the
k nearest neighbours) with the numpy cell list and with ``scipy.spatial.cKDTree``
(``query_pairs`` + ``query``), if scipy is importable.

``--accuracy N``: the per-agent force error of the cut-off at N agents after 1 and 20
steps of zero or random actions, next to the bound of
:func:`swarm_envs.physics.cutoff.force_error_bound` at the measured density and
relative speed. ``--cutoff-tol``: the cut-off core's tolerance (default
:data:`~swarm_envs.envs.cores.cutoff.core.DEFAULT_CUTOFF_TOL`).
"""

from __future__ import annotations

import argparse
import importlib.metadata
import math
import os
import platform
import statistics
import time
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from swarm_envs import tune_allocator
from swarm_envs.config import SwarmConfig, load_swarm_config
from swarm_envs.envs.common import SwarmUnstableError
from swarm_envs.envs.cores.cutoff.core import (
    CUTOFF_MIN_AGENTS,
    DEFAULT_CUTOFF_TOL,
    CutoffSwarmNavCore,
)
from swarm_envs.envs.cores.numpy import SwarmNavCore
from swarm_envs.physics import compiled_pairs, forces
from swarm_envs.physics.cutoff import force_error_bound, sparse_forces
from swarm_envs.physics.neighbors import CELL_MARGIN, REACH, CellList, knn, radius_pairs

Core = type[SwarmNavCore] | type[CutoffSwarmNavCore]

#: The parameter sets a run can use (``--physics``).
PHYSICS = ("navigation", "large_swarm")

_UNIT_BALL = {2: math.pi, 3: 4.0 * math.pi / 3.0}


def config(n: int, dim: int, physics: str = "navigation") -> SwarmConfig:
    """The scenario of ``physics`` (see the module docstring) with N agents."""
    if physics == "large_swarm":
        return load_swarm_config("large_swarm", {"n_agents": n, "dim": dim, "max_steps": 10**9})
    density = 10 / (_UNIT_BALL[dim] * 1.5**dim)  # the default start: 10 agents in 1.5
    return SwarmConfig(n_agents=n, dim=dim, init_density=density, max_steps=10**9)


#: Keyword arguments of every CutoffSwarmNavCore built here (set from the command line).
CUTOFF_KWARGS: dict[str, float] = {}


class RunState(NamedTuple):
    """The physical state at the end of a run (see the module docstring)."""

    nnd: float
    expanse: float
    drift: float  # (E − E_0) / N
    substeps: float  # mean per step
    max_substeps: float
    steps: int  # steps completed
    error: str | None  # why the run stopped early (SwarmUnstableError, wall limit)

    def cells(self) -> str:
        """The state (after the last completed step) as markdown table cells."""
        return f"{self.nnd:.3f} | {self.expanse:.2f} | {self.drift:+.3f} | {self.substeps:.2f} |"

    def outcome(self) -> str:
        """``ok`` or why the run stopped early."""
        return "ok" if self.error is None else self.error


def make_core(core_cls: Core, cfg: SwarmConfig) -> SwarmNavCore:
    """A core of ``core_cls`` for ``cfg``, reset with seed 0."""
    kwargs = CUTOFF_KWARGS if core_cls is CutoffSwarmNavCore else {}
    core = core_cls(cfg, **kwargs)
    core.reset(np.random.default_rng(0))
    return core


def run_steps(
    core: SwarmNavCore, actions: np.ndarray | None, steps: int, wall: float = math.inf
) -> tuple[list[float], RunState]:
    """Step ``core`` up to ``steps`` times (``actions`` ``None``: zero); the seconds of
    each full step (step + observe) and the state at the end."""
    n = core.cfg.n_agents
    e0 = float(core.stats()["energy"][0])
    a = np.zeros(core.x.shape) if actions is None else actions
    times: list[float] = []
    subs: list[float] = []
    stats = core.stats()
    error = None
    start = time.perf_counter()
    for _ in range(steps):
        t0 = time.perf_counter()
        try:
            *_, stats = core.step(a)
        except SwarmUnstableError as err:
            error = f"SwarmUnstableError at step {len(times) + 1}: {str(err).split('. To fix')[0]}"
            error = error.replace("|", "/")
            break
        core.observe()
        times.append(time.perf_counter() - t0)
        subs.append(float(stats["substeps"][0]))
        if time.perf_counter() - start > wall:
            error = f"stopped after {len(times)} steps ({wall:g} s wall limit)"
            break
    state = RunState(
        float(stats["nearest_neighbor_distance"][0]),
        float(stats["expanse"][0]),
        (float(stats["energy"][0]) - e0) / n,
        float(np.mean(subs)) if subs else math.nan,
        float(np.max(subs)) if subs else math.nan,
        len(times),
        error,
    )
    return times, state


#: Steps run before the timed ones (``--settle``; the first is the warm-up).
SETTLE = [1]


def time_step(
    core_cls: Core, n: int, dim: int, repeats: int, physics: str = "navigation"
) -> tuple[float, float, RunState]:
    """``(median, best)`` seconds of one full step (step + observe) of one swarm, after
    ``--settle`` steps (at least the warm-up), and the run's state at its end."""
    core = make_core(core_cls, config(n, dim, physics))
    actions = np.random.default_rng(1).uniform(-1.0, 1.0, (1, n, dim))
    settle = SETTLE[0]
    times, state = run_steps(core, actions, repeats + settle)
    if len(times) <= settle:
        return math.nan, math.nan, state
    return statistics.median(times[settle:]), min(times[settle:]), state


def time_call(fn: Callable[[], object], repeats: int) -> float:
    """Median seconds of ``fn()`` after one warm-up call."""
    fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def neighbour_work(n: int, dim: int, repeats: int, physics: str) -> tuple[float, float | None, int]:
    """Seconds of the neighbour work (pairs within r_c + k nearest) with both methods.

    Returns ``(cell list, cKDTree or None, pairs)``.
    """
    cfg = config(n, dim, physics)
    core = make_core(CutoffSwarmNavCore, cfg)
    x = core.x[0]
    r_c, k = core.cutoff, max(cfg.n_neighbors, 1)

    def cells() -> int:
        grid = CellList.build(x, r_c * (1.0 + CELL_MARGIN) / REACH, REACH)
        count = sum(c[0].size for c in grid.iter_pairs(r_c))
        knn(x, k)
        return count

    pairs = cells()
    ours = time_call(cells, repeats)
    try:
        from scipy.spatial import cKDTree
    except ImportError:
        return ours, None, pairs

    def tree() -> None:
        t = cKDTree(x)
        t.query_pairs(r_c, output_type="ndarray")
        t.query(x, k + 1)

    return ours, time_call(tree, repeats), pairs


def crossover(dim: int, lo: int, hi: int, repeats: int, physics: str) -> int:
    """Bisect (geometrically) the N where the cut-off core starts to win, in ``(lo, hi]``."""
    while hi > lo * 1.15 and hi - lo > 8:
        mid = round(math.sqrt(lo * hi))
        dense = time_step(SwarmNavCore, mid, dim, repeats, physics)[0]
        cut = time_step(CutoffSwarmNavCore, mid, dim, repeats, physics)[0]
        print(f"  bisect N = {mid}: dense {dense * 1e3:.2f} ms, cut-off {cut * 1e3:.2f} ms")
        if cut < dense:
            hi = mid
        else:
            lo = mid
    return hi


def accuracy(n: int, dim: int, cutoff_tol: float, physics: str) -> None:
    """Largest per-agent force error of the cut-off vs its bound, at N agents."""
    cfg = config(n, dim, physics)
    for policy in ("zero", "random"):
        core = CutoffSwarmNavCore(cfg, cutoff_tol=cutoff_tol)
        core.reset(np.random.default_rng(0))
        rng = np.random.default_rng(1)
        for steps in (1, 20):
            while core.t[0] < steps:
                actions = rng.uniform(-1.0, 1.0, (1, n, dim)) * (policy == "random")
                core.step(actions)
            x, v = core.x, core.v
            dense = forces(x, v, cfg.physics)[0]
            i, j = radius_pairs(x, core.cutoff)
            err = np.linalg.norm(sparse_forces(x, v, cfg.physics, i, j)[0] - dense, axis=-1)
            # Density hypothesis of the bound: each ball of radius ρ ≥ r_c around an
            # agent holds at most n ω_d ρ^d others; the smallest such n here.
            rho = np.sqrt(((x[0, :, None, :] - x[0, None, :, :]) ** 2).sum(-1))
            rho.sort(axis=-1)
            at = _UNIT_BALL[dim] * np.maximum(rho[:, 1:], core.cutoff) ** dim
            density = float((np.arange(1, n) / at).max())
            speed = float(np.linalg.norm(v[0, :, None, :] - v[0, None, :, :], axis=-1).max())
            bound = force_error_bound(
                cfg.physics, core.cutoff, speed=speed, n_agents=n, density=density, dim=dim
            )
            print(
                f"| {policy} | {steps} | {np.median(np.linalg.norm(dense, axis=-1)):.3f} | "
                f"{np.median(err):.3f} | {err.max():.3f} | {speed:.2f} | {density:.2f} | "
                f"{bound:.3g} |"
            )


def regime(
    dims: list[int],
    max_n: int,
    steps: int,
    wall: float,
    sizes: list[int] | None = None,
    physics_sets: tuple[str, ...] = PHYSICS,
) -> None:
    """The regime table (see the module docstring)."""
    print(
        f"passive swarms (zero actions), {steps} steps of dt = 0.1 from the reset (seed 0); "
        f"dense core below N = {CUTOFF_MIN_AGENTS}, cut-off core from there"
    )
    print()
    head = "| physics | d | N | start radius | NND | expanse | (E − E0)/N | substeps/step "
    head += "| max substeps | s/step | outcome |"
    print(head)
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|")
    sizes = [n for n in (10, 100, 1000, 10_000, 100_000) if n <= max_n] if not sizes else sizes
    for physics in physics_sets:
        for dim in dims:
            for n in sizes:
                cfg = config(n, dim, physics)
                cls = CutoffSwarmNavCore if n >= CUTOFF_MIN_AGENTS else SwarmNavCore
                times, state = run_steps(make_core(cls, cfg), None, steps, wall)
                per_step = statistics.median(times) if times else math.nan
                line = f"| {physics} | {dim} | {n:,} | {cfg.start_radius:.1f} | {state.cells()}"
                line += f" {state.max_substeps:.0f} | {per_step:.4f} | {state.outcome()} |"
                print(line, flush=True)


def header(args: argparse.Namespace) -> None:
    print(f"glibc heap tuning (swarm_envs.tune_allocator) active: {tune_allocator()}")
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores; numpy {np.__version__}")
    if compiled_pairs.numba_enabled():
        import numba

        pair_pass = f"compiled (numba {importlib.metadata.version('numba')}, "
        pair_pass += f"{numba.config.NUMBA_NUM_THREADS} threads)"
    else:
        pair_pass = "numpy (numba missing, or SWARM_ENVS_NUMBA=0)"
    print(f"cut-off pair pass: {pair_pass}")
    for physics in PHYSICS:
        probe = CutoffSwarmNavCore(config(10, args.dim, physics), **CUTOFF_KWARGS)
        p = probe.cfg.physics
        print(
            f"{physics}: C·l² = {p.h_stability:.3g}, C·l³ = {p.h_stability_3d:.3g}; cut-off "
            f"r_c = {probe.cutoff:.3f} (cutoff_tol {probe.cutoff_tol}, cutoff_speed "
            f"{probe.cutoff_speed}); init_density {probe.cfg.init_density:.3g} (d = {args.dim})"
        )
    print(f"CUTOFF_MIN_AGENTS = {CUTOFF_MIN_AGENTS}")
    print()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dim", type=int, default=2, choices=(2, 3))
    parser.add_argument("--physics", default="navigation", choices=PHYSICS)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--settle", type=int, default=1, help="untimed steps first (>= 1)")
    parser.add_argument("--max-n", type=int, default=100_000)
    parser.add_argument("--sizes", default="", help="comma-separated N (default: 100 … --max-n)")
    parser.add_argument("--dense-max", type=int, default=4000)
    parser.add_argument("--kdtree", action="store_true")
    parser.add_argument("--accuracy", type=int, default=0, metavar="N")
    parser.add_argument("--cutoff-tol", type=float, default=DEFAULT_CUTOFF_TOL)
    parser.add_argument("--regime", action="store_true")
    parser.add_argument("--regime-dims", default="2,3")
    parser.add_argument("--regime-steps", type=int, default=100)
    parser.add_argument("--regime-physics", default=",".join(PHYSICS))
    parser.add_argument("--regime-wall", type=float, default=900.0)
    args = parser.parse_args()
    CUTOFF_KWARGS["cutoff_tol"] = args.cutoff_tol
    SETTLE[0] = max(1, args.settle)
    header(args)
    if args.regime:
        dims = [int(d) for d in args.regime_dims.split(",")]
        sizes = [int(n) for n in args.sizes.split(",")] if args.sizes else None
        physics_sets = tuple(args.regime_physics.split(","))
        regime(dims, args.max_n, args.regime_steps, args.regime_wall, sizes, physics_sets)
        return
    dim, reps, physics = args.dim, args.repeats, args.physics
    print(
        f"timing: physics {physics}, d = {dim}, {SETTLE[0]} untimed steps, then {reps} timed; "
        "the state columns are the cut-off run's (substeps/step over all its steps)"
    )
    print()
    head = "| N | start radius | dense s/step (median) | cut-off s/step (median) | dense best | "
    head += "cut-off best | dense / cut-off | NND | expanse | (E − E0)/N | substeps/step |"
    if args.kdtree:
        head += " pairs/agent | neighbours: cell list s | cKDTree s |"
    print(head)
    print("|" + "---:|" * (head.count("|") - 1))
    sizes = [n for n in (100, 300, 1000, 3000, 10_000, 30_000, 100_000) if n <= args.max_n]
    if args.sizes:
        sizes = [int(n) for n in args.sizes.split(",")]
    winner: dict[int, str] = {}
    for n in sizes:
        cut = time_step(CutoffSwarmNavCore, n, dim, reps, physics)
        dense = time_step(SwarmNavCore, n, dim, reps, physics) if n <= args.dense_max else None
        line = f"| {n:,} | {config(n, dim, physics).start_radius:.1f} | "
        if dense is None:
            line += f"— | {cut[0]:.4f} | — | {cut[1]:.4f} | — |"
        else:
            line += (
                f"{dense[0]:.4f} | {cut[0]:.4f} | {dense[1]:.4f} | {cut[1]:.4f} | "
                f"{dense[0] / cut[0]:.1f} |"
            )
            winner[n] = "cutoff" if cut[0] < dense[0] else "dense"
        line += f" {cut[2].cells()}"
        if args.kdtree:
            ours, tree, pairs = neighbour_work(n, dim, reps, physics)
            line += f" {pairs / n:.0f} | {ours:.4f} | {'—' if tree is None else f'{tree:.4f}'} |"
        print(line, flush=True)
    print()
    lo = max([n for n, w in winner.items() if w == "dense"], default=10)
    hi = min([n for n, w in winner.items() if w == "cutoff" and n > lo], default=None)
    if hi is None:
        print("the dense core won at the largest measured N: no crossover below --dense-max")
    else:
        n_cross = crossover(dim, lo, hi, max(reps, 15), physics)
        print(f"crossover: the cut-off core wins from about N = {n_cross} (d = {dim})")
    if args.accuracy:
        print()
        print(f"per-agent force error of the cut-off at N = {args.accuracy} (d = {dim}):")
        print()
        print(
            "| actions | steps | median |F_dense| | median error | max error "
            "| max |v_i − v_j| | density n | bound |"
        )
        print("|---|---:|---:|---:|---:|---:|---:|---:|")
        accuracy(args.accuracy, dim, args.cutoff_tol, physics)


if __name__ == "__main__":
    main()
