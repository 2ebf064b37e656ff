"""``swarm-train``: train a policy on SwarmNav from a YAML config, with SB3 or Ray RLlib.

Usage::

    swarm-train --config configs/train/demo.yaml [--out runs/demo] [--overwrite] [key=value ...]
    swarm-train --resume runs/demo [total_timesteps=16000000]
    swarm-train --engine rllib --config configs/train/demo_rllib.yaml [--address HOST:6379]

Overrides use dotted keys and YAML values: ``total_timesteps=20000 env.n_agents=6
hyperparams.learning_rate=1e-3``. ``--engine`` picks the trainer: ``sb3``
(:mod:`train.train`, :class:`~train.config.TrainConfig`) or ``rllib``
(:mod:`train.rllib.train`, :class:`~train.rllib.config.RLlibTrainConfig`; needs the
``distributed`` extra). Without ``--engine``, a config whose name ends in ``_rllib`` is
trained with RLlib and any other with SB3. ``--address`` joins a running Ray cluster
(RLlib only); without it RLlib starts a local Ray (``--num-cpus`` CPUs).

Output folder: ``--out`` (default ``runs/<config name>``) must be new or empty;
``--overwrite`` removes an earlier run's files there first (:mod:`train.outdir`).

Stopping and resuming (SB3): SIGINT (Ctrl-C) or SIGTERM stops the run at the next update
boundary and saves a checkpoint, ``model.zip`` and ``meta.json``; the exit status is
130 after SIGINT and 143 after SIGTERM (128 + the signal number). A second signal aborts
without saving. Checkpoints are also saved periodically (``checkpoint_seconds``,
``checkpoint_freq``). ``--resume DIR`` continues the run in DIR from its latest
checkpoint with DIR's saved config; overrides may only extend ``total_timesteps`` or
change the checkpoint cadence (:data:`train.config.RESUME_KEYS`).

Exit status: 0 done; 2 with one line on stderr for a bad flag, config, override or
output folder, or a missing Ray; 130/143 stopped by a signal (see above).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from swarm_envs import tune_allocator
from train.cli_common import CliError, OneLineParser, fail, one_line
from train.config import (
    TrainConfig,
    load_train_config,
    parse_overrides,
    resume_config,
)

PROG = "swarm-train"
ENGINES = ("sb3", "rllib")


def _engine(requested: str | None, config: str | None) -> str:
    if requested is not None:
        return requested
    return "rllib" if config is not None and Path(config).stem.endswith("_rllib") else "sb3"


def build_parser() -> argparse.ArgumentParser:
    """The command-line parser of ``swarm-train``."""
    parser = OneLineParser(prog=PROG, description=__doc__.splitlines()[0])
    parser.add_argument("--config", default=None, help="configs/train/<name>.yaml")
    parser.add_argument("--out", default=None, help="output folder (default runs/<config name>)")
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="--out may hold an earlier run: remove its files first",
    )
    parser.add_argument(
        "--resume",
        default=None,
        metavar="DIR",
        help="continue the SB3 run in DIR from its latest checkpoint, with DIR's config",
    )
    parser.add_argument(
        "--engine",
        choices=ENGINES,
        default=None,
        help="sb3 (one machine) or rllib (Ray; local or a cluster). Default: rllib for "
        "configs named *_rllib.yaml, else sb3",
    )
    parser.add_argument(
        "--address",
        default=None,
        help="rllib: join the Ray cluster at HOST:PORT (or 'auto'); default: start a local Ray",
    )
    parser.add_argument(
        "--num-cpus",
        type=int,
        default=None,
        help="rllib: CPUs of the local Ray (default: the config's num_cpus, else all)",
    )
    parser.add_argument(
        "--plugin",
        action="append",
        default=[],
        metavar="PATH",
        help="a .py file or module to import first: a user's own task or model "
        "(swarm_envs.plugins); repeatable, added to the config's plugins",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("overrides", nargs="*", help="key=value overrides (dotted keys)")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``swarm-train``; returns the exit status."""
    args = build_parser().parse_args(argv)
    try:
        return _main(args)
    except KeyboardInterrupt:  # outside the SB3 trainer's own handling (startup, RLlib)
        print(f"{PROG}: interrupted by SIGINT", file=sys.stderr)
        return 130


def _main(args: argparse.Namespace) -> int:
    tune_allocator()  # a long-running tool: keep freed heap for reuse
    engine = _engine(args.engine, args.config)
    try:
        if args.resume is not None:
            tc, out = _resume_args(args, engine)
        elif args.config is None:
            raise CliError("give --config FILE (a new run) or --resume DIR (continue a run)")
        else:
            out = Path(args.out) if args.out else Path("runs") / Path(args.config).stem
            if engine == "rllib":
                return _rllib(args, out)
            if args.address is not None or args.num_cpus is not None:
                raise CliError("--address and --num-cpus apply only to --engine rllib")
            overrides = parse_overrides(args.overrides)
            tc = load_train_config(args.config, overrides, tuple(args.plugin))
            from train.outdir import check_out_dir

            check_out_dir(out, overwrite=args.overwrite)
    except (CliError, ValueError, OSError) as err:
        return fail(PROG, err)
    return _sb3(tc, out, args)


def _resume_args(args: argparse.Namespace, engine: str) -> tuple[TrainConfig, Path]:
    """The config and folder of ``--resume DIR`` (DIR's config, allowed overrides)."""
    for flag, given in (
        ("--config", args.config),
        ("--out", args.out),
        ("--overwrite", args.overwrite or None),
        ("--address", args.address),
        ("--num-cpus", args.num_cpus),
    ):
        if given is not None:
            raise CliError(f"--resume DIR continues the run in DIR with its config; drop {flag}")
    if engine != "sb3":
        raise CliError("--resume continues SB3 runs; RLlib runs keep their own checkpoints")
    out = Path(args.resume)
    saved = out / "train_config.yaml"
    if not saved.is_file():
        raise CliError(f"--resume {out}: no train_config.yaml there (not a swarm-train run)")
    return resume_config(load_train_config(saved), parse_overrides(args.overrides)), out


def _sb3(tc: TrainConfig, out: Path, args: argparse.Namespace) -> int:
    from train.interrupt import (
        TrainingAborted,
        TrainingInterrupted,
        exit_status,
        stop_on_signals,
    )
    from train.outdir import OutDirError
    from train.train import TrainSetupError, train

    with stop_on_signals() as stop:
        try:
            train(
                tc,
                out,
                progress_bar=not args.no_progress,
                overwrite=args.overwrite,
                resume=args.resume is not None,
                stop=stop,
                prog=PROG,
            )
        except (TrainSetupError, OutDirError) as err:
            return fail(PROG, err)
        except TrainingInterrupted as err:
            print(f"{PROG}: {one_line(str(err))}", file=sys.stderr)
            return exit_status(err.signum)
        except TrainingAborted as err:
            print(f"{PROG}: {one_line(str(err))}", file=sys.stderr)
            return exit_status(err.signum)
    return 0


def _rllib(args: argparse.Namespace, out: Path) -> int:
    from train.outdir import RUN_FILES, check_out_dir, prepare_out_dir
    from train.rllib.cluster import check_address, check_num_cpus, require_ray
    from train.rllib.config import load_rllib_config

    try:
        from swarm_envs.plugins import load_plugins

        load_plugins(args.plugin)
        rc = load_rllib_config(args.config, parse_overrides(args.overrides))
        check_address(args.address)
        check_num_cpus(args.num_cpus)
        require_ray()
        check_out_dir(out, overwrite=args.overwrite)
        prepare_out_dir(out, overwrite=args.overwrite, patterns=RUN_FILES, prog=PROG)
    except (ValueError, ImportError, OSError) as err:
        return fail(PROG, err)
    from train.rllib.train import train_rllib

    train_rllib(rc, out, address=args.address, num_cpus=args.num_cpus)
    return 0


if __name__ == "__main__":
    sys.exit(main())
