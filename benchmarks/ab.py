"""A/B in one run: the same rows timed on two versions of the code, window after window.

Usage::

    python benchmarks/ab.py --base HEAD~1 [--sizes 32x1,32x1024,64x128]
                            [--rows vec_env,torch_vec_env,parallel_env,physics]
                            [--seconds 0.5] [--repeats 7] [--tune-allocator] [--json out.json]
                            [--large-swarm] [--zero-actions] [--integrator NAME]

``--base`` is a git revision (checked out into a temporary worktree) or a folder holding
another checkout. Each version runs in its own worker process (``PYTHONPATH`` pointing
at its tree); the parent asks them in turn to time one window of each row, so that a
busy machine slows both alike, and prints the medians, their ratio (this tree over the
base: above 1 is faster) and the physical state of the swarms at the end of the timing
(mean speed, expanse, nearest-neighbour distance), so that both timed the same physics.

``--large-swarm`` runs every row on the large-swarm parameter set
(``SocialPotentialParams.large_swarm()``, given as plain values so that older versions
take it too) at its start density 0.3; with ``--zero-actions`` (every row) the swarms stay
at that density and a step takes one substep at every N: rows that time the same work in
versions with and without step-size control (compare the printed states).

``--integrator NAME`` sets ``SwarmConfig.integrator`` of the env rows (``vec_env``,
``torch_vec_env``, ``parallel_env``; e.g. ``implicit_damping_euler``, which the torch
core refuses); the ``physics`` row stays the bare semi-implicit Euler step. A version
that does not know the integrator fails on that row, naming it.

Rows (the same API calls in both versions):

- ``vec_env``: the SB3 VecEnv on the C step (``backend="native"``; in versions whose
  torch backend ran the C step, ``backend="torch"``), random actions;
- ``torch_vec_env``: the SB3 VecEnv on the compiled torch core (``SWARM_ENVS_NATIVE=0``);
- ``parallel_env``: one PettingZoo ``parallel_env`` step (dict API) with the default
  backend, at N × 1 only;
- ``physics``: one bare numpy semi-implicit Euler step of the social potential model
  (``swarm_envs.physics.step``), the reference of the other rows.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

WORKER = r"""
import json, os, sys, time
import numpy as np

def make(row, n, b, tune, env):
    env = dict(env)
    zero = env.get("_zero_actions", False)
    import swarm_envs
    from swarm_envs import config, swarm_nav_v0
    if tune:
        if hasattr(swarm_envs, "tune_allocator"):
            swarm_envs.tune_allocator()
        else:
            from swarm_envs._malloc import keep_freed_memory
            keep_freed_memory()
    rng = np.random.default_rng(0)
    if row == "physics":
        from swarm_envs.physics import SocialPotentialParams, random_swarm, step
        if "physics" in env:
            p = SocialPotentialParams(**env["physics"])
        else:
            p = SocialPotentialParams.navigation()
        radius = env.get("init_radius", 1.5)
        x, v = random_swarm(rng, n, radius=radius, speed=0.1, batch_shape=(b,))
        u = 0.0 * x if zero else 3.0 * rng.uniform(-1, 1, x.shape)
        return (lambda: step(x, v, p, dt=0.1, control=u)), (lambda: state_of(x, v))
    if row == "parallel_env":
        kw = {k: v for k, v in env.items() if k != "_zero_actions"}
        env = swarm_nav_v0.parallel_env(n_agents=n, max_cycles=200, **kw)
        env.reset(seed=0)
        acts = {a: rng.uniform(-1, 1, 2).astype(np.float32) for a in env.possible_agents}
        if zero:
            acts = {a: 0.0 * act for a, act in acts.items()}
        def step():
            if not env.agents:
                env.reset()
            env.step(acts)
        return step, (lambda: state_of(env.core.x, env.core.v))
    if row == "vec_env":
        backend = "native" if "native" in config.BACKENDS else "torch"
        env.pop("_zero_actions", None)
        venv = swarm_nav_v0.vec_env(b, n_agents=n, max_steps=200, backend=backend, **env)
        env["_zero_actions"] = zero
    else:  # the compiled torch core (earlier versions ran the C step inside it)
        os.environ["SWARM_ENVS_NATIVE"] = "0"
        try:
            kw = {k: v for k, v in env.items() if k != "_zero_actions"}
            venv = swarm_nav_v0.vec_env(b, n_agents=n, max_steps=200, backend="torch", **kw)
        finally:
            del os.environ["SWARM_ENVS_NATIVE"]
    venv.seed(0)
    venv.reset()
    a = rng.uniform(-1, 1, (venv.num_envs, 2)).astype(np.float32)
    if env.pop("_zero_actions", False):
        a[:] = 0.0
    core = venv.cores[0]
    return (lambda: venv.step(a)), (lambda: state_of(core.x, core.v))

def state_of(x, v):
    x, v = np.asarray(x), np.asarray(v)
    speed = float(np.linalg.norm(v, axis=-1).mean())
    expanse = float(np.linalg.norm(x - x.mean(axis=-2, keepdims=True), axis=-1).mean())
    d = np.linalg.norm(x[..., :, None, :] - x[..., None, :, :], axis=-1)
    n = x.shape[-2]
    d[..., np.arange(n), np.arange(n)] = np.inf
    nnd = float(d.min(axis=-1).mean()) if n > 1 else 0.0
    return {"speed": speed, "expanse": expanse, "nnd": nnd}

rows = {}
for line in sys.stdin:
    cmd = json.loads(line)
    if cmd["op"] == "make":
        key = (cmd["row"], cmd["n"], cmd["b"])
        fn, state = make(cmd["row"], cmd["n"], cmd["b"], cmd["tune"], cmd.get("env", {}))
        fn()
        rows[key] = (fn, state)
        print(json.dumps({"ok": True}), flush=True)
    elif cmd["op"] == "time":
        fn, _ = rows[(cmd["row"], cmd["n"], cmd["b"])]
        calls, start = 0, time.perf_counter()
        while True:
            fn()
            calls += 1
            elapsed = time.perf_counter() - start
            if elapsed >= cmd["seconds"]:
                break
        print(json.dumps({"rate": calls / elapsed}), flush=True)
    elif cmd["op"] == "state":
        _, state = rows[(cmd["row"], cmd["n"], cmd["b"])]
        print(json.dumps(state()), flush=True)
"""


#: ``SocialPotentialParams.large_swarm()`` as plain values, and its start density.
LARGE_SWARM = dict(
    C_a=4.0, C_r=64.0, l_a=0.5, l_r=0.25, C_o=0.5, l_o=1.0, beta=1.0, C_g=30.0, l_g=10.0
)
LARGE_SWARM_DENSITY = 0.3


def large_swarm_env(n: int) -> dict:
    """VecEnv keywords of the large-swarm set for ``n`` agents (2-D start disc)."""
    import math

    return {"physics": LARGE_SWARM, "init_radius": math.sqrt(n / (math.pi * LARGE_SWARM_DENSITY))}


class Worker:
    """One version of the code in its own process."""

    def __init__(self, tree: Path) -> None:
        env = {**os.environ, "PYTHONPATH": str(tree)}
        env.pop("SWARM_ENVS_NATIVE", None)
        self.proc = subprocess.Popen(
            [sys.executable, "-c", WORKER],
            cwd=tree,
            env=env,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )

    def ask(self, **cmd: object) -> dict:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write(json.dumps(cmd) + "\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError(f"worker failed on {cmd}")
        return json.loads(line)

    def close(self) -> None:
        if self.proc.stdin:
            self.proc.stdin.close()
        self.proc.wait(timeout=60)


def base_tree(base: str, root: Path, tmp: Path) -> Path:
    """``base`` as a folder: itself if it is one, else a worktree of that revision."""
    if Path(base).is_dir():
        return Path(base).resolve()
    tree = tmp / "base"
    subprocess.run(
        ["git", "-C", str(root), "worktree", "add", "--detach", str(tree), base],
        check=True,
        capture_output=True,
    )
    return tree


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", required=True, help="git revision or folder")
    parser.add_argument("--sizes", default="32x1,32x1024,64x128", help="N x B pairs")
    parser.add_argument("--rows", default="vec_env,torch_vec_env,parallel_env,physics")
    parser.add_argument("--seconds", type=float, default=0.5)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--tune-allocator", action="store_true", help="tune glibc in both")
    parser.add_argument("--json", default=None)
    parser.add_argument("--large-swarm", action="store_true", help="the large-swarm set")
    parser.add_argument(
        "--zero-actions", action="store_true", help="VecEnv rows with zero actions (passive)"
    )
    parser.add_argument("--integrator", default=None, help="SwarmConfig.integrator of the env rows")
    args = parser.parse_args()
    root = Path(__file__).resolve().parent.parent
    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    rows = args.rows.split(",")
    with tempfile.TemporaryDirectory() as tmp:
        trees = {"base": base_tree(args.base, root, Path(tmp)), "this": root}
        workers = {name: Worker(tree) for name, tree in trees.items()}
        results = []
        try:
            for n, b in sizes:
                for row in rows:
                    if row == "parallel_env" and b != 1:
                        continue
                    spec = dict(row=row, n=n, b=b)
                    env = large_swarm_env(n) if args.large_swarm else {}
                    if args.zero_actions:
                        env["_zero_actions"] = True
                    if args.integrator is not None and row != "physics":
                        env["integrator"] = args.integrator
                    for w in workers.values():
                        w.ask(op="make", tune=args.tune_allocator, env=env, **spec)
                    rates: dict[str, list[float]] = {name: [] for name in workers}
                    for _ in range(args.repeats):
                        for name, w in workers.items():
                            rates[name].append(
                                w.ask(op="time", seconds=args.seconds, **spec)["rate"]
                            )
                    state = {name: w.ask(op="state", **spec) for name, w in workers.items()}
                    med = {name: statistics.median(r) for name, r in rates.items()}
                    results.append({**spec, "median": med, "state": state})
                    print(
                        f"{row:14s} N={n:<4d} B={b:<5d} base {med['base'] * n * b / 1e6:8.3f} M "
                        f"this {med['this'] * n * b / 1e6:8.3f} M agent-steps/s  "
                        f"this/base {med['this'] / med['base']:.2f}x",
                        flush=True,
                    )
        finally:
            for w in workers.values():
                w.close()
            if trees["base"] != Path(args.base).resolve() and not Path(args.base).is_dir():
                subprocess.run(
                    ["git", "-C", str(root), "worktree", "remove", "--force", str(trees["base"])],
                    check=False,
                    capture_output=True,
                )
    print("\n| row | N | B | base (agent-steps/s) | this | this / base | state (base → this) |")
    print("|---|---:|---:|---:|---:|---:|---|")
    for r in results:
        n, b = r["n"], r["b"]
        s0, s1 = r["state"]["base"], r["state"]["this"]
        state = (
            f"speed {s0['speed']:.2f}→{s1['speed']:.2f}, expanse {s0['expanse']:.2f}→"
            f"{s1['expanse']:.2f}, NND {s0['nnd']:.3f}→{s1['nnd']:.3f}"
        )
        print(
            f"| {r['row']} | {n} | {b} | {r['median']['base'] * n * b / 1e6:.2f} M | "
            f"{r['median']['this'] * n * b / 1e6:.2f} M | "
            f"{r['median']['this'] / r['median']['base']:.2f}x | {state} |"
        )
    by = {(r["row"], r["n"], r["b"]): r["median"] for r in results}
    for n, b in sizes:
        if b == 1 and ("parallel_env", n, 1) in by and ("physics", n, 1) in by:
            env, phys = by[("parallel_env", n, 1)], by[("physics", n, 1)]
            print(
                f"\nparallel_env step / bare numpy Euler step at N = {n} (throughput): "
                f"base {env['base'] / phys['base']:.2f}x, this {env['this'] / phys['this']:.2f}x"
            )
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
