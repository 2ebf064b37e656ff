"""Throughput of the full SwarmNav step (physics + observations + reward + info): a table.

Usage: ``python benchmarks/envs.py [--seconds 2] [--repeats 3]``

Rows: ``parallel_env`` (PettingZoo dicts) and the Gymnasium env at N = 10, 32, 100;
``vec_env`` (SB3 VecEnv) at B × 32 for B = 1, 64, 1024 (float64 core). Random actions
drawn once per row (not timed). If ``vmas`` is importable, its navigation scenario is
timed in the same run at the same N and the ratio printed.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time
from collections.abc import Callable

import numpy as np

import swarm_envs  # noqa: F401  (registers the Gymnasium id)
from swarm_envs import swarm_nav_v0
from swarm_envs._malloc import keep_freed_memory


def median_rate(fn: Callable[[], None], seconds: float, repeats: int) -> float:
    """Median calls per second of ``fn`` over ``repeats`` windows of ``seconds``."""
    fn()
    rates = []
    for _ in range(repeats):
        calls, start = 0, time.perf_counter()
        while (elapsed := time.perf_counter() - start) < seconds:
            fn()
            calls += 1
        rates.append(calls / elapsed)
    return statistics.median(rates)


def bench_parallel(n: int, seconds: float, repeats: int) -> float:
    env = swarm_nav_v0.parallel_env(n_agents=n, max_steps=10**9)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    actions = {a: rng.uniform(-1, 1, 2).astype(np.float32) for a in env.possible_agents}
    return median_rate(lambda: env.step(actions), seconds, repeats)


def bench_gym(n: int, seconds: float, repeats: int) -> float:
    import gymnasium as gym

    env = gym.make("swarm_envs/SwarmNav-v0", n_agents=n, max_steps=10**9, max_episode_steps=10**9)
    env.reset(seed=0)
    action = np.random.default_rng(0).uniform(-1, 1, env.action_space.shape).astype(np.float32)
    return median_rate(lambda: env.step(action), seconds, repeats)


def bench_vec(b: int, n: int, seconds: float, repeats: int) -> float:
    venv = swarm_nav_v0.vec_env(b, n_agents=n, max_steps=200)
    venv.seed(0)
    venv.reset()
    actions = np.random.default_rng(0).uniform(-1, 1, (venv.num_envs, 2)).astype(np.float32)
    return median_rate(lambda: venv.step(actions), seconds, repeats)


def bench_vmas(n: int, b: int, seconds: float, repeats: int) -> float | None:
    try:
        import torch
        import vmas
    except ImportError:
        return None
    env = vmas.make_env("navigation", num_envs=b, device="cpu", n_agents=n, continuous_actions=True)
    env.reset()
    acts = [torch.zeros(b, 2) for _ in range(n)]
    return median_rate(lambda: env.step(acts), seconds, repeats)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=2.0)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    print(f"glibc keep-freed-memory tuning active: {keep_freed_memory()}")
    s, r = args.seconds, args.repeats
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores; numpy {np.__version__}")
    print()
    print("| API | swarms B | agents N | steps/s | agent-steps/s |")
    print("|---|---:|---:|---:|---:|")
    for n in (10, 32, 100):
        rate = bench_parallel(n, s, r)
        print(f"| parallel_env | 1 | {n} | {rate:,.0f} | {rate * n / 1e6:.3f} M |")
    for n in (10, 32, 100):
        rate = bench_gym(n, s, r)
        print(f"| gym.make | 1 | {n} | {rate:,.0f} | {rate * n / 1e6:.3f} M |")
    for b in (1, 64, 1024):
        rate = bench_vec(b, 32, s, r)
        print(f"| vec_env | {b} | 32 | {rate:,.0f} | {rate * b * 32 / 1e6:.3f} M |")
    for n, b in ((32, 1), (32, 1024)):
        vmas_rate = bench_vmas(n, b, s, r)
        if vmas_rate is None:
            print("\n(vmas not importable: no side-by-side ratio)")
            break
        ours = bench_parallel(n, s, r) if b == 1 else bench_vec(b, n, s, r)
        print(
            f"| vmas navigation | {b} | {n} | {vmas_rate:,.0f} | "
            f"{vmas_rate * b * n / 1e6:.3f} M | ours / vmas = {ours / vmas_rate:.1f}x |"
        )


if __name__ == "__main__":
    main()
