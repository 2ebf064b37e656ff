"""Seconds per full SwarmNav step vs N, dense core against sparse core, and the crossover N.

Usage: ``python benchmarks/large_swarms.py [--dim 2] [--repeats 7] [--max-n 100000]
[--dense-max 4000] [--kdtree] [--accuracy 2000] [--cutoff-tol 0.03]``

The sparse core's pair pass is compiled with numba where it imports
(:mod:`swarm_envs.physics.compiled_pairs`); ``SWARM_ENVS_NUMBA=0`` times the numpy pass
instead. The header says which ran.

A full step is ``core.step(actions)`` followed by ``core.observe()`` (what every env
adapter does), for one swarm (B = 1, float64) with the default config except
``init_radius``, which is scaled as ``1.5 (N / 10)^{1/d}``
(:func:`swarm_envs.envs.sparse_core.density_preserving_radius`) so that every N starts
at the density of the default N = 10 case; with the default radius, 100,000 agents
would start 10^4 times denser. Random actions are drawn once per row (not timed).
Each cell is the median (and the best) of ``--repeats`` single steps after one
warm-up step; on a shared machine the medians are what a run sees.

Rows: N = 100 … ``--max-n``; the dense core only up to ``--dense-max`` (its
``(N, N)`` temporaries need about ``12 · 8 N²`` bytes). The crossover is then
bisected (geometrically) between the largest N where the dense core wins and the
smallest where the sparse core wins.

``--kdtree``: also time the neighbour work alone (all pairs within ``r_c`` plus the
k nearest neighbours) with the numpy cell list and with ``scipy.spatial.cKDTree``
(``query_pairs`` + ``query``), if scipy is importable.

``--accuracy N``: the per-agent force error of the cut-off at N agents after 1 and 20
steps of zero or random actions, next to the bound of
:func:`swarm_envs.physics.cutoff.force_error_bound` at the measured density and
relative speed. ``--cutoff-tol``: the sparse core's tolerance (default
:data:`~swarm_envs.envs.sparse_core.DEFAULT_CUTOFF_TOL`).
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

import numpy as np

from swarm_envs import tune_allocator
from swarm_envs.config import SwarmConfig
from swarm_envs.envs.core import SwarmNavCore
from swarm_envs.envs.sparse_core import (
    DEFAULT_CUTOFF_TOL,
    SPARSE_MIN_AGENTS,
    SparseSwarmNavCore,
    density_preserving_radius,
)
from swarm_envs.physics import compiled_pairs, forces
from swarm_envs.physics.cutoff import force_error_bound, sparse_forces
from swarm_envs.physics.neighbors import CELL_MARGIN, REACH, CellList, knn, radius_pairs

Core = type[SwarmNavCore] | type[SparseSwarmNavCore]


def config(n: int, dim: int) -> SwarmConfig:
    """The default scenario with N agents at the default start density."""
    return SwarmConfig(
        n_agents=n, dim=dim, init_radius=density_preserving_radius(n, dim), max_steps=10**9
    )


#: Keyword arguments of every SparseSwarmNavCore built here (set from the command line).
SPARSE_KWARGS: dict[str, float] = {}


def time_step(core_cls: Core, n: int, dim: int, repeats: int) -> tuple[float, float]:
    """``(median, best)`` seconds of one full step (step + observe) of one swarm."""
    kwargs = SPARSE_KWARGS if core_cls is SparseSwarmNavCore else {}
    core = core_cls(config(n, dim), **kwargs)
    core.reset(np.random.default_rng(0))
    actions = np.random.default_rng(1).uniform(-1.0, 1.0, (1, n, dim))
    core.step(actions)  # warm-up
    core.observe()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        core.step(actions)
        core.observe()
        times.append(time.perf_counter() - start)
    return statistics.median(times), min(times)


def time_call(fn: Callable[[], object], repeats: int) -> float:
    """Median seconds of ``fn()`` after one warm-up call."""
    fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def neighbour_work(n: int, dim: int, repeats: int) -> tuple[float, float | None, int]:
    """Seconds of the neighbour work (pairs within r_c + k nearest) with both methods.

    Returns ``(cell list, cKDTree or None, pairs)``.
    """
    cfg = config(n, dim)
    core = SparseSwarmNavCore(cfg, **SPARSE_KWARGS)
    core.reset(np.random.default_rng(0))
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


def crossover(dim: int, lo: int, hi: int, repeats: int) -> int:
    """Bisect (geometrically) the N where the sparse core starts to win, in ``(lo, hi]``."""
    while hi > lo * 1.15 and hi - lo > 8:
        mid = round(math.sqrt(lo * hi))
        dense = time_step(SwarmNavCore, mid, dim, repeats)[0]
        sparse = time_step(SparseSwarmNavCore, mid, dim, repeats)[0]
        print(f"  bisect N = {mid}: dense {dense * 1e3:.2f} ms, sparse {sparse * 1e3:.2f} ms")
        if sparse < dense:
            hi = mid
        else:
            lo = mid
    return hi


def accuracy(n: int, dim: int, cutoff_tol: float) -> None:
    """Largest per-agent force error of the cut-off vs its bound, at N agents."""
    cfg = config(n, dim)
    for policy in ("zero", "random"):
        core = SparseSwarmNavCore(cfg, cutoff_tol=cutoff_tol)
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
            ball = math.pi if dim == 2 else 4.0 * math.pi / 3.0
            at = ball * np.maximum(rho[:, 1:], core.cutoff) ** dim
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dim", type=int, default=2, choices=(2, 3))
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--max-n", type=int, default=100_000)
    parser.add_argument("--dense-max", type=int, default=4000)
    parser.add_argument("--kdtree", action="store_true")
    parser.add_argument("--accuracy", type=int, default=0, metavar="N")
    parser.add_argument("--cutoff-tol", type=float, default=DEFAULT_CUTOFF_TOL)
    args = parser.parse_args()
    print(f"glibc heap tuning (swarm_envs.tune_allocator) active: {tune_allocator()}")
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores; numpy {np.__version__}")
    dim, reps = args.dim, args.repeats
    SPARSE_KWARGS["cutoff_tol"] = args.cutoff_tol
    probe = SparseSwarmNavCore(config(10, dim), **SPARSE_KWARGS)
    print(
        f"d = {dim}; cut-off r_c = {probe.cutoff:.3f} (cutoff_tol {probe.cutoff_tol}, "
        f"cutoff_speed {probe.cutoff_speed}); SPARSE_MIN_AGENTS = {SPARSE_MIN_AGENTS}"
    )
    if compiled_pairs.numba_enabled():
        pair_pass = f"compiled (numba {importlib.metadata.version('numba')})"
    else:
        pair_pass = "numpy (numba missing, or SWARM_ENVS_NUMBA=0)"
    print(f"sparse pair pass: {pair_pass}")
    print()
    head = "| N | init_radius | dense s/step (median) | sparse s/step (median) | dense best | "
    head += "sparse best | dense / sparse |"
    if args.kdtree:
        head += " pairs/agent | neighbours: cell list s | cKDTree s |"
    print(head)
    print("|" + "---:|" * (head.count("|") - 1))
    sizes = [n for n in (100, 300, 1000, 3000, 10_000, 30_000, 100_000) if n <= args.max_n]
    winner: dict[int, str] = {}
    for n in sizes:
        sparse = time_step(SparseSwarmNavCore, n, dim, reps)
        dense = time_step(SwarmNavCore, n, dim, reps) if n <= args.dense_max else None
        line = f"| {n:,} | {density_preserving_radius(n, dim):.1f} | "
        if dense is None:
            line += f"— | {sparse[0]:.4f} | — | {sparse[1]:.4f} | — |"
        else:
            line += (
                f"{dense[0]:.4f} | {sparse[0]:.4f} | {dense[1]:.4f} | {sparse[1]:.4f} | "
                f"{dense[0] / sparse[0]:.1f} |"
            )
            winner[n] = "sparse" if sparse[0] < dense[0] else "dense"
        if args.kdtree:
            ours, tree, pairs = neighbour_work(n, dim, reps)
            line += f" {pairs / n:.0f} | {ours:.4f} | {'—' if tree is None else f'{tree:.4f}'} |"
        print(line, flush=True)
    print()
    lo = max([n for n, w in winner.items() if w == "dense"], default=10)
    hi = min([n for n, w in winner.items() if w == "sparse" and n > lo], default=None)
    if hi is None:
        print("the dense core won at the largest measured N: no crossover below --dense-max")
    else:
        n_cross = crossover(dim, lo, hi, max(reps, 15))
        print(f"crossover: the sparse core wins from about N = {n_cross} (d = {dim})")
    if args.accuracy:
        print()
        print(f"per-agent force error of the cut-off at N = {args.accuracy} (d = {dim}):")
        print()
        print(
            "| actions | steps | median |F_dense| | median error | max error "
            "| max |v_i − v_j| | density n | bound |"
        )
        print("|---|---:|---:|---:|---:|---:|---:|---:|")
        accuracy(args.accuracy, dim, args.cutoff_tol)


if __name__ == "__main__":
    main()
