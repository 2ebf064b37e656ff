"""Throughput against the number of agents N and the batch size B, with a plot.

Usage::

    python benchmarks/scaling.py [--batches 1,4,16,64,256,1024] [--n-fixed 32]
                                 [--agents 8,16,32,64,128] [--b-fixed 64]
                                 [--seconds 0.3] [--repeats 5] [--peers]
                                 [--plot docs/img/throughput.png] [--json out.json]

Two sweeps: B at N = ``--n-fixed`` and N at B = ``--b-fixed``. Rows are those of
``benchmarks/compare.py`` (same step functions): the numpy core, the torch core plain
and compiled (full step: physics, observations, reward, statistics) and, with
``--peers`` and where importable, VMAS's navigation and minimal pairwise scenarios.
Each size's rows take turns window after window; the table gives the median and best
agent-steps/s, the plot the medians (log-log), with the machine in the title.
"""

from __future__ import annotations

import argparse
import json
import os
import sys

import torch

from swarm_envs import tune_allocator

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from compare import ROWS, compare, fmt, machine  # benchmarks/ is not a package

OURS = ("numpy core", "torch core (plain)", "torch core (compiled)")
PEERS = ("vmas navigation", "vmas pairwise")


def ints(text: str) -> list[int]:
    try:
        values = [int(v) for v in text.split(",")]
    except ValueError:
        raise SystemExit(f"expected a comma-separated list of integers, got {text!r}") from None
    if any(v < 1 for v in values):
        raise SystemExit(f"values must be >= 1, got {text!r}")
    return values


def sweep(sizes: list[tuple[int, int]], rows: tuple[str, ...], seconds: float, repeats: int):
    """``compare`` restricted to ``rows``, for every (N, B) in ``sizes``."""
    saved = list(ROWS)
    ROWS[:] = [r for r in saved if r[0] in rows]
    try:
        out = []
        for n, b in sizes:
            print(f"== N = {n}, B = {b} ==", flush=True)
            out += compare(n, b, seconds, repeats, physics=False)
            torch._dynamo.reset()  # drop compiled graphs of sizes already measured
        return out
    finally:
        ROWS[:] = saved


def plot(results: dict, path: str, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9.5, 3.8), constrained_layout=True)
    for ax, (key, xlabel, fixed) in zip(
        axes,
        [
            ("by_batch", "swarms B (batch)", f"N = {results['n_fixed']}"),
            ("by_agents", "agents N per swarm", f"B = {results['b_fixed']}"),
        ],
        strict=True,
    ):
        data = results[key]
        for row in dict.fromkeys(r["row"] for r in data):
            pts = sorted(
                (r["batch"] if key == "by_batch" else r["n_agents"], r["agent_steps_per_s_median"])
                for r in data
                if r["row"] == row
            )
            style = "-o" if row in OURS else "--s"
            ax.plot(*zip(*pts, strict=True), style, label=row, markersize=4)
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.set_xlabel(xlabel)
        ax.set_ylabel("agent-steps/s (median)")
        ax.set_title(fixed, fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7, loc="best")
    fig.suptitle(title, fontsize=8)
    os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
    fig.savefig(path, dpi=90)
    print(f"wrote {path}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batches", default="1,4,16,64,256,1024")
    parser.add_argument("--n-fixed", type=int, default=32)
    parser.add_argument("--agents", default="8,16,32,64,128")
    parser.add_argument("--b-fixed", type=int, default=64)
    parser.add_argument("--seconds", type=float, default=0.3)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=None)
    parser.add_argument("--peers", action="store_true", help="also time VMAS where importable")
    parser.add_argument("--plot", default="docs/img/throughput.png")
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    if args.threads is not None:
        torch.set_num_threads(args.threads)
    tune_allocator()
    rows = OURS + (PEERS if args.peers else ())
    print(f"machine: {machine()}")
    results = {
        "machine": machine(),
        "n_fixed": args.n_fixed,
        "b_fixed": args.b_fixed,
        "by_batch": sweep(
            [(args.n_fixed, b) for b in ints(args.batches)], rows, args.seconds, args.repeats
        ),
        "by_agents": sweep(
            [(n, args.b_fixed) for n in ints(args.agents)], rows, args.seconds, args.repeats
        ),
    }
    print("\n| row | N | B | agent-steps/s (median) | agent-steps/s (best) |")
    print("|---|---:|---:|---:|---:|")
    for r in results["by_batch"] + results["by_agents"]:
        print(
            f"| {r['row']} | {r['n_agents']} | {r['batch']} | "
            f"{fmt(r['agent_steps_per_s_median'])} | {fmt(r['agent_steps_per_s_best'])} |"
        )
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=1)
    if args.plot:
        plot(results, args.plot, f"SwarmNav step throughput — {results['machine']}")


if __name__ == "__main__":
    main()
