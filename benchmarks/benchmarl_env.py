"""Frames per second of the TorchRL env over the batched core against TorchRL's generic
``PettingZooWrapper``: a table (docs/ecosystem.md).

Usage: ``python benchmarks/benchmarl_env.py [--agents 10] [--batches 1,16,256,1024]
[--seconds 1] [--repeats 5] [--torch-threads K]``; needs the ``benchmarl`` extra
(``pip install -e ".[benchmarl]"``).

Each row times ``step_and_maybe_reset`` (what a TorchRL collector, and so BenchMARL,
calls each step) with one random action drawn before timing: TorchRL's
``PettingZooWrapper(swarm_nav_v0.parallel_env(...), return_state=True)`` (one swarm, a
Python dict per step), and :class:`train.benchmarl.SwarmTorchRLEnv` with
``return_state=True`` at each batch size B (B swarms in one core step); for reference,
the SB3 ``swarm_nav_v0.vec_env`` over the same core (``step``) at each B. SwarmNav's
defaults otherwise (400-step episodes, reset as they end). A frame is one swarm step
(BenchMARL's ``frames``); agent-steps are frames × N. Median and best of the windows,
which the rows take in turn; the ratio is against the wrapper's median.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
from collections.abc import Callable

import numpy as np
import torch

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
    parser.add_argument(
        "--torch-threads",
        type=int,
        default=None,
        help="torch.set_num_threads (the C step runs on torch's threads; default: torch's own)",
    )
    args = parser.parse_args()
    if args.torch_threads is not None:
        torch.set_num_threads(args.torch_threads)
    n = args.agents
    batches = [int(b) for b in args.batches.split(",")]

    from torchrl.envs import PettingZooWrapper

    # (label, B, one call); all built first, then timed window after window in turn, so
    # that the rows share the machine's load alike.
    steppers: list[tuple[str, int, Callable[[], None]]] = []
    wrapper = PettingZooWrapper(swarm_nav_v0.parallel_env(n_agents=n), return_state=True)
    wrapper.set_seed(0)
    steppers.append(("PettingZooWrapper(parallel_env)", 1, stepper(wrapper, ("agent", "action"))))
    for b in batches:
        env = SwarmTorchRLEnv(b, n_agents=n, return_state=True)
        env.set_seed(0)
        steppers.append((f"SwarmTorchRLEnv [{env.backend}]", b, stepper(env, ("agents", "action"))))
    for b in batches:
        vec = swarm_nav_v0.vec_env(b, n_agents=n)
        vec.seed(0)
        vec.reset()
        actions = np.random.default_rng(0).uniform(-1, 1, (b * n, 2)).astype(np.float32)
        steppers.append((f"vec_env (SB3) [{vec.backend}]", b, lambda v=vec, a=actions: v.step(a)))
    windows: list[list[float]] = [[] for _ in steppers]
    for _ in range(args.repeats):
        for per_row, (_, _, step) in zip(windows, steppers, strict=True):
            per_row.append(rates(step, args.seconds, 1)[0])
    rows = [
        (name, b, statistics.median(w), max(w))
        for (name, b, _), w in zip(steppers, windows, strict=True)
    ]

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
