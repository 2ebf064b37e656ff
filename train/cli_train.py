"""``swarm-train``: train an SB3 policy on SwarmNav from a YAML config.

Usage::

    swarm-train --config configs/train/demo.yaml [--out runs/demo] [key=value ...]

Overrides use dotted keys and YAML values: ``total_timesteps=20000 env.n_agents=6
hyperparams.learning_rate=1e-3``. Exit status 2 with a message on a bad config.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from train.config import load_train_config, parse_overrides


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="swarm-train", description=__doc__.splitlines()[0])
    parser.add_argument("--config", required=True, help="configs/train/<name>.yaml")
    parser.add_argument("--out", default=None, help="output folder (default runs/<config name>)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("overrides", nargs="*", help="key=value overrides (dotted keys)")
    args = parser.parse_args(argv)
    try:
        tc = load_train_config(args.config, parse_overrides(args.overrides))
    except ValueError as err:
        print(f"swarm-train: error: {err}", file=sys.stderr)
        return 2
    from train.train import train

    out = Path(args.out) if args.out else Path("runs") / Path(args.config).stem
    train(tc, out, progress_bar=not args.no_progress)
    return 0


if __name__ == "__main__":
    sys.exit(main())
