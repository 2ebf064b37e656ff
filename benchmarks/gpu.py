"""Throughput of the torch core on a GPU: one swarm and batched, up to 4096 × 128.

Usage: ``python benchmarks/gpu.py [--sizes 32x1,32x1024,32x4096,128x64,128x1024,128x4096]
[--seconds 1] [--repeats 5] [--device cuda] [--peers] [--json out.json]``

Rows per size (N agents × B swarms, float32, compiled):

- ``physics only``: one Euler step of the social potential
  (:class:`~swarm_envs._runtime.torch_compile.SocialPotentialStepper`);
- ``core, on device``: :meth:`TorchSwarmNavCore.step` with the actions as a CUDA tensor,
  then :meth:`~TorchSwarmNavCore.observe_tensor` (the observations stay on the GPU, as a
  GPU learner would take them; the ``(B, 11)`` statistics and rewards come to the host
  each step);
- ``core, to host``: the same with :meth:`~TorchSwarmNavCore.observe`, which copies the
  observations to a numpy array (what an SB3 VecEnv hands its policy);
- with ``--peers``, where ``vmas`` imports: ``vmas pairwise`` and ``vmas navigation``
  on the same GPU, the scenarios of ``benchmarks/compare.py`` (VMAS's simulator core
  with the cheapest observation and zero reward; its navigation scenario).

``benchmarks/gpu_check.sh`` runs this with the CUDA tests in one call on a machine
with a GPU (see its header for the wheels it needs there).

Every timed window ends with ``torch.cuda.synchronize``. Printed: median and best
agent-steps/s, the compile time of each core, and the GPU's name. Needs CUDA; prints
why and exits 0 without it.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

from swarm_envs._runtime.torch_compile import SocialPotentialStepper
from swarm_envs.config import SwarmConfig
from swarm_envs.envs.cores.torch.core import TorchSwarmNavCore
from swarm_envs.physics import SocialPotentialParams, random_swarm


def rates(
    fn: Callable[[], object], sync: Callable[[], None], seconds: float, repeats: int
) -> list[float]:
    """Calls per second over ``repeats`` windows of about ``seconds`` (synchronised)."""
    fn()
    sync()
    out = []
    for _ in range(repeats):
        calls, start = 0, time.perf_counter()
        while True:
            fn()
            calls += 1
            if calls % 8 == 0:
                sync()
                elapsed = time.perf_counter() - start
                if elapsed >= seconds:
                    break
        out.append(calls / elapsed)
    return out


def peer_rows(n: int, b: int, device: torch.device) -> list[tuple[str, None, Callable[[], object]]]:
    """VMAS's rows on ``device`` (none where ``vmas`` does not import)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from compare import vmas_navigation, vmas_pairwise

    rows: list[tuple[str, None, Callable[[], object]]] = []
    for label, make in (("vmas pairwise", vmas_pairwise), ("vmas navigation", vmas_navigation)):
        step = make(n, b, device=str(device))
        if step is not None:
            rows.append((label, None, step))
    return rows


def bench_size(
    n: int, b: int, device: torch.device, seconds: float, repeats: int, peers: bool = False
) -> list[dict]:
    sync = lambda: torch.cuda.synchronize(device)  # noqa: E731
    rows = []
    params = SocialPotentialParams.navigation()
    x, v = random_swarm(
        np.random.default_rng(0), n, radius=3.0, speed=0.5, batch_shape=(b,), dtype=np.float32
    )
    tx, tv = torch.from_numpy(x).to(device), torch.from_numpy(v).to(device)
    u = torch.from_numpy(np.random.default_rng(1).uniform(-3, 3, x.shape).astype(np.float32))
    u = u.to(device)
    stepper = SocialPotentialStepper(params, dt=0.1, compile=True)
    stepper.warmup(tx, tv, None, u)
    rows.append(("physics only", stepper.compile_seconds, lambda: stepper(tx, tv, None, u)))

    core = TorchSwarmNavCore(SwarmConfig(n_agents=n, max_steps=10**9), batch=b, device=device)
    core.reset(np.random.default_rng(0))
    a = torch.from_numpy(np.random.default_rng(2).uniform(-1, 1, (b, n, 2)).astype(np.float32))
    a = a.to(device)
    rows.append(
        ("core, on device", core.compile_seconds, lambda: (core.step(a), core.observe_tensor()))
    )
    rows.append(("core, to host", None, lambda: (core.step(a), core.observe())))
    if peers:
        rows += peer_rows(n, b, device)
    out = []
    for label, compile_s, fn in rows:
        r = rates(fn, sync, seconds, repeats)
        out.append(
            {
                "row": label,
                "n_agents": n,
                "batch": b,
                "compile_seconds": compile_s,
                "agent_steps_per_s_median": statistics.median(r) * n * b,
                "agent_steps_per_s_best": max(r) * n * b,
                "ms_per_step_median": 1e3 / statistics.median(r),
            }
        )
        print(
            f"| {label} | {n} | {b} | {out[-1]['agent_steps_per_s_median'] / 1e6:.2f} M | "
            f"{out[-1]['agent_steps_per_s_best'] / 1e6:.2f} M | "
            f"{out[-1]['ms_per_step_median']:.3f} | "
            f"{'' if compile_s is None else f'{compile_s:.1f}'} |",
            flush=True,
        )
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="32x1,32x1024,32x4096,128x64,128x1024,128x4096")
    parser.add_argument("--seconds", type=float, default=1.0)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--device", default="cuda")
    parser.add_argument("--peers", action="store_true", help="add VMAS's rows, same GPU")
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    if not torch.cuda.is_available():
        print("CUDA is not available: nothing to measure")
        return
    device = torch.device(args.device)
    name = torch.cuda.get_device_name(device)
    print(f"GPU: {name}; torch {torch.__version__}")
    print("| row | N | B | agent-steps/s (median) | (best) | ms/step (median) | compile s |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    results = []
    for size in args.sizes.split(","):
        n, b = (int(s) for s in size.lower().split("x"))
        results += bench_size(n, b, device, args.seconds, args.repeats, args.peers)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"gpu": name, "torch": torch.__version__, "results": results}, fh, indent=1)


if __name__ == "__main__":
    main()
