"""Throughput of the full SwarmNav step (physics + observations + reward + info): a table.

Usage: ``python benchmarks/envs.py [--seconds 1] [--repeats 5]``

Rows: ``parallel_env`` (PettingZoo dicts) and the Gymnasium env at N = 10, 32, 100
(float64 core); ``vec_env`` (SB3 VecEnv) at B × 32 for B = 1, 64, 1024 (float32 core)
on the backend ``"auto"`` picks (the label says which; the torch backend compiles once,
before timing), and at 64 and 1024 × 32 on the numpy backend.
Then the same ``parallel_env`` (N = 32) and ``vec_env`` (64 × 32) rows for each
``dynamics`` of the seeds (``--dynamics`` picks; default all four).
Random actions drawn once per row (not timed). Median and best of the
repeated windows. The 1024-swarm VecEnv uses its default worker threads (one per 512
swarms, up to the CPU count). If ``vmas`` is importable, its navigation scenario is
timed in the same run at the same N and the ratio printed.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import statistics
import time
from collections.abc import Callable

import numpy as np

import swarm_envs  # noqa: F401  (registers the Gymnasium id)
from swarm_envs import swarm_nav_v0, tune_allocator
from swarm_envs.config import DYNAMICS, SwarmConfig
from swarm_envs.envs.backends import select_backend


def rates(fn: Callable[[], None], seconds: float, repeats: int) -> tuple[float, float]:
    """``(median, best)`` calls per second of ``fn`` over ``repeats`` windows of ``seconds``.

    On a shared machine the spread is wide (host contention); the best window is the code's
    speed, the median what a run typically sees. Both are printed.
    """
    fn()
    out = []
    for _ in range(repeats):
        calls, start = 0, time.perf_counter()
        while (elapsed := time.perf_counter() - start) < seconds:
            fn()
            calls += 1
        out.append(calls / elapsed)
    return statistics.median(out), max(out)


def bench_parallel(
    n: int, seconds: float, repeats: int, dynamics: str = "social_potential"
) -> tuple[float, float]:
    env = swarm_nav_v0.parallel_env(n_agents=n, max_steps=10**9, dynamics=dynamics)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    actions = {a: rng.uniform(-1, 1, 2).astype(np.float32) for a in env.possible_agents}
    return rates(lambda: env.step(actions), seconds, repeats)


def bench_gym(n: int, seconds: float, repeats: int) -> tuple[float, float]:
    import gymnasium as gym

    env = gym.make("swarm_envs/SwarmNav-v0", n_agents=n, max_steps=10**9, max_episode_steps=10**9)
    env.reset(seed=0)
    action = np.random.default_rng(0).uniform(-1, 1, env.action_space.shape).astype(np.float32)
    return rates(lambda: env.step(action), seconds, repeats)


def bench_vec(
    b: int,
    n: int,
    seconds: float,
    repeats: int,
    dynamics: str = "social_potential",
    backend: str = "auto",
) -> tuple[float, float]:
    venv = swarm_nav_v0.vec_env(b, n_agents=n, max_steps=200, dynamics=dynamics, backend=backend)
    venv.seed(0)
    venv.reset()
    actions = np.random.default_rng(0).uniform(-1, 1, (venv.num_envs, 2)).astype(np.float32)
    return rates(lambda: venv.step(actions), seconds, repeats)


def bench_vmas(n: int, b: int, seconds: float, repeats: int) -> tuple[float, float] | None:
    try:
        import torch
        import vmas
    except ImportError:
        return None
    # VMAS spawns agents and goals by rejection sampling at 0.25 spacing in a box of
    # half-width 1 by default, which never finishes for N = 32: widen it with sqrt(N).
    half_width = max(1.0, 0.5 * math.sqrt(n))
    env = vmas.make_env(
        "navigation",
        num_envs=b,
        device="cpu",
        n_agents=n,
        continuous_actions=True,
        world_spawning_x=half_width,
        world_spawning_y=half_width,
    )
    env.reset()
    acts = [torch.zeros(b, 2) for _ in range(n)]
    return rates(lambda: env.step(acts), seconds, repeats)


def row(api: str, b: int, n: int, rate: tuple[float, float]) -> str:
    med, best = rate
    return (
        f"| {api} | {b} | {n} | {med:,.0f} | {best:,.0f} | "
        f"{med * b * n / 1e6:.3f} M | {best * b * n / 1e6:.3f} M |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=1.0)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--dynamics", nargs="+", default=list(DYNAMICS), choices=DYNAMICS)
    args = parser.parse_args()
    print(f"glibc heap tuning (swarm_envs.tune_allocator) active: {tune_allocator()}")
    s, r = args.seconds, args.repeats
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores; numpy {np.__version__}")
    print()
    print(
        "| API | swarms B | agents N | steps/s (median) | steps/s (best) "
        "| agent-steps/s (median) | agent-steps/s (best) |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|")
    for n in (10, 32, 100):
        print(row("parallel_env", 1, n, bench_parallel(n, s, r)))
    for n in (10, 32, 100):
        print(row("gym.make", 1, n, bench_gym(n, s, r)))
    for b in (1, 64, 1024):
        backend = select_backend(SwarmConfig(n_agents=32), b)
        print(row(f"vec_env ({backend})", b, 32, bench_vec(b, 32, s, r)))
    for b in (64, 1024):
        print(row("vec_env (numpy)", b, 32, bench_vec(b, 32, s, r, backend="numpy")))
    for dynamics in args.dynamics:
        print(row(f"parallel_env ({dynamics})", 1, 32, bench_parallel(32, s, r, dynamics)))
        print(row(f"vec_env ({dynamics})", 64, 32, bench_vec(64, 32, s, r, dynamics)))
    for n, b in ((32, 1), (32, 1024)):
        vmas_rate = bench_vmas(n, b, s, r)
        if vmas_rate is None:
            print("\n(vmas not importable: no side-by-side ratio)")
            break
        ours = bench_parallel(n, s, r) if b == 1 else bench_vec(b, n, s, r)
        print(
            row("vmas navigation", b, n, vmas_rate) + f" ours/vmas (median) = "
            f"{ours[0] / vmas_rate[0]:.1f}x"
        )


if __name__ == "__main__":
    main()
