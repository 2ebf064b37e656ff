"""Substeps per step, throughput and trajectory error of the step-size rules.

Usage::

    python benchmarks/substeps.py [--steps 50] [--refine 20] [--batch 8] [--large-n 1000]
                                  [--seconds 1.0] [--json out.json]

For the navigation (``configs/env/paper_navigation.yaml`` at N = 32 and 128), large-swarm
(``configs/env/large_swarm.yaml`` at ``--large-n`` agents) and mill
(``configs/env/mill.yaml``) configs, each integrator (and its step-size rule,
``docs/models.md`` §7) integrates the same seeded starts for ``--steps`` steps of
``dt`` with zero actions (the passive physics), and the navigation swarm of 32 once more
driven as a whole by a constant action (``--drive`` along x, a fraction of ``u_max``), the
case in which an implicit treatment of the alignment that resists the swarm's collective
acceleration would show. Printed per row:

- ``substeps``: mean substeps per step;
- ``numpy`` / ``C``: agent-steps per second of the numpy core and of the C step
  (``step`` + ``observe``, one thread; CPU seconds in brackets);
- ``pos err``: the position RMS error after ``--steps`` steps against the reference, the
  same starts integrated by semi-implicit Euler with ``dt/--refine``; ``pos err/nnd`` the
  same over the reference's mean nearest-neighbour distance;
- ``ΔE``: the energy after ``--steps`` steps minus the reference's, over the reference's
  change of energy from the start (0: the same dissipation);
- ``Δpol``: the polarization after ``--steps`` steps minus the reference's;
- the physical state after ``--steps`` steps: mean speed, expanse and nearest-neighbour
  distance (``compare.swarm_state``), and polarization (and ``mill_order`` for the mill).

The trajectories run on the C step where it builds (numpy otherwise): every core computes
the same step (``tests/test_conformance.py``).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from typing import Any

import numpy as np

from swarm_envs.config import SwarmConfig, load_swarm_config
from swarm_envs.envs.cores.native import NativeSwarmNavCore, native_support
from swarm_envs.envs.cores.numpy import SwarmNavCore

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from compare import fmt, machine, swarm_state  # benchmarks/ is not a package

#: (name, config file, overrides, driven by a constant action)
CONFIGS: tuple[tuple[str, str, dict[str, Any], bool], ...] = (
    ("navigation N=32", "configs/env/paper_navigation.yaml", {"n_agents": 32}, False),
    ("navigation N=32 driven", "configs/env/paper_navigation.yaml", {"n_agents": 32}, True),
    ("navigation N=128", "configs/env/paper_navigation.yaml", {"n_agents": 128}, False),
    ("large swarm", "configs/env/large_swarm.yaml", {}, False),
    ("mill", "configs/env/mill.yaml", {}, False),
)

#: (row name, integrator, fraction of dt): the old and the new rule, and the new one at
#: a quarter of dt (its own convergence).
RULES: tuple[tuple[str, str, int], ...] = (
    ("semi_implicit_euler (Gershgorin)", "semi_implicit_euler", 1),
    ("implicit_damping_euler (block)", "implicit_damping_euler", 1),
    ("implicit_damping_euler, dt/4", "implicit_damping_euler", 4),
)


def config(path: str, overrides: dict[str, Any], integrator: str, dt_div: int) -> SwarmConfig:
    base = load_swarm_config(path, {**overrides, "max_steps": 10**9, "backend": "numpy"})
    return load_swarm_config(
        path,
        {
            **overrides,
            "max_steps": 10**9,
            "integrator": integrator,
            "dt": base.dt / dt_div,
            "max_substeps": max(base.max_substeps, 100),
            "on_unstable": "raise",
        },
    )


def core_for(cfg: SwarmConfig, batch: int, native: bool) -> Any:
    kind = NativeSwarmNavCore if native else SwarmNavCore
    core = kind(cfg, batch=batch, dtype=np.float64)
    core.reset(np.random.default_rng(0))
    return core


def run(cfg: SwarmConfig, batch: int, steps: int, native: bool, drive: float) -> dict[str, Any]:
    """Integrate ``steps`` steps with the action ``drive`` along x for every agent (0:
    the passive physics); the end state and the mean substeps."""
    core = core_for(cfg, batch, native)
    zero = np.zeros((batch, cfg.n_agents, cfg.dim))
    zero[..., 0] = drive
    e0 = core.stats()["energy"].copy()
    substeps = 0.0
    for _ in range(steps):
        core.step(zero)
        substeps += float(core.stats()["substeps"].mean())
    return {
        "x": np.array(core.x),
        "v": np.array(core.v),
        "stats": {k: np.array(val) for k, val in core.stats().items()},
        "e0": e0,
        "substeps": substeps / steps,
    }


def rate(cfg: SwarmConfig, batch: int, native: bool, seconds: float) -> tuple[float, float]:
    """Agent-steps per second (wall, and CPU seconds per wall second) of ``step`` +
    ``observe`` with zero actions, after one warm-up step."""
    core = core_for(cfg, batch, native)
    zero = np.zeros((batch, cfg.n_agents, cfg.dim))
    core.step(zero)
    n, w0, c0 = 0, time.perf_counter(), time.process_time()
    while time.perf_counter() - w0 < seconds:
        core.step(zero)
        core.observe()
        n += 1
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    return n * batch * cfg.n_agents / wall, cpu / wall


def rows_for(
    name: str, path: str, overrides: dict[str, Any], driven: bool, args: argparse.Namespace
) -> list:
    native = native_support()[0]
    drive = args.drive if driven else 0.0
    batch = 1 if name == "large swarm" else args.batch
    if name == "large swarm":
        overrides = {**overrides, "n_agents": args.large_n}
    ref_cfg = config(path, overrides, "semi_implicit_euler", args.refine)
    ref = run(ref_cfg, batch, args.steps * args.refine, native, drive)
    ref_state = swarm_state(ref["x"], ref["v"])
    out = []
    for label, integrator, div in RULES:
        cfg = config(path, overrides, integrator, div)
        res = run(cfg, batch, args.steps * div, native, drive)
        err = float(np.sqrt(((res["x"] - ref["x"]) ** 2).sum(-1).mean()))
        de_ref = ref["stats"]["energy"] - ref["e0"]
        de = (res["stats"]["energy"] - ref["stats"]["energy"]) / np.where(de_ref != 0, de_ref, 1)
        state = swarm_state(res["x"], res["v"])
        np_rate = rate(cfg, batch, False, args.seconds)
        c_rate = rate(cfg, batch, True, args.seconds) if native else (float("nan"), 0.0)
        out.append(
            {
                "config": name,
                "n_agents": cfg.n_agents,
                "batch": batch,
                "rule": label,
                "substeps": res["substeps"] * div,
                "numpy": np_rate,
                "native": c_rate,
                "pos_err": err,
                "pos_err_nnd": err / ref_state["nnd"],
                "dE": float(np.mean(de)),
                "dpol": float(np.mean(res["stats"]["polarization"] - ref["stats"]["polarization"])),
                **state,
                "polarization": float(res["stats"]["polarization"].mean()),
                "mill_order": float(res["stats"].get("mill_order", np.zeros(1)).mean()),
            }
        )
    out.append(
        {
            "config": name,
            "n_agents": ref_cfg.n_agents,
            "batch": batch,
            "rule": f"reference: semi_implicit_euler, dt/{args.refine}",
            "substeps": ref["substeps"] * args.refine,
            **ref_state,
            "polarization": float(ref["stats"]["polarization"].mean()),
            "mill_order": float(ref["stats"].get("mill_order", np.zeros(1)).mean()),
        }
    )
    return out


def table(rows: list[dict[str, Any]]) -> str:
    head = (
        "| config | rule | substeps / dt | numpy agent-steps/s | C agent-steps/s | pos err "
        "| pos err / nnd | ΔE | Δpol | speed | expanse | nnd | polarization | mill order |"
    )
    lines = [head, "|" + "---|" * 15]
    for r in rows:
        ref = "numpy" not in r

        def num(key: str, spec: str, r: dict[str, Any] = r, ref: bool = ref) -> str:
            return "" if ref else format(r[key], spec)

        speed = "" if ref else f"{fmt(r['numpy'][0])} ({r['numpy'][1]:.1f})"
        native = r.get("native", (float("nan"), 0.0))
        c = "" if native[0] != native[0] else f"{fmt(native[0])} ({native[1]:.1f})"
        lines.append(
            f"| {r['config']} ({r['batch']} × {r['n_agents']}) | {r['rule']} | "
            f"{r['substeps']:.2f} | {speed} | {c} | {num('pos_err', '.3g')} | "
            f"{num('pos_err_nnd', '.3g')} | {num('dE', '+.3f')} | {num('dpol', '+.3f')} | "
            f"{r['speed']:.3f} | {r['expanse']:.3f} | {r['nnd']:.3f} | "
            f"{r['polarization']:.3f} | {r['mill_order']:.3f} |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=50)
    parser.add_argument("--refine", type=int, default=20)
    parser.add_argument("--batch", type=int, default=8)
    parser.add_argument("--large-n", type=int, default=1000)
    parser.add_argument("--seconds", type=float, default=1.0)
    parser.add_argument("--drive", type=float, default=0.25)
    parser.add_argument("--configs", default=",".join(name for name, *_ in CONFIGS))
    parser.add_argument("--json")
    args = parser.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    wanted = set(args.configs.split(","))
    rows = []
    for name, path, overrides, driven in CONFIGS:
        if name in wanted:
            rows += rows_for(name, path, overrides, driven, args)
            print(table(rows[-len(RULES) - 1 :]), flush=True)
    print(f"\n{machine()}; {args.steps} steps of dt; drive {args.drive}\n")
    print(table(rows))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1, default=float)


if __name__ == "__main__":
    main()
