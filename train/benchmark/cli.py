"""``swarm-benchmark``: train and evaluate every entry of a benchmark matrix; write the
results table with bootstrap confidence intervals.

Usage::

    swarm-benchmark                   # configs/benchmark/results.yaml -> runs/benchmark
    swarm-benchmark --only navigation/zone --seeds 0 1 2 3 4
    swarm-benchmark --quick           # a smoke run -> runs/benchmark_quick

For every entry and training seed (``--seeds``) the learned policy is trained into
``OUT/models/<entry>/seed<k>/``; then every model and every baseline is evaluated on
the same ``--episodes`` episodes (``--eval-seed``). ``OUT/results.json``,
``OUT/results.md`` and ``OUT/results.png`` are written after each entry.

Stopping and continuing: Ctrl-C (or SIGTERM) stops a training at its next update
boundary and saves it; the finished models stay. Running the same command again reuses
every finished model, resumes the stopped one and trains the rest. A model folder that
holds a run of another config, or a residual policy on a baseline whose tuned gains have
changed since, is refused; ``--overwrite`` retrains the selected entries from scratch.

``--baselines-only`` trains nothing and evaluates the baselines alone (the best one
marked, the lower bound on the time to goal): the table of what a learned policy must
beat, in minutes.

``--quick`` is a smoke run for tests and CI: about one update of training per seed, two
seeds, ten episodes (unless ``--seeds`` / ``--episodes`` say otherwise), into
``runs/benchmark_quick`` by default. Its numbers mean nothing about the policies.

Exit status: 0 done; 2 with one line on stderr for a bad flag, matrix or model folder;
130/143 stopped by SIGINT/SIGTERM.
"""

from __future__ import annotations

import argparse
import platform
import sys
from pathlib import Path
from typing import Any

from swarm_envs import tune_allocator
from train.benchmark.matrix import DEFAULT_MATRIX, Matrix, load_matrix
from train.benchmark.report import MEASURE_DOCS, write_results
from train.benchmark.run import (
    DEFAULT_EPISODES,
    DEFAULT_EVAL_SEED,
    Settings,
    entry_train_config,
    existing_run,
    model_folder,
    run_entry,
)
from train.benchmark.stats import BOOTSTRAP_SEED, CONFIDENCE, N_RESAMPLES
from train.cli_common import CliError, OneLineParser, check_seed, fail, one_line

PROG = "swarm-benchmark"
DEFAULT_OUT = "runs/benchmark"
QUICK_OUT = "runs/benchmark_quick"
DEFAULT_SEEDS = (0, 1, 2)
QUICK_SEEDS = (0, 1)
QUICK_EPISODES = 10


def build_parser() -> argparse.ArgumentParser:
    """The command-line parser of ``swarm-benchmark``."""
    summary = __doc__.split("\n\n")[0].replace("\n", " ")  # the first sentence, whole
    parser = OneLineParser(prog=PROG, description=summary)
    parser.add_argument("--matrix", default=DEFAULT_MATRIX, help="the benchmark matrix (YAML)")
    parser.add_argument(
        "--out", default=None, help=f"output folder (default {DEFAULT_OUT}; --quick: {QUICK_OUT})"
    )
    parser.add_argument(
        "--seeds",
        type=int,
        nargs="+",
        default=None,
        help="training seeds (default 0 1 2; --quick: 0 1)",
    )
    parser.add_argument(
        "--episodes",
        type=int,
        default=None,
        help=f"evaluation episodes per policy (default {DEFAULT_EPISODES}; --quick: "
        f"{QUICK_EPISODES})",
    )
    parser.add_argument(
        "--eval-seed",
        type=int,
        default=DEFAULT_EVAL_SEED,
        help=f"seed of the evaluation episodes (default {DEFAULT_EVAL_SEED}; not a training seed)",
    )
    parser.add_argument(
        "--only", nargs="+", default=None, metavar="NAME", help="run these entries only"
    )
    parser.add_argument(
        "--quick", action="store_true", help="smoke run: tiny training, 2 seeds, 10 episodes"
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="retrain the selected entries' models instead of reusing or resuming them",
    )
    parser.add_argument(
        "--resamples",
        type=int,
        default=N_RESAMPLES,
        help=f"bootstrap resamples (default {N_RESAMPLES:,})",
    )
    parser.add_argument(
        "--bootstrap-seed",
        type=int,
        default=BOOTSTRAP_SEED,
        help=f"seed of the bootstrap (default {BOOTSTRAP_SEED})",
    )
    parser.add_argument(
        "--jobs",
        type=int,
        default=1,
        help="processes at once (default 1: everything in this process, one after "
        "another): each training run, and each entry's evaluation once its runs are "
        "trained, in a process of its own",
    )
    parser.add_argument("--no-progress", action="store_true", help="no training progress bars")
    parser.add_argument(
        "--baselines-only",
        action="store_true",
        help="train nothing: evaluate every baseline (the best marked, the time bound) only",
    )
    return parser


def settings_from_args(args: argparse.Namespace) -> Settings:
    """The :class:`Settings` of the parsed flags (``CliError`` on a bad value)."""
    seeds = tuple(args.seeds) if args.seeds is not None else None
    seeds = seeds or (QUICK_SEEDS if args.quick else DEFAULT_SEEDS)
    for seed in seeds:
        check_seed("--seeds", seed)
    if len(set(seeds)) != len(seeds):
        raise CliError(f"--seeds gives a seed twice: {' '.join(map(str, seeds))}")
    episodes = args.episodes
    if episodes is None:
        episodes = QUICK_EPISODES if args.quick else DEFAULT_EPISODES
    if episodes < 1:
        raise CliError(f"--episodes must be an integer >= 1, got {episodes}")
    check_seed("--eval-seed", args.eval_seed)
    if args.eval_seed in seeds:
        raise CliError(
            f"--eval-seed ({args.eval_seed}) must differ from the training seeds "
            f"({' '.join(map(str, seeds))})"
        )
    if args.resamples < 1:
        raise CliError(f"--resamples must be an integer >= 1, got {args.resamples}")
    check_seed("--bootstrap-seed", args.bootstrap_seed)
    if args.jobs < 1:
        raise CliError(f"--jobs must be an integer >= 1, got {args.jobs}")
    return Settings(
        seeds=seeds,
        episodes=episodes,
        eval_seed=args.eval_seed,
        quick=args.quick,
        overwrite=args.overwrite,
        progress=not args.no_progress,
        n_resamples=args.resamples,
        bootstrap_seed=args.bootstrap_seed,
        confidence=CONFIDENCE,
        baselines_only=args.baselines_only,
        jobs=args.jobs,
    )


def _versions() -> dict[str, str]:
    import numpy
    import stable_baselines3
    import torch

    import swarm_envs

    return {
        "swarm_envs": swarm_envs.__version__,
        "stable_baselines3": stable_baselines3.__version__,
        "torch": torch.__version__,
        "numpy": numpy.__version__,
        "python": platform.python_version(),
        "platform": platform.platform(),
    }


def _header(matrix: Matrix, names: list[str], s: Settings, argv: list[str]) -> dict[str, Any]:
    return {
        "matrix": matrix.path,
        "entries": names,
        **s.to_dict(),
        "bootstrap": "percentile; learned policies: resample seeds, then episodes within "
        "each resampled seed; baselines: resample episodes",
        "command": [PROG, *argv],
        "versions": _versions(),
    }


def main(argv: list[str] | None = None) -> int:
    """Run ``swarm-benchmark``; returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(argv)
    try:
        return _main(args, argv)
    except KeyboardInterrupt:  # outside a training (which saves and stops on its own)
        print(f"{PROG}: interrupted by SIGINT; {_again()}", file=sys.stderr)
        return 130


def _count(n: int, one: str, many: str) -> str:
    return f"{n} {one if n == 1 else many}"


def _again() -> str:
    return "finished work is kept: run the same command again to continue"


def _main(args: argparse.Namespace, argv: list[str]) -> int:
    from train.interrupt import TrainingAborted, TrainingInterrupted, exit_status, signal_name
    from train.outdir import OutDirError, check_out_dir
    from train.train import TrainSetupError

    tune_allocator()  # a long-running tool: keep freed heap for reuse
    try:
        s = settings_from_args(args)
        out = Path(args.out or (QUICK_OUT if args.quick else DEFAULT_OUT))
        check_out_dir(out, overwrite=True)  # only refuses a file where the folder goes
        matrix = load_matrix(args.matrix)
        entries = matrix.select(args.only)
        for entry in entries:  # every config and model folder checked before any training
            for seed in () if s.baselines_only else s.seeds:
                tc = entry_train_config(entry, seed, s.quick)
                existing_run(tc, model_folder(out, entry, seed), overwrite=s.overwrite)
    except (CliError, ValueError, OSError) as err:
        return fail(PROG, err)
    results: dict[str, Any] = {
        "benchmark": _header(matrix, [e.name for e in entries], s, argv),
        "measures": MEASURE_DOCS,
        "entries": [],
    }
    trained = "baselines only" if s.baselines_only else _count(len(s.seeds), "seed", "seeds")
    print(
        f"{PROG}: {_count(len(entries), 'entry', 'entries')} × {trained}, "
        f"{s.episodes} evaluation episodes each"
        f"{' (quick smoke run)' if s.quick else ''}; out = {out}"
    )
    try:
        if s.jobs > 1 and not s.baselines_only:
            from train.benchmark.parallel import run_in_parallel

            def written(done: list[dict[str, Any]]) -> None:
                results["entries"] = done
                write_results(results, out)

            results["entries"] = run_in_parallel(entries, out, s, written=written)
            paths = write_results(results, out)
        else:
            for entry in entries:
                results["entries"].append(run_entry(entry, out, s))
                paths = write_results(results, out)
    except (TrainSetupError, OutDirError) as err:
        return fail(PROG, err)
    except RuntimeError as err:  # a training or evaluation process failed (--jobs)
        return fail(PROG, err)
    except TrainingInterrupted as err:
        print(
            f"{PROG}: stopped by {signal_name(err.signum)} at {err.timesteps:,} timesteps, "
            f"saved in {err.out}; {_again()}",
            file=sys.stderr,
        )
        return exit_status(err.signum)
    except TrainingAborted as err:
        print(f"{PROG}: {one_line(str(err))}; {_again()}", file=sys.stderr)
        return exit_status(err.signum)
    print(f"wrote {', '.join(str(p) for p in paths.values())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
