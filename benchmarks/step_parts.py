"""Where one VecEnv step on the C step spends its time: the C call and the Python around it.

Usage::

    python benchmarks/step_parts.py [--sizes 32x1024,32x64,128x64] [--steps 400]
                                    [--integrator implicit_damping_euler] [--threads 1]

Steps the SB3 VecEnv (``backend="native"``, random actions, ``max_steps=200``) with timers
wrapped around its layers, and prints per size the time of a whole step and, nested, of
the task layer's step, the core's ``advance``, the C call itself (every call: the step's
and the re-measures of the swarms that were reset) and the Python parts of each layer, in
microseconds per step and nanoseconds per agent-step. The timers cost about a microsecond
per wrapped call, so the whole step is timed first without them. The split of the C call
itself (pair passes, neighbour search, observations, statistics) needs a profiler: build
the C step with ``CFLAGS=-g`` (a build at first use) and run ``perf record`` on this
script; ``docs/performance.md`` ("Where a step's time goes at 32 × 1,024") gives the split.
"""

from __future__ import annotations

import argparse
import functools
import time
from collections import defaultdict
from collections.abc import Callable
from typing import Any

import numpy as np

from swarm_envs import swarm_nav_v0
from swarm_envs.envs.task import layer

#: What is timed: (label, the object's attribute path from the VecEnv or the module).
PARTS = (
    ("VecEnv step_wait", "venv.step_wait"),
    ("  episode ends and resets", "venv._end_episodes"),
    ("  quiet infos", "venv._quiet_infos.infos"),
    ("  swarm infos", "venv._swarm_infos.infos"),
    ("  task layer step", "core.task.step"),
    ("    reward", "core.task._reward"),
    ("    records", "core.task.records.follow"),
    ("    core advance", "core.advance"),
    ("      statistics columns", "core._unpack"),
    ("      C calls", "core._fn"),
)


def _wrap(owner: Any, name: str, label: str, spent: dict[str, float]) -> None:
    fn: Callable[..., Any] = getattr(owner, name)

    @functools.wraps(fn)
    def timed(*args: Any, **kwargs: Any) -> Any:
        start = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            spent[label] += time.perf_counter() - start

    setattr(owner, name, timed)


def measure(n: int, b: int, steps: int, integrator: str | None) -> None:
    kwargs: dict[str, Any] = {} if integrator is None else {"integrator": integrator}
    venv = swarm_nav_v0.vec_env(b, n_agents=n, max_steps=200, backend="native", **kwargs)
    venv.seed(0)
    venv.reset()
    actions = np.random.default_rng(0).uniform(-1, 1, (venv.num_envs, 2)).astype(np.float32)
    for _ in range(10):
        venv.step(actions)
    start = time.perf_counter()
    for _ in range(steps):
        venv.step(actions)
    bare = (time.perf_counter() - start) / steps
    spent: dict[str, float] = defaultdict(float)
    roots = {"venv": venv, "core": venv.cores[0]}
    for label, path in PARTS:
        root, *attrs, name = path.split(".")
        owner = roots[root]
        for attr in attrs:
            owner = getattr(owner, attr)
        _wrap(owner, name, label, spent)
    _wrap(layer, "episode_end", "    episode end", spent)
    _wrap(layer, "beyond_bound", "    unstable guard's check", spent)
    start = time.perf_counter()
    for _ in range(steps):
        venv.step(actions)
    timed = (time.perf_counter() - start) / steps
    scale = 1e9 / (n * b)
    print(f"\n{n} x {b} ({integrator or 'default integrator'}), {steps} steps")
    print(f"  {'whole step (no timers)':34s} {bare * 1e6:9.1f} us  {bare * scale:7.1f} ns/agent")
    print(f"  {'whole step (with the timers)':34s} {timed * 1e6:9.1f} us")
    for label, _ in (*PARTS, ("    episode end", ""), ("    unstable guard's check", "")):
        per_step = spent[label] / steps
        print(f"  {label:34s} {per_step * 1e6:9.1f} us  {per_step * scale:7.1f} ns/agent")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="32x1024,32x64,128x64", help="N x B pairs")
    parser.add_argument("--steps", type=int, default=400)
    parser.add_argument("--integrator", default=None)
    parser.add_argument("--threads", type=int, default=None, help="torch.set_num_threads")
    args = parser.parse_args()
    if args.threads is not None:
        import torch

        torch.set_num_threads(args.threads)
    for size in args.sizes.split(","):
        n, b = (int(v) for v in size.split("x"))
        measure(n, b, args.steps, args.integrator)


if __name__ == "__main__":
    main()
