"""The robustness-sweep flags of ``swarm-eval`` (:mod:`train.cli_eval`).

``--failed-fraction``, ``--obs-noise``, ``--action-noise`` and ``--neighbor-dropout``
each list values of that perturbation; ``--failure-mode`` and ``--failure-time`` say how
and when agents fail. The sweep itself is :mod:`train.evaluate.robustness`.
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Any

from train.cli_common import CliError

if TYPE_CHECKING:
    from swarm_envs.config import SwarmConfig

__all__ = [
    "add_robustness_arguments",
    "failure_options",
    "robustness_configs",
    "robustness_sweeps",
]


def add_robustness_arguments(p: argparse.ArgumentParser) -> None:
    """The flags of a robustness sweep, as an argument group of ``p``."""
    from swarm_envs.perturbations import FAILURE_MODES

    group = p.add_argument_group(
        "robustness sweep",
        "each option listing several values is swept (one row per value, the others at 0 "
        "or at their single value); writes robustness.csv and robustness.png",
    )
    sweeps = {
        "failed_fraction": "fractions of the agents that fail, in [0, 1)",
        "obs_noise": "std of Gaussian noise on the observations, >= 0",
        "action_noise": "std of Gaussian noise on the actions, >= 0",
        "neighbor_dropout": "probabilities of dropping a neighbour slot, in [0, 1)",
    }
    for key, what in sweeps.items():
        flag = "--" + key.replace("_", "-")
        group.add_argument(flag, type=float, nargs="+", default=None, metavar="X", help=what)
    group.add_argument(
        "--failure-mode",
        choices=FAILURE_MODES,
        default=None,
        help="what a failed agent does (default: the config's, passive)",
    )
    group.add_argument(
        "--failure-time",
        type=int,
        nargs="+",
        default=None,
        metavar="T",
        help="the step after which agents fail: T, or LOW HIGH drawn per agent "
        "(default: the config's, 0)",
    )


def robustness_sweeps(args: argparse.Namespace) -> dict[str, list[float]]:
    """The ``{option: values}`` of the robustness flags given, each checked."""
    from swarm_envs.perturbations import Perturbations
    from train.evaluate.robustness import SWEPT, sweep_values

    sweeps = {}
    for key in SWEPT:
        values = getattr(args, key)
        if values is not None:
            try:
                sweeps[key] = sweep_values(key, values)
            except ValueError as err:
                raise CliError(f"--{key.replace('_', '-')}: {err}") from None
    if (args.failure_mode or args.failure_time) and "failed_fraction" not in sweeps:
        raise CliError("--failure-mode and --failure-time need --failed-fraction")
    if args.failure_time is not None:
        if len(args.failure_time) > 2:
            n = len(args.failure_time)
            raise CliError(f"--failure-time takes T or LOW HIGH, got {n} values")
        try:
            Perturbations(failure_time=failure_options(args)["failure_time"])
        except ValueError as err:
            raise CliError(f"--failure-time: {err}") from None
    if sweeps and args.n_agents is not None:
        raise CliError("--n-agents and a perturbation sweep do not combine; run them apart")
    return sweeps


def robustness_configs(
    cfg: SwarmConfig, args: argparse.Namespace, sweeps: dict[str, list[float]]
) -> list[SwarmConfig]:
    """The configs of the sweep's rows, or :class:`CliError` naming what is wrong."""
    from train.evaluate import robustness

    try:
        rows = robustness.robustness_configs(cfg, sweeps, **failure_options(args))
    except ValueError as err:
        raise CliError(f"robustness sweep: {err}") from None
    return [row.cfg for row in rows]


def failure_options(args: argparse.Namespace) -> dict[str, Any]:
    """``failure_mode`` and ``failure_time`` of the flags (``None`` where not given)."""
    time = args.failure_time
    return {
        "failure_mode": args.failure_mode,
        "failure_time": None if time is None else (time[0] if len(time) == 1 else time),
    }
