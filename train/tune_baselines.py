"""``swarm-tune``: tune the simple baselines' gains on training seeds, write them to the configs.

For every entry of the benchmark matrix (``configs/benchmark/results.yaml``) and every
simple baseline of its task (:data:`agents.SIMPLE`), each point of the baseline's grid
(``configs/baselines/grids.yaml``) is evaluated on the entry's training env, on
``episodes`` episodes seeded with the grid file's ``seed`` — a training seed, never an
evaluation seed (``swarm-eval``, ``swarm-demo`` and ``swarm-benchmark`` evaluate on
others, and this command refuses theirs). The point with the highest mean return wins;
ties go to the earlier point. The winners are written to
``configs/baselines/tuned.yaml`` (``--out``), keyed by baseline and scenario
(``"<task>/<dynamics>"``, :func:`agents.tuned.scenario_key`), with the return they
scored, so that ``make_controller("pd", env)`` and every evaluation use them.

Exit status 0, or 2 with one line on stderr on a bad flag or file.
"""

from __future__ import annotations

import argparse
import itertools
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml

from agents.tuned import Gain
from swarm_envs.config import CONFIG_ROOT, SwarmConfig, load_swarm_config
from train.cli_common import CliError, OneLineParser, check_seed, fail
from train.config import read_yaml_mapping

__all__ = ["DEFAULT_GRIDS", "Grid", "grid_points", "load_grids", "main", "tune_scenario"]

PROG = "swarm-tune"

#: The grid file read unless ``--grids`` names another.
DEFAULT_GRIDS = CONFIG_ROOT / "baselines" / "grids.yaml"

#: A grid: each gain's values (numbers, or names such as ``saturation``'s).
Grid = dict[str, list[Gain]]


def evaluation_seeds() -> tuple[int, ...]:
    """The seeds the evaluations use (the benchmark's and the demo's, and the periodic
    evaluation's during training): a tuning seed must be none of them."""
    from train.benchmark.run import DEFAULT_EVAL_SEED
    from train.config import TrainConfig

    return (DEFAULT_EVAL_SEED, TrainConfig.eval_seed)


def load_grids(path: str | Path = DEFAULT_GRIDS) -> tuple[int, int, dict[str, Grid]]:
    """``(seed, episodes, {baseline: {gain: values}})`` from a grid file.

    Raises:
        ValueError: an unknown key, a baseline that is not a simple one, an empty grid
            or one of values that are neither numbers nor names, or an evaluation seed as
            the tuning seed.
    """
    from agents import CONTROLLERS, SIMPLE

    data = read_yaml_mapping(path, "grid file")
    unknown = sorted(set(data) - {"seed", "episodes", "grids"})
    if unknown:
        raise ValueError(
            f"{path}: unknown key(s) {', '.join(unknown)}; allowed: seed, episodes, grids"
        )
    seed = check_seed("seed", data.get("seed", 0))
    if seed in evaluation_seeds():
        raise ValueError(f"{path}: seed {seed} is an evaluation seed; tune on a training seed")
    episodes = data.get("episodes", 50)
    if not isinstance(episodes, int) or isinstance(episodes, bool) or episodes < 1:
        raise ValueError(f"{path}: episodes must be an integer >= 1, got {episodes!r}")
    simple = sorted({name for names in SIMPLE.values() for name in names})
    grids: dict[str, Grid] = {}
    for name, grid in dict(data.get("grids") or {}).items():
        if name not in simple or name not in CONTROLLERS:
            raise ValueError(
                f"{path}: grids.{name}: not a simple baseline; known: {', '.join(simple)}"
            )
        if not isinstance(grid, Mapping) or not grid:
            raise ValueError(f"{path}: grids.{name} must map gain names to lists of values")
        grids[name] = {}
        for gain, values in grid.items():
            if (
                not isinstance(values, list)
                or not values
                or not all(
                    isinstance(v, int | float | str) and not isinstance(v, bool) for v in values
                )
            ):
                raise ValueError(
                    f"{path}: grids.{name}.{gain} must be a non-empty list of numbers or names"
                )
            grids[name][str(gain)] = [v if isinstance(v, str) else float(v) for v in values]
    return seed, episodes, grids


def grid_points(grid: Grid) -> list[dict[str, Gain]]:
    """Every point of ``grid``, in order (the last gain varies fastest).

    >>> grid_points({"k_p": [1.0, 2.0], "saturation": ["box"]})
    [{'k_p': 1.0, 'saturation': 'box'}, {'k_p': 2.0, 'saturation': 'box'}]
    """
    names = list(grid)
    return [dict(zip(names, values, strict=True)) for values in itertools.product(*grid.values())]


def make_tuned(name: str, cfg: SwarmConfig, point: Mapping[str, Any]) -> Any:
    """The baseline ``name`` for ``cfg`` with the gains of one grid point."""
    from agents import CONTROLLERS

    return CONTROLLERS[name](cfg, **point)


def tune_scenario(
    name: str, cfg: SwarmConfig, grid: Grid, seed: int, episodes: int
) -> dict[str, Any]:
    """Evaluate every point of ``grid`` on ``cfg``; return the winner's record
    ``{"gains", "mean_return", "success_rate", "seed", "episodes", "points"}``."""
    from train.evaluate import evaluate_policies

    points = grid_points(grid)
    policies = {f"p{i}": make_tuned(name, cfg, p) for i, p in enumerate(points)}
    results = evaluate_policies(
        policies, cfg, episodes, seed, progress=False, gif=False, plots=False
    )
    scores = [results["policies"][f"p{i}"] for i in range(len(points))]
    best = max(range(len(points)), key=lambda i: (scores[i]["mean_return"], -i))
    return {
        "gains": points[best],
        "mean_return": round(float(scores[best]["mean_return"]), 4),
        "success_rate": round(float(scores[best]["success_rate"]), 4),
        "seed": seed,
        "episodes": episodes,
        "points": len(points),
    }


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``swarm-tune``; returns the exit status."""
    from train.benchmark.matrix import DEFAULT_MATRIX

    parser = OneLineParser(prog=PROG, description=__doc__.splitlines()[0])
    parser.add_argument(
        "--grids", default=str(DEFAULT_GRIDS), help="grid file (default: %(default)s)"
    )
    parser.add_argument(
        "--matrix",
        default=DEFAULT_MATRIX,
        help="benchmark matrix whose scenarios are tuned (default: %(default)s)",
    )
    parser.add_argument("--only", nargs="+", metavar="ENTRY", help="tune these matrix entries only")
    parser.add_argument(
        "--out", default=None, help="tuned gains file (default: configs/baselines/tuned.yaml)"
    )
    args = parser.parse_args(argv)
    try:
        return _main(args)
    except KeyboardInterrupt:
        print(
            f"{PROG}: interrupted by SIGINT; the tuned file keeps the scenarios done",
            file=sys.stderr,
        )
        return 130


def _main(args: argparse.Namespace) -> int:
    from agents import SIMPLE
    from agents.tuned import TUNED_PATH, scenario_key
    from train.benchmark.matrix import load_matrix

    out = Path(args.out) if args.out else TUNED_PATH
    try:
        seed, episodes, grids = load_grids(args.grids)
        entries = load_matrix(args.matrix).select(args.only)
        if out.exists() and not out.is_file():
            raise CliError(f"--out {out} is not a file")
    except (CliError, ValueError, OSError) as err:
        return fail(PROG, err)
    tuned: dict[str, dict[str, Any]] = {}
    if out.is_file():
        tuned = dict((yaml.safe_load(out.read_text(encoding="utf-8")) or {}).get("baselines", {}))
    for entry in entries:
        tc = entry.train_config(seed=seed)
        cfg = load_swarm_config(tc.env_config, tc.env)
        for name in SIMPLE[cfg.task]:
            if name not in grids:
                continue
            key = scenario_key(cfg)
            print(
                f"{PROG}: {name} on {key}: {len(grid_points(grids[name]))} points ...", flush=True
            )
            record = tune_scenario(name, cfg, grids[name], seed, episodes)
            tuned.setdefault(name, {})[key] = record
            print(
                f"  best {record['gains']}: return {record['mean_return']:.2f}, "
                f"success {record['success_rate']:.0%}",
                flush=True,
            )
            _write(out, tuned, args.grids)
    return 0


def _write(out: Path, tuned: Mapping[str, Any], grids: str) -> None:
    header = (
        "# Written by swarm-tune (train/tune_baselines.py) from the grids of\n"
        f"# {Path(grids).name}: per baseline and scenario (<task>/<dynamics>), the gains with\n"
        "# the highest mean return on the training seed; the controllers read them\n"
        "# (agents/tuned.py). Rerun `swarm-tune` rather than editing by hand.\n"
    )
    body = yaml.safe_dump({"baselines": dict(tuned)}, sort_keys=True)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(".tmp")
    tmp.write_text(header + body, encoding="utf-8")
    tmp.replace(out)


if __name__ == "__main__":
    sys.exit(main())
