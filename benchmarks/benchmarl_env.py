"""Frames per second of the TorchRL env over the batched core against TorchRL's generic
``PettingZooWrapper``: a table (docs/ecosystem.md).

Usage: ``python benchmarks/benchmarl_env.py [--agents 10] [--batches 1,16,256,1024]
[--seconds 1] [--repeats 5]`` (needs the ``benchmarl`` extra: ``pip install -e ".[benchmarl]"``).

Each row times ``step_and_maybe_reset`` (what a TorchRL collector, and so BenchMARL,
calls each step) with one random action drawn before timing: TorchRL's
``PettingZooWrapper(swarm_nav_v0.parallel_env(...), return_state=True)`` (one swarm, a
Python dict per step), and :class:`train.benchmarl.SwarmTorchRLEnv` with
``return_state=True`` at each batch size B (B swarms in one core step). SwarmNav's
defaults otherwise (400-step episodes, reset as they end). A frame is one swarm step
(BenchMARL's ``frames``); agent-steps are frames × N. Median and best of the repeated
windows; the ratio is against the wrapper's median.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable

from swarm_envs import swarm_nav_v0
from train.benchmarl import SwarmTorchRLEnv

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from compare import fmt, machine  # benchmarks/ is not a package
from envs import rates


def stepper(env, action_key: tuple[str, str]) -> Callable[[], None]:
    """One ``step_and_maybe_reset`` with a fixed random action (drawn here, not timed)."""
    td = env.reset()
    action = env.rand_action(td.clone()).get(action_key).clone()

    def step() -> None:
        nonlocal td
        td.set(action_key, action)
        _, td = env.step_and_maybe_reset(td)

    return step


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--agents", type=int, default=10, help="agents per swarm N (default 10)")
    parser.add_argument(
        "--batches",
        default="1,16,256,1024",
        help="swarms B of the batched env (default 1,16,256,1024)",
    )
    parser.add_argument("--seconds", type=float, default=1.0, help="timing window (default 1)")
    parser.add_argument("--repeats", type=int, default=5, help="windows per row (default 5)")
    args = parser.parse_args()
    n = args.agents
    batches = [int(b) for b in args.batches.split(",")]

    from torchrl.envs import PettingZooWrapper

    rows: list[tuple[str, int, float, float]] = []
    wrapper = PettingZooWrapper(swarm_nav_v0.parallel_env(n_agents=n), return_state=True)
    wrapper.set_seed(0)
    median, best = rates(stepper(wrapper, ("agent", "action")), args.seconds, args.repeats)
    rows.append(("PettingZooWrapper(parallel_env)", 1, median, best))
    for b in batches:
        env = SwarmTorchRLEnv(b, n_agents=n, return_state=True)
        env.set_seed(0)
        median, best = rates(stepper(env, ("agents", "action")), args.seconds, args.repeats)
        rows.append((f"SwarmTorchRLEnv [{env.backend}]", b, median, best))

    print(f"machine: {machine()}")
    print(
        f"SwarmNav, N = {n} agents, return_state=True, step_and_maybe_reset, "
        f"{args.repeats} windows of {args.seconds:g} s"
    )
    print()
    print("| env | B | frames/s (median) | agent-steps/s (median) | best | × wrapper |")
    print("|---|---:|---:|---:|---:|---:|")
    base = rows[0][2]
    for name, b, median, best in rows:
        print(
            f"| {name} | {b} | {fmt(median * b)} | {fmt(median * b * n)} | "
            f"{fmt(best * b * n)} | {median * b / base:.0f} |"
        )


if __name__ == "__main__":
    main()
