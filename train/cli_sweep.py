"""``swarm-sweep``: a grid of physics parameters × seeds, on Ray Tune or locally.

Usage::

    swarm-sweep --config configs/sweeps/quick.yaml [--engine ray|local] [--out DIR]
    swarm-sweep --config configs/sweeps/fig9_fig10_large.yaml --address HEAD_IP:6379
    swarm-sweep --config configs/sweeps/quick.yaml seeds=8 relax.n_agents=100

``--engine ray`` (the default) runs one Ray Tune trial per grid point × seed, on a
local Ray (``--num-cpus``) or on the cluster at ``--address``; ``--engine local`` runs
the same trials in this process without Ray, with the same numbers. Overrides use
dotted keys and YAML values, as in ``swarm-train``. The output folder (default
``runs/sweeps/<config name>``) receives ``trials.csv``, ``summary.csv``,
``results.json``, ``sweep.png`` and ``sweep_config.yaml`` (see :mod:`train.sweep`).
``--out`` must be new or empty; ``--overwrite`` removes an earlier sweep's files there
first. Exit status 2 with one line on stderr on a bad flag, config or output folder, or
when Ray is needed but absent; 130 on Ctrl-C.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from swarm_envs import tune_allocator
from train.cli_common import OneLineParser, fail
from train.config import parse_overrides
from train.outdir import SWEEP_FILES, check_out_dir, prepare_out_dir
from train.sweep import ENGINES, load_sweep_config, run_sweep, write_outputs

PROG = "swarm-sweep"


def build_parser() -> argparse.ArgumentParser:
    """The command-line parser of ``swarm-sweep``."""
    p = OneLineParser(prog=PROG, description=__doc__.splitlines()[0])
    p.add_argument("--config", required=True, help="configs/sweeps/<name>.yaml")
    p.add_argument(
        "--engine",
        choices=ENGINES,
        default="ray",
        help="ray: Ray Tune trials (local Ray or --address); local: this process, no Ray "
        "(default ray)",
    )
    p.add_argument(
        "--address",
        default=None,
        help="ray: join the Ray cluster at HOST:PORT (or 'auto'); default: start a local Ray",
    )
    p.add_argument("--num-cpus", type=int, default=None, help="ray: CPUs of the local Ray")
    p.add_argument(
        "--storage",
        default=None,
        help="ray: folder or URI for Tune's trial logs (default <out>/ray_tune; on a "
        "multi-machine cluster use a shared folder or a cloud URI)",
    )
    p.add_argument("--out", default=None, help="output folder (default runs/sweeps/<name>)")
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="--out may hold an earlier sweep: remove its files first",
    )
    p.add_argument("--no-plot", action="store_true", help="do not write sweep.png")
    p.add_argument("--no-progress", action="store_true", help="no progress output")
    p.add_argument("overrides", nargs="*", help="key=value overrides (dotted keys)")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``swarm-sweep``; returns the exit status (0 ok, 2 user error, 130 Ctrl-C)."""
    args = build_parser().parse_args(argv)
    try:
        return _main(args)
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted by SIGINT", file=sys.stderr)
        return 130


def _main(args: argparse.Namespace) -> int:
    tune_allocator()  # a long-running tool: keep freed heap for reuse
    name = Path(args.config).stem
    out = Path(args.out) if args.out else Path("runs") / "sweeps" / name
    try:
        sc = load_sweep_config(args.config, parse_overrides(args.overrides))
        if args.engine == "local" and (args.address or args.num_cpus or args.storage):
            raise ValueError("--address, --num-cpus and --storage apply only to --engine ray")
        if args.engine == "ray":
            from train.rllib.cluster import check_address, check_num_cpus, require_ray

            check_address(args.address)
            check_num_cpus(args.num_cpus)
            require_ray()
        check_out_dir(out, overwrite=args.overwrite)
        prepare_out_dir(out, overwrite=args.overwrite, patterns=SWEEP_FILES, prog=PROG)
    except (ValueError, ImportError, OSError) as err:
        hint = " (or run without Ray: --engine local)" if isinstance(err, ImportError) else ""
        return fail(PROG, f"{err}{hint}" if hint else err)
    n_trials = len(sc.points()) * len(sc.seeds)
    print(
        f"{sc.task} sweep over {', '.join(sc.grid)}: {len(sc.points())} grid point(s) × "
        f"{len(sc.seeds)} seed(s) = {n_trials} trials on engine {args.engine}"
    )
    storage = args.storage if args.storage else out.resolve() / "ray_tune"
    result = run_sweep(
        sc,
        engine=args.engine,
        name=f"sweep_{name}",
        address=args.address,
        num_cpus=args.num_cpus,
        storage_path=storage if args.engine == "ray" else None,
        progress=not args.no_progress,
    )
    write_outputs(result, out, plot=not args.no_plot)
    print(
        f"{n_trials} trials in {result.seconds:.1f} s; wrote {out / 'trials.csv'}, "
        f"{out / 'summary.csv'}, {out / 'results.json'}"
        + ("" if args.no_plot else f", {out / 'sweep.png'}")
    )
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
