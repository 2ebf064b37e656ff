"""Throughput of ``swarm_envs.physics.forces``: a table, not a test.

Usage: ``python benchmarks/physics.py [--repeats 5] [--seconds 0.5]``

Rows: one swarm at N = 10, 30, 100, 300, 1000 and batches B = 64, 1024 at N = 32, in
float64 and float32. Columns: ``forces()`` calls per second and agent-force
evaluations per second (calls/s × B × N). The median of ``--repeats`` timings, each
running for about ``--seconds``.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time

import numpy as np

from swarm_envs._malloc import keep_freed_memory
from swarm_envs.physics import SocialPotentialParams, forces, random_swarm

CASES = [((), 10), ((), 30), ((), 100), ((), 300), ((), 1000), ((64,), 32), ((1024,), 32)]


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
    print(f"glibc keep-freed-memory tuning active: {keep_freed_memory()}")
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


if __name__ == "__main__":
    main()
