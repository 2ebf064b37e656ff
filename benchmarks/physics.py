"""Throughput of ``swarm_envs.physics.forces``: a table, not a test.

Usage: ``python benchmarks/physics.py [--repeats 5] [--seconds 0.5]``

Table 1, the social potential's forces: one swarm at N = 10, 30, 100, 300, 1000 and
batches B = 64, 1024 at N = 32, in float64 and float32. Columns: ``forces()`` calls per
second and agent-force evaluations per second (calls/s × B × N).

Table 2, one step of each model of the seeds (float64, the SwarmNav navigation
parameters, ``dt = 0.1``): the social potential (semi-implicit Euler), Couzin's zone
model, Viscido's piecewise force model (with its random force) and the Lagrangian
gradient model (exact gradient, safe substeps; it advances its own state so that the
substep carries over, as in the env) at B × N = 1 × 32, 1 × 100, 64 × 32.

Every figure is the median of ``--repeats`` timings, each running for about ``--seconds``.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time

import numpy as np

from swarm_envs import tune_allocator
from swarm_envs.physics import (
    LagrangianParams,
    PiecewiseParams,
    SocialPotentialParams,
    ZoneParams,
    forces,
    random_swarm,
    step,
)
from swarm_envs.physics.lagrangian import lagrangian_step
from swarm_envs.physics.piecewise import piecewise_forces
from swarm_envs.physics.zone import zone_step

MODEL_CASES = [((), 32), ((), 100), ((64,), 32)]

CASES = [((), 10), ((), 30), ((), 100), ((), 300), ((), 1000), ((64,), 32), ((1024,), 32)]


def median_rate(fn, seconds: float, repeats: int) -> float:
    """Median calls per second of ``fn()`` over ``repeats`` windows of ``seconds``."""
    fn()  # warm-up
    rates = []
    for _ in range(repeats):
        calls, start = 0, time.perf_counter()
        while (elapsed := time.perf_counter() - start) < seconds:
            fn()
            calls += 1
        rates.append(calls / elapsed)
    return statistics.median(rates)


def model_steps(batch: tuple[int, ...], n: int) -> dict[str, object]:
    """One step function per model, on a random start spread like the env's."""
    rng = np.random.default_rng(0)
    x, v = random_swarm(rng, n, radius=0.5 * np.sqrt(n), speed=0.5, batch_shape=batch)
    heading = v / np.linalg.norm(v, axis=-1, keepdims=True)
    sp, zone = SocialPotentialParams.navigation(), ZoneParams.navigation(param_spread=0.0)
    pw, lag = PiecewiseParams.navigation(), LagrangianParams.navigation()
    noise = np.random.default_rng(1)
    dt = 0.1

    def piecewise_step() -> None:
        v2 = v + dt * piecewise_forces(x, v, pw, noise)
        _ = x + dt * v2

    state = {"x": x, "h": None}

    def lagrangian_frame() -> None:  # stateful, as in the env: the substep is carried
        state["x"], _, state["h"] = lagrangian_step(state["x"], lag, dt=dt, substep=state["h"])

    return {
        "social_potential": lambda: step(x, v, sp, dt=dt),
        "zone": lambda: zone_step(x, heading, zone, dt=dt),
        "piecewise": piecewise_step,
        "lagrangian": lagrangian_frame,
    }


def time_forces(batch: tuple[int, ...], n: int, dtype: type, seconds: float, repeats: int) -> float:
    """Median calls per second of ``forces`` on a random swarm of the given shape."""
    params = SocialPotentialParams()
    x, v = random_swarm(
        np.random.default_rng(0), n, radius=3.0, speed=0.5, batch_shape=batch, dtype=dtype
    )
    forces(x, v, params)  # warm-up
    rates = []
    for _ in range(repeats):
        calls, start = 0, time.perf_counter()
        while (elapsed := time.perf_counter() - start) < seconds:
            forces(x, v, params)
            calls += 1
        rates.append(calls / elapsed)
    return statistics.median(rates)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--seconds", type=float, default=0.5)
    args = parser.parse_args()
    print(f"glibc heap tuning (swarm_envs.tune_allocator) active: {tune_allocator()}")
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, {platform.processor() or ''}")
    print(f"numpy {np.__version__}, python {platform.python_version()}")
    print()
    header = ("B", "N", "dtype", "forces() calls/s", "agent-forces/s")
    print("| {:>5} | {:>5} | {:>7} | {:>16} | {:>14} |".format(*header))
    print(f"|{'-' * 7}|{'-' * 7}|{'-' * 9}|{'-' * 18}|{'-' * 16}|")
    for batch, n in CASES:
        for dtype in (np.float64, np.float32):
            rate = time_forces(batch, n, dtype, args.seconds, args.repeats)
            b = int(np.prod(batch)) if batch else 1
            print(
                f"| {b:>5} | {n:>5} | {np.dtype(dtype).name:>7} | {rate:>16,.0f} | "
                f"{rate * b * n / 1e6:>12.2f} M |"
            )
    print()
    print("| model | B | N | steps/s | agent-steps/s |")
    print("|---|---:|---:|---:|---:|")
    for batch, n in MODEL_CASES:
        b = int(np.prod(batch)) if batch else 1
        for name, fn in model_steps(batch, n).items():
            rate = median_rate(fn, args.seconds, args.repeats)
            print(f"| {name} | {b} | {n} | {rate:,.0f} | {rate * b * n / 1e6:.3f} M |")


if __name__ == "__main__":
    main()
