"""``swarm-tune``: tune the simple baselines' gains on training seeds, write them to the configs.

For every entry of the benchmark matrix (``configs/benchmark/results.yaml``) and every
simple baseline of its task (:data:`agents.SIMPLE`), each point of the baseline's grid
(``configs/baselines/grids.yaml``) is evaluated on the entry's training env, on
``episodes`` episodes seeded with the grid file's ``seed`` — a training seed, never an
evaluation seed (``swarm-eval``, ``swarm-demo`` and ``swarm-benchmark`` evaluate on
others, and this command refuses theirs). The point with the highest mean return wins;
ties go to the earlier point. The winners are written to
``configs/baselines/tuned.yaml`` (``--out``), keyed by baseline and scenario
(``"<task>/<dynamics>"``, with ``"/informed=<f>"`` for an entry trained at one informed
fraction: :func:`agents.tuned.scenario_key`), with the return they scored, so that
``make_controller("pd", env)`` and every evaluation use them. Entries that share a
scenario are tuned once.

Where one of a baseline's grid points can fail in rare episodes (a flock that stalls),
a few episodes may not hold one, and the grid's best on them can be a point that fails
more often: where the grid file asks for it (``select: {<baseline>: {top, episodes}}``),
the grid's ``top`` best points are scored again on ``episodes`` episodes of the same seed,
and the best of them is the grid's winner (then refined on those episodes).

A grid is coarse: where the grid file asks for it (``refine: {rounds, factor}``), the
grid's winner is then refined on the same episodes by a local search: each round tries
every numeric gain of the current best multiplied and divided by ``factor`` (a zero
gain stays zero; a value the baseline refuses, out of its gain's range, is skipped) and
every other value the grid lists for each named gain (such as ``saturation``), and
moves to the best of them if it scores higher; the search stops after ``rounds`` rounds
or at a round that finds nothing better.

Exit status 0, or 2 with one line on stderr on a bad flag or file.
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from agents.tuned import Gain
from swarm_envs.config import CONFIG_ROOT, SwarmConfig, load_swarm_config
from train.cli_common import CliError, OneLineParser, check_seed, fail
from train.config import read_yaml_mapping

__all__ = [
    "DEFAULT_GRIDS",
    "Grid",
    "Refinement",
    "Selection",
    "grid_points",
    "load_grids",
    "main",
    "refinement_points",
    "tune_scenario",
]

PROG = "swarm-tune"

#: The grid file read unless ``--grids`` names another.
DEFAULT_GRIDS = CONFIG_ROOT / "baselines" / "grids.yaml"

#: A grid: each gain's values (numbers, or names such as ``saturation``'s).
Grid = dict[str, list[Gain]]

#: Points scored between two progress lines (``tune_scenario(progress=True)``).
PROGRESS_POINTS = 500


@dataclass(frozen=True)
class Refinement:
    """The local search after the grid (module docstring): at most ``rounds`` rounds
    (0: none), numeric gains stepped by ``factor > 1``."""

    rounds: int = 0
    factor: float = 1.25


@dataclass(frozen=True)
class Selection:
    """The second look at the grid's best points (module docstring): its ``top ≥ 1``
    best points scored again on ``episodes ≥ 1`` episodes."""

    top: int
    episodes: int


def evaluation_seeds() -> tuple[int, ...]:
    """The seeds the evaluations use (the benchmark's and the demo's, and the periodic
    evaluation's during training): a tuning seed must be none of them."""
    from train.benchmark.run import DEFAULT_EVAL_SEED
    from train.config import TrainConfig

    return (DEFAULT_EVAL_SEED, TrainConfig.eval_seed)


def load_grids(
    path: str | Path = DEFAULT_GRIDS,
) -> tuple[int, int, dict[str, Grid], Refinement, dict[str, Selection]]:
    """``(seed, episodes, {baseline: {gain: values}}, refinement, {baseline: selection})``
    from a grid file.

    Raises:
        ValueError: an unknown key, a baseline that is not a simple one, an empty grid
            or one of values that are neither numbers nor names, an evaluation seed as
            the tuning seed, a ``refine`` section that is not ``{rounds: integer >= 0,
            factor: number > 1}``, or a ``select`` section that does not map baselines
            of ``grids`` to ``{top: integer >= 1, episodes: integer >= 1}``.
    """
    from agents import CONTROLLERS, SIMPLE

    data = read_yaml_mapping(path, "grid file")
    unknown = sorted(set(data) - {"seed", "episodes", "grids", "refine", "select"})
    if unknown:
        raise ValueError(
            f"{path}: unknown key(s) {', '.join(unknown)}; allowed: seed, episodes, grids, "
            "refine, select"
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
    refinement = _refinement(path, data.get("refine"))
    return seed, episodes, grids, refinement, _selections(path, data.get("select"), grids)


def _selections(path: str | Path, section: Any, grids: Mapping[str, Grid]) -> dict[str, Selection]:
    if section is None:
        return {}
    if not isinstance(section, Mapping):
        raise ValueError(
            f"{path}: select must map baselines to {{top: integer >= 1, episodes: integer "
            f">= 1}}, got {section!r}"
        )
    out: dict[str, Selection] = {}
    for name, entry in section.items():
        if name not in grids:
            raise ValueError(
                f"{path}: select.{name}: not a baseline of grids; known: {', '.join(grids)}"
            )
        values = dict(entry) if isinstance(entry, Mapping) else {}
        counts = all(
            isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in values.values()
        )
        if set(values) != {"top", "episodes"} or not counts:
            raise ValueError(
                f"{path}: select.{name} must be {{top: integer >= 1, episodes: integer >= 1}}, "
                f"got {entry!r}"
            )
        out[str(name)] = Selection(values["top"], values["episodes"])
    return out


def _refinement(path: str | Path, section: Any) -> Refinement:
    if section is None:
        return Refinement()
    problem = ValueError(
        f"{path}: refine must be a mapping {{rounds: integer >= 0, factor: number > 1}}, "
        f"got {section!r}"
    )
    if not isinstance(section, Mapping) or set(section) - {"rounds", "factor"}:
        raise problem
    rounds = section.get("rounds", Refinement.rounds)
    factor = section.get("factor", Refinement.factor)
    if not isinstance(rounds, int) or isinstance(rounds, bool) or rounds < 0:
        raise problem
    if not isinstance(factor, int | float) or isinstance(factor, bool) or not factor > 1:
        raise problem
    return Refinement(rounds, float(factor))


def refinement_points(
    point: Mapping[str, Gain], grid: Grid, factor: float
) -> list[dict[str, Gain]]:
    """The neighbours of ``point`` one round of the refinement tries: each numeric gain
    multiplied, then divided, by ``factor`` (a zero gain has none), and each named gain
    set to every other value its grid lists.

    >>> grid = {"k_p": [1.0], "k_d": [0.0], "saturation": ["box", "clip"]}
    >>> for p in refinement_points({"k_p": 2.0, "k_d": 0.0, "saturation": "box"}, grid, 2.0):
    ...     print(p)
    {'k_p': 4.0, 'k_d': 0.0, 'saturation': 'box'}
    {'k_p': 1.0, 'k_d': 0.0, 'saturation': 'box'}
    {'k_p': 2.0, 'k_d': 0.0, 'saturation': 'clip'}
    """
    out: list[dict[str, Gain]] = []
    for gain, value in point.items():
        if isinstance(value, str):
            out.extend({**point, gain: other} for other in grid[gain] if other != value)
        elif value != 0:
            out.append({**point, gain: round(float(value) * factor, 6)})
            out.append({**point, gain: round(float(value) / factor, 6)})
    return out


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


def _scores(
    name: str,
    cfg: SwarmConfig,
    points: Sequence[Mapping[str, Gain]],
    seed: int,
    episodes: int,
    progress: bool = False,
) -> list[dict[str, Any]]:
    """Every point's scores, each evaluated on the same ``episodes`` episodes of ``seed``;
    with ``progress``, a line on stdout after every :data:`PROGRESS_POINTS` points but
    the last (how many, the time taken and about how long the rest takes)."""
    from train.evaluate import evaluate_policies

    scores: list[dict[str, Any]] = []
    start = time.monotonic()
    for first in range(0, len(points), PROGRESS_POINTS):
        chunk = points[first : first + PROGRESS_POINTS]
        policies = {f"p{i}": make_tuned(name, cfg, p) for i, p in enumerate(chunk)}
        results = evaluate_policies(
            policies, cfg, episodes, seed, progress=False, gif=False, plots=False
        )
        scores.extend(results["policies"][f"p{i}"] for i in range(len(chunk)))
        if progress and len(scores) < len(points):
            spent = time.monotonic() - start
            left = spent * (len(points) - len(scores)) / len(scores)
            print(
                f"  {len(scores)}/{len(points)} points scored on {episodes} "
                f"episode{'' if episodes == 1 else 's'} in "
                f"{spent:.0f} s; about {left:.0f} s to go",
                flush=True,
            )
    return scores


def _ranked(scores: Sequence[Mapping[str, Any]]) -> list[int]:
    """The points' indices, the highest mean return first (ties: the earlier)."""
    return sorted(range(len(scores)), key=lambda i: (-scores[i]["mean_return"], i))


def _best(scores: Sequence[Mapping[str, Any]]) -> tuple[int, Mapping[str, Any]]:
    """The index of the point with the highest mean return (ties: the earlier) and its
    scores."""
    best = _ranked(scores)[0]
    return best, scores[best]


def _accepted(name: str, cfg: SwarmConfig, point: Mapping[str, Gain]) -> bool:
    """Whether the baseline takes the gains of ``point`` (a step may leave a gain's
    range, such as the mill's ``approach`` beyond 1)."""
    try:
        make_tuned(name, cfg, point)
    except ValueError:
        return False
    return True


def tune_scenario(
    name: str,
    cfg: SwarmConfig,
    grid: Grid,
    seed: int,
    episodes: int,
    refinement: Refinement = Refinement(),
    selection: Selection | None = None,
    progress: bool = False,
) -> dict[str, Any]:
    """Evaluate every point of ``grid`` on ``cfg``, score its best ones again
    (``selection``), refine the winner (``refinement``; module docstring); return the
    result's record ``{"gains", "mean_return", "success_rate", "seed", "episodes",
    "points"}`` (``episodes``: those the result was scored on; ``points``: every
    evaluation of a point), with ``"grid_gains"``, ``"grid_return"`` and
    ``"refine_rounds"`` (the rounds that moved it) where the refinement ran, and
    ``"grid_episodes"`` and ``"selected_from"`` (the points scored again) where the
    selection did. With ``progress``, a long evaluation prints a line on stdout every
    :data:`PROGRESS_POINTS` points."""
    points = grid_points(grid)
    record: dict[str, Any] = {}
    if selection is None:
        best, score = _best(_scores(name, cfg, points, seed, episodes, progress))
        gains, evaluated = points[best], len(points)
    else:
        ranked = _ranked(_scores(name, cfg, points, seed, episodes, progress))
        finalists = [points[i] for i in ranked[: selection.top]]
        best, score = _best(_scores(name, cfg, finalists, seed, selection.episodes, progress))
        gains, evaluated = finalists[best], len(points) + len(finalists)
        record = {"grid_episodes": episodes, "selected_from": len(finalists)}
        episodes = selection.episodes
    if refinement.rounds > 0:
        grid_best, grid_return, moved = gains, float(score["mean_return"]), 0
        for _ in range(refinement.rounds):
            neighbours = [
                p
                for p in refinement_points(gains, grid, refinement.factor)
                if _accepted(name, cfg, p)
            ]
            if not neighbours:
                break
            evaluated += len(neighbours)
            i, candidate = _best(_scores(name, cfg, neighbours, seed, episodes, progress))
            if not candidate["mean_return"] > score["mean_return"]:
                break
            gains, score, moved = neighbours[i], candidate, moved + 1
        record |= {
            "grid_gains": dict(grid_best),  # a copy: no YAML alias when they are equal
            "grid_return": round(grid_return, 4),
            "refine_rounds": moved,
        }
    return {
        "gains": gains,
        "mean_return": round(float(score["mean_return"]), 4),
        "success_rate": round(float(score["success_rate"]), 4),
        "seed": seed,
        "episodes": episodes,
        "points": evaluated,
        **record,
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
        seed, episodes, grids, refinement, selections = load_grids(args.grids)
        entries = load_matrix(args.matrix).select(args.only)
        if out.exists() and not out.is_file():
            raise CliError(f"--out {out} is not a file")
    except (CliError, ValueError, OSError) as err:
        return fail(PROG, err)
    tuned: dict[str, dict[str, Any]] = {}
    if out.is_file():
        tuned = dict((yaml.safe_load(out.read_text(encoding="utf-8")) or {}).get("baselines", {}))
    done: set[tuple[str, str]] = set()
    for entry in entries:
        tc = entry.train_config(seed=seed)
        cfg = load_swarm_config(tc.env_config, tc.env)
        for name in SIMPLE[cfg.task]:
            key = scenario_key(cfg)
            if name not in grids or (name, key) in done:
                continue
            done.add((name, key))
            print(
                f"{PROG}: {name} on {key}: {len(grid_points(grids[name]))} points ...", flush=True
            )
            record = tune_scenario(
                name,
                cfg,
                grids[name],
                seed,
                episodes,
                refinement,
                selections.get(name),
                progress=True,
            )
            tuned.setdefault(name, {})[key] = record
            refined = (
                f" (the grid's best {record['grid_return']:.2f}, refined in "
                f"{record['refine_rounds']} round(s))"
                if "grid_return" in record
                else ""
            )
            if "selected_from" in record:
                refined += (
                    f"; chosen among the grid's {record['selected_from']} best on "
                    f"{record['grid_episodes']} episodes, on {record['episodes']}"
                )
            print(
                f"  best {record['gains']}: return {record['mean_return']:.2f}{refined}, "
                f"success {record['success_rate']:.0%}",
                flush=True,
            )
            _write(out, tuned, args.grids)
    return 0


def _write(out: Path, tuned: Mapping[str, Any], grids: str) -> None:
    header = (
        "# Written by swarm-tune (train/tune_baselines.py) from the grids of\n"
        f"# {Path(grids).name}: per baseline and scenario (<task>/<dynamics>, and\n"
        "# /informed=<f> for one informed fraction), the gains with\n"
        "# the highest mean return on the training seed (refined around the grid's\n"
        "# best where the grid file says so); the controllers read them\n"
        "# (agents/tuned.py). Rerun `swarm-tune` rather than editing by hand.\n"
    )
    body = yaml.safe_dump({"baselines": dict(tuned)}, sort_keys=True)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(".tmp")
    tmp.write_text(header + body, encoding="utf-8")
    tmp.replace(out)


if __name__ == "__main__":
    sys.exit(main())
