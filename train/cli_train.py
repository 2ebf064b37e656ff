"""``swarm-train``: train a policy on SwarmNav from a YAML config, with SB3 or Ray RLlib.

Usage::

    swarm-train --config configs/train/demo.yaml [--out runs/demo] [key=value ...]
    swarm-train --engine rllib --config configs/train/demo_rllib.yaml [--address HOST:6379]

Overrides use dotted keys and YAML values: ``total_timesteps=20000 env.n_agents=6
hyperparams.learning_rate=1e-3``. ``--engine`` picks the trainer: ``sb3``
(:mod:`train.train`, :class:`~train.config.TrainConfig`) or ``rllib``
(:mod:`train.rllib.train`, :class:`~train.rllib.config.RLlibTrainConfig`; needs the
``distributed`` extra). Without ``--engine``, a config whose name ends in ``_rllib`` is
trained with RLlib and any other with SB3. ``--address`` joins a running Ray cluster
(RLlib only); without it RLlib starts a local Ray (``--num-cpus`` CPUs). Exit status 2
with a message on a bad config or a missing Ray.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from swarm_envs import tune_allocator
from train.config import load_train_config, parse_overrides

ENGINES = ("sb3", "rllib")


def _engine(requested: str | None, config: str) -> str:
    if requested is not None:
        return requested
    return "rllib" if Path(config).stem.endswith("_rllib") else "sb3"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="swarm-train", description=__doc__.splitlines()[0])
    parser.add_argument("--config", required=True, help="configs/train/<name>.yaml")
    parser.add_argument("--out", default=None, help="output folder (default runs/<config name>)")
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
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("overrides", nargs="*", help="key=value overrides (dotted keys)")
    args = parser.parse_args(argv)
    tune_allocator()  # a long-running tool: keep freed heap for reuse
    engine = _engine(args.engine, args.config)
    out = Path(args.out) if args.out else Path("runs") / Path(args.config).stem
    try:
        if engine == "sb3":
            if args.address is not None or args.num_cpus is not None:
                raise ValueError("--address and --num-cpus apply only to --engine rllib")
            tc = load_train_config(args.config, parse_overrides(args.overrides))
        else:
            from train.rllib.cluster import check_address, check_num_cpus, require_ray
            from train.rllib.config import load_rllib_config

            rc = load_rllib_config(args.config, parse_overrides(args.overrides))
            check_address(args.address)
            check_num_cpus(args.num_cpus)
            require_ray()
    except (ValueError, ImportError) as err:
        print(f"swarm-train: error: {err}", file=sys.stderr)
        return 2
    if engine == "sb3":
        from train.train import train

        train(tc, out, progress_bar=not args.no_progress)
        return 0
    from train.rllib.train import train_rllib

    train_rllib(rc, out, address=args.address, num_cpus=args.num_cpus)
    return 0


if __name__ == "__main__":
    sys.exit(main())
