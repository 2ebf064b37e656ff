"""Side by side: swarm_envs (numpy and torch cores) against VMAS and MPE2, same N and batch.

Usage::

    python benchmarks/compare.py [--sizes 32x1,32x64,32x1024] [--seconds 0.5] [--repeats 5]
                                 [--threads T] [--json out.json] [--no-physics] [--rows R1,R2]
                                 [--update-docs]

Installs nothing. VMAS rows appear where ``vmas`` imports, MPE2 rows where ``mpe2``
imports (try a separate venv: ``python3.11 -m venv /tmp/peers && /tmp/peers/bin/pip
install -c constraints.txt vmas==1.5.2 mpe2 -e .``).

Every row is one ``step`` of B swarms (environments) of N agents, timed in windows of
about ``--seconds``; the rows of one size take turns, window after window, ``--repeats``
times, so that a busy machine slows them all alike. Printed: median and best
agent-steps/s (steps/s × B × N) and the ratio of each row's median to the numpy core's;
then, per size, how many times the physics alone the full step costs (the target for
the VecEnv is 2×).

Rows, ours (all with random actions in [−1, 1], drawn once per row):

- ``numpy core``: :class:`SwarmNavCore` (float32) ``step`` + ``observe`` (physics,
  observations, reward, statistics);
- ``numpy vec_env``: :class:`SwarmNavVecEnv` ``step`` (adds SB3's per-slot infos and the
  auto-reset bookkeeping);
- ``torch core (plain)`` / ``(compiled)``: :class:`TorchSwarmNavCore`, the same work as
  the numpy core, its step in plain torch or through ``torch.compile``;
- ``native core``: :class:`NativeSwarmNavCore`, the step in C (where a C compiler
  builds it);
- ``native vec_env`` / ``torch vec_env (compiled)``: the SB3 VecEnv on the C step (the
  default) or on the compiled torch core;
- ``native vec_env (implicit damping)``: the same VecEnv on the C step with
  ``integrator="implicit_damping_euler"`` (``docs/models.md`` §7: about one substep per
  step where the damping limits the explicit rule);
- ``physics only``: one semi-implicit Euler step of the social potential model, numpy
  and torch plain/compiled (no observations, reward or statistics).

Peers:

- ``vmas navigation``: VMAS's ``navigation`` scenario (lidar observations, goal reward),
  its spawn box widened ∝ √N (VMAS's rejection sampling of 2N entities in its default
  2 × 2 box never finishes at N = 32);
- ``vmas pairwise``: a minimal VMAS scenario defined here, N disc agents and nothing
  else: VMAS's simulator core (all-pairs collision forces, integration) with the
  cheapest observation (own position and velocity) and zero reward, the closest
  VMAS analogue of our "physics only";
- ``mpe2 simple_spread``: MPE2's ``simple_spread_v3`` (N agents, N landmarks) through its
  PettingZoo ``parallel_env``; MPE2 has no batching, so B environments are B Python
  objects stepped in a loop (run for B ≤ 64 and B × N ≤ 2048 only: seconds per step
  beyond).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch

import swarm_envs  # noqa: F401  (registers the Gymnasium id)
from swarm_envs import swarm_nav_v0, tune_allocator
from swarm_envs._runtime.torch_compile import SocialPotentialStepper
from swarm_envs.config import SwarmConfig
from swarm_envs.envs.cores.native import NativeSwarmNavCore, native_support
from swarm_envs.envs.cores.numpy import SwarmNavCore
from swarm_envs.envs.cores.torch.core import TorchSwarmNavCore
from swarm_envs.physics import SocialPotentialParams, random_swarm
from swarm_envs.physics import step as numpy_step

Step = Callable[[], Any]

#: Largest batch, and largest B × N, for which MPE2's per-environment loop is timed.
MPE2_MAX_BATCH = 64
MPE2_MAX_AGENTS = 2048


def machine() -> str:
    """One line naming the machine and the libraries."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            names = [ln.split(":", 1)[1].strip() for ln in fh if ln.startswith("model name")]
        cpu = names[0] if names else cpu
    except OSError:
        pass
    return (
        f"{cpu}, {os.cpu_count()} cores, torch {torch.__version__} "
        f"({torch.get_num_threads()} threads), numpy {np.__version__}, "
        f"python {platform.python_version()}"
    )


def actions_for(shape: tuple[int, ...], seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-1, 1, shape).astype(np.float32)


# --------------------------------------------------------------------------- ours


def numpy_core(n: int, b: int) -> Step:
    core = SwarmNavCore(SwarmConfig(n_agents=n, max_steps=10**9), batch=b, dtype=np.float32)
    core.reset(np.random.default_rng(0))
    a = actions_for((b, n, 2))
    return lambda: (core.step(a), core.observe())


def numpy_vec_env(n: int, b: int) -> Step:
    venv = swarm_nav_v0.vec_env(b, n_agents=n, max_steps=200, backend="numpy")
    venv.seed(0)
    venv.reset()
    a = actions_for((venv.num_envs, 2))
    return lambda: venv.step(a)


def swarm_state(x: np.ndarray, v: np.ndarray) -> dict[str, float]:
    """The physical state a row timed: mean speed, expanse, nearest-neighbour distance."""
    x, v = np.asarray(x, np.float64), np.asarray(v, np.float64)
    n = x.shape[-2]
    rho = np.linalg.norm(x[..., :, None, :] - x[..., None, :, :], axis=-1)
    rho[..., np.arange(n), np.arange(n)] = np.inf
    return {
        "speed": float(np.linalg.norm(v, axis=-1).mean()),
        "expanse": float(np.linalg.norm(x - x.mean(axis=-2, keepdims=True), axis=-1).mean()),
        "nnd": float(rho.min(axis=-1).mean()) if n > 1 else 0.0,
    }


def parallel_env(n: int, b: int) -> Step | None:
    """One PettingZoo ``parallel_env`` step with the dict API, default backend (B = 1)."""
    if b != 1:
        return None
    env = swarm_nav_v0.parallel_env(n_agents=n, max_cycles=200)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    actions = {a: rng.uniform(-1, 1, 2).astype(np.float32) for a in env.possible_agents}

    def step() -> None:
        if not env.agents:
            env.reset()
        env.step(actions)

    step.state = lambda: swarm_state(env.core.x, env.core.v)  # type: ignore[attr-defined]
    return step


def vec_env(
    backend: str, integrator: str = "semi_implicit_euler"
) -> Callable[[int, int], Step | None]:
    """The SB3 VecEnv on ``backend``: ``"native"`` (the C step, the default where it
    builds) or ``"torch"`` (the torch core, compiled), with ``integrator``."""

    def make(n: int, b: int) -> Step | None:
        if backend == "native" and not native_support()[0]:
            return None
        venv = swarm_nav_v0.vec_env(
            b, n_agents=n, max_steps=200, backend=backend, integrator=integrator
        )
        assert venv.backend == backend, venv.backend
        if backend == "torch":
            print(f"    (torch vec_env {b} x {n}: ready in {venv.core.compile_seconds:.1f} s)")
        venv.seed(0)
        venv.reset()
        a = actions_for((venv.num_envs, 2))

        def step() -> Any:
            return venv.step(a)

        step.state = lambda: swarm_state(venv.cores[0].x, venv.cores[0].v)  # type: ignore[attr-defined]
        return step

    return make


def native_core(n: int, b: int) -> Step | None:
    """:class:`NativeSwarmNavCore` (float32) ``step`` + ``observe``."""
    if not native_support()[0]:
        return None
    core = NativeSwarmNavCore(SwarmConfig(n_agents=n, max_steps=10**9), batch=b, dtype=np.float32)
    core.reset(np.random.default_rng(0))
    a = actions_for((b, n, 2))
    return lambda: (core.step(a), core.observe())


def torch_core(kernel: str) -> Callable[[int, int], Step | None]:
    """:class:`TorchSwarmNavCore` ``step`` + ``observe``, ``"plain"`` or ``"compiled"``."""

    def make(n: int, b: int) -> Step | None:
        cfg = SwarmConfig(n_agents=n, max_steps=10**9)
        core = TorchSwarmNavCore(cfg, batch=b, compile=kernel == "compiled")
        if kernel != "plain":
            print(f"    (torch core {b} x {n}, {kernel}: ready in {core.compile_seconds:.1f} s)")
        core.reset(np.random.default_rng(0))
        a = actions_for((b, n, 2))
        return lambda: (core.step(a), core.observe())

    return make


def physics_numpy(n: int, b: int) -> Step:
    params = SocialPotentialParams.navigation()
    x, v = random_swarm(
        np.random.default_rng(0), n, radius=3.0, speed=0.5, batch_shape=(b,), dtype=np.float32
    )
    u = 3.0 * actions_for(x.shape)
    return lambda: numpy_step(x, v, params, dt=0.1, control=u)


def physics_torch(compile: bool) -> Callable[[int, int], Step]:
    def make(n: int, b: int) -> Step:
        params = SocialPotentialParams.navigation()
        x, v = random_swarm(
            np.random.default_rng(0), n, radius=3.0, speed=0.5, batch_shape=(b,), dtype=np.float32
        )
        tx, tv = torch.from_numpy(x), torch.from_numpy(v)
        u = torch.from_numpy(3.0 * actions_for(x.shape))
        stepper = SocialPotentialStepper(params, dt=0.1, compile=compile)
        stepper.warmup(tx, tv, None, u)
        if compile:
            print(f"    (physics {b} x {n}: compiled in {stepper.compile_seconds:.1f} s)")
        return lambda: stepper(tx, tv, None, u)

    return make


# --------------------------------------------------------------------------- peers


def vmas_navigation(n: int, b: int, device: str = "cpu") -> Step | None:
    try:
        import vmas
    except ImportError:
        return None
    half_width = max(1.0, 0.5 * math.sqrt(n))  # see the module docstring
    env = vmas.make_env(
        "navigation",
        num_envs=b,
        device=device,
        n_agents=n,
        continuous_actions=True,
        world_spawning_x=half_width,
        world_spawning_y=half_width,
    )
    env.reset()
    acts = [torch.from_numpy(actions_for((b, 2), seed=i)).to(device) for i in range(n)]
    return lambda: env.step(acts)


def vmas_pairwise(n: int, b: int, device: str = "cpu") -> Step | None:
    try:
        import vmas
        from vmas.simulator.core import Agent, Sphere, World
        from vmas.simulator.scenario import BaseScenario
    except ImportError:
        return None

    class Pairwise(BaseScenario):
        """N disc agents and nothing else: VMAS's all-pairs collision physics."""

        def make_world(self, batch_dim: int, device: torch.device, **kwargs: Any) -> World:
            world = World(batch_dim, device)
            for i in range(n):
                world.add_agent(Agent(name=f"agent_{i}", shape=Sphere(0.05), u_multiplier=1.0))
            return world

        def reset_world_at(self, env_index: int | None = None) -> None:
            half = max(1.0, 0.5 * math.sqrt(n))
            for agent in self.world.agents:
                shape = (1 if env_index is not None else self.world.batch_dim, 2)
                pos = (torch.rand(shape, device=self.world.device) * 2 - 1) * half
                agent.set_pos(pos if env_index is None else pos[0], batch_index=env_index)

        def observation(self, agent: Agent) -> torch.Tensor:
            return torch.cat([agent.state.pos, agent.state.vel], dim=-1)

        def reward(self, agent: Agent) -> torch.Tensor:
            return torch.zeros(self.world.batch_dim, device=self.world.device)

    env = vmas.make_env(Pairwise(), num_envs=b, device=device, continuous_actions=True)
    env.reset()
    acts = [torch.from_numpy(actions_for((b, 2), seed=i)).to(device) for i in range(n)]
    return lambda: env.step(acts)


def mpe2_spread(n: int, b: int) -> Step | None:
    if b > MPE2_MAX_BATCH or b * n > MPE2_MAX_AGENTS:
        return None
    try:
        from mpe2 import simple_spread_v3
    except ImportError:
        return None
    envs = [
        simple_spread_v3.parallel_env(N=n, continuous_actions=True, max_cycles=10**9)
        for _ in range(b)
    ]
    for i, env in enumerate(envs):
        env.reset(seed=i)
    acts = [
        {a: np.abs(actions_for((5,), seed=j)) for j, a in enumerate(env.possible_agents)}
        for env in envs
    ]

    def step() -> None:
        for env, act in zip(envs, acts, strict=True):
            env.step(act)

    return step


ROWS: list[tuple[str, Callable[[int, int], Step | None], bool]] = [
    # (label, factory, physics-only row?)
    ("numpy core", numpy_core, False),
    ("numpy vec_env", numpy_vec_env, False),
    ("torch core (plain)", torch_core("plain"), False),
    ("torch core (compiled)", torch_core("compiled"), False),
    ("native core", native_core, False),
    ("torch vec_env (compiled)", vec_env("torch"), False),
    ("native vec_env", vec_env("native"), False),
    ("native vec_env (implicit damping)", vec_env("native", "implicit_damping_euler"), False),
    ("pettingzoo parallel_env", parallel_env, False),
    ("vmas navigation", vmas_navigation, False),
    ("vmas pairwise", vmas_pairwise, False),
    ("mpe2 simple_spread", mpe2_spread, False),
    ("physics only, numpy", physics_numpy, True),
    ("physics only, torch plain", physics_torch(False), True),
    ("physics only, torch compiled", physics_torch(True), True),
]


def time_window(fn: Step, seconds: float) -> float:
    """Calls per second over one window of about ``seconds`` (at least one call)."""
    calls, start = 0, time.perf_counter()
    while True:
        fn()
        calls += 1
        elapsed = time.perf_counter() - start
        if elapsed >= seconds:
            return calls / elapsed


def compare(
    n: int, b: int, seconds: float, repeats: int, physics: bool, only: set[str] | None = None
) -> list[dict]:
    """Time every available row at N = n, B = b, alternating; one dict per row (the rows
    named in ``only``, where given)."""
    steps: dict[str, Step] = {}
    for label, factory, is_physics in ROWS:
        if (is_physics and not physics) or (only is not None and label not in only):
            continue
        fn = factory(n, b)
        if fn is None:
            continue
        fn()  # warm-up (caches, first allocation)
        steps[label] = fn
    rates: dict[str, list[float]] = {label: [] for label in steps}
    for _ in range(repeats):
        for label, fn in steps.items():
            rates[label].append(time_window(fn, seconds))
    states = {label: fn.state() for label, fn in steps.items() if hasattr(fn, "state")}
    return [
        {
            "row": label,
            "n_agents": n,
            "batch": b,
            "state": states.get(label),
            "steps_per_s_median": statistics.median(r),
            "steps_per_s_best": max(r),
            "agent_steps_per_s_median": statistics.median(r) * n * b,
            "agent_steps_per_s_best": max(r) * n * b,
        }
        for label, r in rates.items()
    ]


def table(results: list[dict]) -> str:
    """The throughput table (markdown), with each timed env's physical state."""
    lines = [
        "| row | N | B | agent-steps/s (median) | agent-steps/s (best) | vs numpy core "
        "(median) | state at the end (speed, expanse, NND) |",
        "|---|---:|---:|---:|---:|---:|---|",
    ]
    for size in sorted({(r["n_agents"], r["batch"]) for r in results}):
        rows = [r for r in results if (r["n_agents"], r["batch"]) == size]
        base = next((r for r in rows if r["row"] == "numpy core"), None)
        for r in rows:
            ratio = (
                f"{r['agent_steps_per_s_median'] / base['agent_steps_per_s_median']:.2f}x"
                if base
                else "-"
            )
            st = r.get("state")
            state = f"{st['speed']:.2f}, {st['expanse']:.2f}, {st['nnd']:.3f}" if st else ""
            lines.append(
                f"| {r['row']} | {r['n_agents']} | {r['batch']} | "
                f"{fmt(r['agent_steps_per_s_median'])} | {fmt(r['agent_steps_per_s_best'])} "
                f"| {ratio} | {state} |"
            )
    return "\n".join(lines)


#: (full-step row, physics-only row) pairs of the "cost of the full step" table.
FULL_VS_PHYSICS = (
    ("torch core (compiled)", "physics only, torch compiled"),
    ("native core", "physics only, torch compiled"),
    ("torch vec_env (compiled)", "physics only, torch compiled"),
    ("native vec_env", "physics only, torch compiled"),
    ("numpy core", "physics only, numpy"),
    ("pettingzoo parallel_env", "physics only, numpy"),
)


def full_vs_physics(results: list[dict]) -> str:
    """How many times the physics alone costs the full step (markdown).

    Both rows of a ratio come from the same run, their windows alternating; a ratio of
    medians and a ratio of bests (the bests are the least disturbed windows).
    """
    lines = []
    for size in sorted({(r["n_agents"], r["batch"]) for r in results}):
        rows = {r["row"]: r for r in results if (r["n_agents"], r["batch"]) == size}
        for full, physics in FULL_VS_PHYSICS:
            if full in rows and physics in rows:
                f, p = rows[full], rows[physics]
                median = p["agent_steps_per_s_median"] / f["agent_steps_per_s_median"]
                best = p["agent_steps_per_s_best"] / f["agent_steps_per_s_best"]
                lines.append(
                    f"| {full} | {physics} | {size[0]} | {size[1]} | {median:.2f}x | {best:.2f}x |"
                )
    if not lines:
        return ""
    head = [
        "| full step | physics alone | N | B | time ratio (medians) | time ratio (bests) |",
        "|---|---|---:|---:|---:|---:|",
    ]
    return "\n".join(head + lines)


#: The rows set against VMAS's simulator core in the "against VMAS" table.
VS_VMAS = ("native vec_env", "native vec_env (implicit damping)", "native core")


def against_vmas(results: list[dict]) -> str:
    """Each of :data:`VS_VMAS` over ``vmas pairwise``, per size (markdown; empty without
    VMAS): ratios of medians and of bests, both rows from the same run."""
    lines = []
    for size in sorted({(r["n_agents"], r["batch"]) for r in results}):
        rows = {r["row"]: r for r in results if (r["n_agents"], r["batch"]) == size}
        peer = rows.get("vmas pairwise")
        if peer is None:
            continue
        for label in VS_VMAS:
            if label in rows:
                ours = rows[label]
                median = ours["agent_steps_per_s_median"] / peer["agent_steps_per_s_median"]
                best = ours["agent_steps_per_s_best"] / peer["agent_steps_per_s_best"]
                lines.append(f"| {label} | {size[0]} | {size[1]} | {median:.1f}x | {best:.1f}x |")
    if not lines:
        return ""
    head = [
        "| ours | N | B | over vmas pairwise (medians) | (bests) |",
        "|---|---:|---:|---:|---:|",
    ]
    return "\n".join(head + lines)


#: The block of docs/performance.md that ``--update-docs`` rewrites.
DOCS_BEGIN, DOCS_END = "<!-- begin compare.py -->", "<!-- end compare.py -->"


def update_docs(path: Path, text: str) -> None:
    """Replace the block between :data:`DOCS_BEGIN` and :data:`DOCS_END` of ``path``."""
    doc = path.read_text()
    if DOCS_BEGIN not in doc or DOCS_END not in doc:
        raise SystemExit(f"{path} has no {DOCS_BEGIN} ... {DOCS_END} block")
    head, rest = doc.split(DOCS_BEGIN, 1)
    tail = rest.split(DOCS_END, 1)[1]
    path.write_text(f"{head}{DOCS_BEGIN}\n{text}\n{DOCS_END}{tail}")


def fmt(rate: float) -> str:
    if rate >= 1e6:
        return f"{rate / 1e6:.2f} M"
    if rate >= 1e3:
        return f"{rate / 1e3:.1f} k"
    return f"{rate:.0f}"


def parse_sizes(text: str) -> list[tuple[int, int]]:
    """``"32x1,32x1024"`` → ``[(32, 1), (32, 1024)]`` (N x B)."""
    sizes = []
    for part in text.split(","):
        try:
            n, b = (int(v) for v in part.lower().split("x"))
        except ValueError:
            raise SystemExit(f"--sizes: expected NxB pairs like 32x1024, got {part!r}") from None
        if n < 1 or b < 1:
            raise SystemExit(f"--sizes: N and B must be >= 1, got {part!r}")
        sizes.append((n, b))
    return sizes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="32x1,32x64,32x1024", help="N x B pairs")
    parser.add_argument("--seconds", type=float, default=0.5, help="length of one window")
    parser.add_argument("--repeats", type=int, default=5, help="windows per row")
    parser.add_argument("--threads", type=int, default=None, help="torch.set_num_threads")
    parser.add_argument("--json", default=None, help="also write the results here")
    parser.add_argument("--no-physics", action="store_true", help="skip physics-only rows")
    parser.add_argument(
        "--rows", default=None, help="comma-separated row labels to time (default: all)"
    )
    parser.add_argument(
        "--update-docs", action="store_true", help="rewrite the tables of docs/performance.md"
    )
    args = parser.parse_args()
    if args.threads is not None:
        torch.set_num_threads(args.threads)
    tune_allocator()
    print(f"machine: {machine()}")
    for mod in ("vmas", "mpe2"):
        try:
            version = getattr(__import__(mod), "__version__", "?")
            print(f"{mod} {version}: importable")
        except ImportError:
            print(f"{mod}: not importable (its rows are skipped)")
    labels = {label for label, _, _ in ROWS}
    only = None if args.rows is None else {r.strip() for r in args.rows.split(",")}
    if only is not None and not only <= labels:
        raise SystemExit(f"--rows: unknown {sorted(only - labels)}; rows: {sorted(labels)}")
    results: list[dict] = []
    for n, b in parse_sizes(args.sizes):
        print(f"\n== N = {n}, B = {b} ==", flush=True)
        results += compare(n, b, args.seconds, args.repeats, not args.no_physics, only)
    command = " ".join(["python benchmarks/compare.py", *sys.argv[1:]])
    text = (
        f"Measured by `{command.replace(' --update-docs', '')}` on {machine()}.\n\n"
        f"{table(results)}\n\nCost of the full step (observations, reward, statistics; "
        f"the dict API for PettingZoo) over the physics alone:\n\n{full_vs_physics(results)}"
    )
    vs_vmas = against_vmas(results)
    if vs_vmas:
        text += f"\n\nAgainst VMAS's simulator core (`vmas pairwise`), same run:\n\n{vs_vmas}"
    print()
    print(text)
    if args.update_docs:
        update_docs(Path(__file__).resolve().parent.parent / "docs" / "performance.md", text)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"machine": machine(), "results": results}, fh, indent=1)


if __name__ == "__main__":
    main()
