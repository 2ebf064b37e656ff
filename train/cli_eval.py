"""``swarm-eval``: evaluate analytic controllers, SB3 models and RLlib checkpoints on SwarmNav.

Usage::

    swarm-eval --env swarm_envs/SwarmNav-v0 [--config configs/env/paper_navigation.yaml] \\
        --policies potential zero random [path/to/model.zip ...] [runs/x_rllib/checkpoint] \\
        --episodes 20 --seed 0 --out runs/eval
    swarm-eval --policies runs/ppo/model.zip analytic zero \\
        --n-agents 10 31 100 300 1000 --episodes 20 --out runs/eval_sizes
    swarm-eval --policies runs/ppo/model.zip analytic zero \\
        --failed-fraction 0 0.1 0.3 0.5 --failure-mode frozen --obs-noise 0 0.5 1 \\
        --episodes 20 --out runs/eval_robustness

Policies are built-in names (``potential``, ``informed``, ``goal_force``,
``lyapunov``, ``mill``, ``pd``, ``follow``, ``zero``, ``random``, see
:data:`agents.CONTROLLERS`; ``analytic``, the paper's controller of the config's
dynamics, reported under its own name; and ``baselines``, every baseline of the config's
task, :func:`agents.baseline_names`, the default with ``zero`` and ``random``), paths to
Stable-Baselines3 model zips (algorithm detected from the zip), or RLlib checkpoint
folders written by ``swarm-train --engine rllib`` (the shared module, through
:class:`train.rllib.policy.RLlibPolicy`; needs the ``distributed`` extra). Every
policy runs on the same seeded episodes; the output folder receives ``results.json``,
``summary.md``, ``curves.png`` and one ``episode0_<policy>.gif`` per policy (see
:mod:`train.evaluate` and ``docs/evaluation.md``). The episodes run on the backend and
device of the config (``--set backend=native``, ``--set device=cuda`` with the torch
backend), recorded in ``results.json`` as ``backend``. A model trained by ``swarm-train``
records its env: evaluating it where the dynamics, the observation layout or scales, or
``u_max`` differ prints a one-line warning (``swarm-eval: warning: ...``).

Size transfer: ``--n-agents 10 31 100 300 1000`` evaluates every policy unchanged at
each swarm size (the config otherwise as given) and writes ``results.json``,
``summary.md`` (one table row per policy and N), ``transfer.csv`` and ``transfer.png``
(success rate, return, time to goal and collisions against N) instead of the curves and
GIFs (:mod:`train.evaluate.transfer`). Only shared per-agent policies transfer: a
model trained on the Gymnasium env (whole-swarm observation) is refused. ``--set
n_agents=...`` does not combine with ``--n-agents``.

Robustness: ``--failed-fraction``, ``--obs-noise``, ``--action-noise`` and
``--neighbor-dropout`` each list values of that perturbation (``SwarmConfig.perturbations``,
``swarm_envs.perturbations``); ``--failure-mode passive|removed|frozen`` and
``--failure-time T`` (or ``LOW HIGH``, drawn per agent) say how and when agents fail.
Each option listing several values is swept, one row per value with the other options
at 0 (an option given one value keeps it in every row; where no option lists several,
each given option is swept); every policy runs each row on the same seeded episodes, in
the config with only its ``perturbations`` replaced (the observation layout is kept:
``observe_status`` is not switched on). Writes ``results.json``, ``summary.md`` (one
table row per option, policy and value), ``robustness.csv`` and ``robustness.png``
(:mod:`train.evaluate.robustness`). It does not combine with ``--n-agents``.

Unstable steps (step-size control): unless the config file or a ``--set`` names
``on_unstable``, the episodes run with ``on_unstable="truncate"``, so an episode whose
step goes unstable ends there and is counted in the ``unstable`` column (with
``on_unstable=raise`` such a step stops the evaluation with exit status 2). The tables
also report the mean integration substeps per step. ``results.json`` never holds NaN or
infinity: an undefined measure (the time to goal without a success) is ``null``, ``—``
in the tables.

``--out`` must be new or empty; ``--overwrite`` removes an earlier evaluation's files
there first (``results.json``, ``summary.md``, ``curves.png``, the GIFs, a demo's
``report.md``, ``transfer.csv``, ``transfer.png``, ``robustness.csv``,
``robustness.png``) and keeps anything else, such as a
run's ``model.zip``.

Exit status: 0 on success; 2 with one line on stderr for a bad flag (``--seed`` outside
[0, 2**32 - 1], ``--episodes`` < 1, an unavailable ``--device``, ...), an unknown
policy name, a missing or unreadable model file, a model whose spaces do not fit the
env (with what it was trained on), a central policy with ``--n-agents``, a perturbation
value out of its range (the message names the option and the range), ``--n-agents``
with a perturbation sweep, an env ``device`` that is unavailable or needs another
backend, an unknown env id, a bad config (YAML syntax included, or one not valid at a
size of ``--n-agents`` or a value of a sweep), an unstable step with
``on_unstable=raise``, or an ``--out`` that is a file or holds files (without
``--overwrite``); 130 on Ctrl-C.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from swarm_envs import ENV_ID, tune_allocator
from train.cli_common import CliError, OneLineParser, check_device, check_seed, fail, one_line
from train.cli_eval_robustness import (
    add_robustness_arguments,
    failure_options,
    robustness_configs,
    robustness_sweeps,
)
from train.config import DEFAULT_TORCH_THREADS

if TYPE_CHECKING:
    from swarm_envs.config import SwarmConfig

PROG = "swarm-eval"


def build_parser() -> argparse.ArgumentParser:
    """The command-line parser of ``swarm-eval``."""
    p = OneLineParser(
        prog=PROG,
        description="Evaluate policies (analytic controllers, SB3 models) on the same seeded "
        "SwarmNav episodes; write results.json, summary.md, curves.png and GIFs (with "
        "--n-agents: at several swarm sizes, transfer.csv and transfer.png; with a "
        "perturbation sweep: robustness.csv and robustness.png).",
    )
    p.add_argument("--env", default=ENV_ID, help=f"Gymnasium env id (default {ENV_ID})")
    p.add_argument(
        "--plugin",
        action="append",
        default=[],
        metavar="PATH",
        help="a .py file or module to import first: a user's own task or model "
        "(swarm_envs.plugins); repeatable",
    )
    p.add_argument(
        "--config",
        default=None,
        help="env YAML, e.g. configs/env/paper_navigation.yaml (default: the env's defaults)",
    )
    p.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a config key (YAML value; dotted for sections, e.g. physics.C_o=0.7); "
        "repeatable",
    )
    p.add_argument("--max-steps", type=int, default=None, help="override max_steps")
    p.add_argument(
        "--n-agents",
        type=int,
        nargs="+",
        default=None,
        metavar="N",
        help="size transfer: evaluate every policy unchanged at each of these swarm sizes "
        "(shared per-agent policies only); writes transfer.csv and transfer.png",
    )
    add_robustness_arguments(p)
    p.add_argument(
        "--policies",
        nargs="+",
        default=["baselines", "zero", "random"],
        metavar="POLICY",
        help="built-in names (baselines = every baseline of the config's task: the paper's "
        "controller and the tuned simple ones; analytic = the paper's controller of the "
        "config's dynamics; potential, informed, goal_force, lyapunov, mill, pd, follow, "
        "zero, random), SB3 model .zip paths and/or RLlib checkpoint folders; LABEL=POLICY "
        "names a policy in the tables, plots and GIFs (default: the controller's name, or "
        "the run folder's name for a model). Default: baselines zero random",
    )
    p.add_argument("--episodes", type=int, default=20, help="episodes per policy (default 20)")
    p.add_argument("--seed", type=int, default=0, help="seed of the episodes (default 0)")
    p.add_argument("--out", default="runs/eval", help="output folder (default runs/eval)")
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="--out may hold an earlier evaluation: remove its files first",
    )
    p.add_argument("--device", default="cpu", help="torch device for SB3 models (default cpu)")
    p.add_argument(
        "--torch-threads",
        type=int,
        default=DEFAULT_TORCH_THREADS,
        metavar="N",
        help=f"torch CPU threads for the models (default {DEFAULT_TORCH_THREADS}; 0: torch's own)",
    )
    p.add_argument(
        "--stochastic", action="store_true", help="sample SB3 actions (default deterministic)"
    )
    p.add_argument("--gif-size", type=int, default=300, help="GIF size in pixels (default 300)")
    p.add_argument("--no-gif", action="store_true", help="do not write GIFs")
    p.add_argument("--no-plots", action="store_true", help="do not write curves.png")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def _parse_overrides(items: Sequence[str], max_steps: int | None) -> dict[str, Any]:
    import yaml

    from train.cli_common import yaml_message

    out: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        if not sep or not key or any(not part for part in key.split(".")):
            raise CliError(f"--set expects KEY=VALUE, got {item!r}")
        try:
            value = yaml.safe_load(raw)
        except yaml.YAMLError as err:
            raise CliError(f"--set {item!r}: {yaml_message(err)}") from None
        *sections, leaf = key.split(".")
        node = out
        for s in sections:
            node = node.setdefault(s, {})
            if not isinstance(node, dict):
                raise CliError(f"--set {key}: {s} is not a section")
        node[leaf] = value
    if max_steps is not None:
        out["max_steps"] = max_steps
    return out


def _make_config(env_id: str, config: str | None, overrides: dict[str, Any]) -> SwarmConfig:
    import gymnasium
    import yaml

    import swarm_envs  # noqa: F401  (registers the env ids)
    from agents.base import swarm_config_of
    from train.cli_common import yaml_message

    kwargs = dict(overrides)
    if config is not None:
        kwargs["config"] = config
    try:
        env = gymnasium.make(env_id, **kwargs)
    except gymnasium.error.Error as err:
        raise CliError(f"cannot make env {env_id!r}: {err}") from None
    except (ValueError, TypeError) as err:
        raise CliError(f"bad config for {env_id}: {err}") from None
    except yaml.YAMLError as err:
        raise CliError(f"bad config for {env_id}: {yaml_message(err)}") from None
    except OSError as err:
        raise CliError(f"cannot read the config of {env_id}: {err}") from None
    try:
        return swarm_config_of(env)
    except ValueError:
        raise CliError(f"{env_id} is not a swarm_envs SwarmNav environment") from None
    finally:
        env.close()


def check_backend(cfg: SwarmConfig, batch: int) -> str:
    """The backend that will run ``batch`` episodes of ``cfg`` (its ``backend`` and
    ``device``), or :class:`CliError` when its ``device`` is unavailable here or needs
    another backend."""
    from swarm_envs.envs.backends import resolve_backend
    from train.config import device_problem

    if cfg.device != "cpu" and (problem := device_problem(cfg.device)) is not None:
        raise CliError(f"device {problem}")
    try:
        return resolve_backend(cfg, batch)
    except ValueError as err:
        raise CliError(str(err)) from None


def _unique(name: str, taken: set[str]) -> str:
    out, i = name, 2
    while out in taken:
        out, i = f"{name}_{i}", i + 1
    return out


def _user_sets(key: str, config: str | None, overrides: dict[str, Any]) -> bool:
    """Whether the config file or a ``--set`` names the top-level ``key``."""
    if key in overrides:
        return True
    if config is None:
        return False
    from swarm_envs.config import load_yaml, resolve_config_path

    return key in load_yaml(resolve_config_path(config))


def _size_configs(cfg: SwarmConfig, sizes: Sequence[int], episodes: int) -> list[SwarmConfig]:
    """``cfg`` at each ``--n-agents`` size, each checked as :func:`check_backend` does."""
    from train.evaluate.transfer import size_configs

    try:
        configs = size_configs(cfg, sizes)
    except ValueError as err:
        raise CliError(f"--n-agents: {err}") from None
    for c in configs:
        check_backend(c, episodes)
    return configs


def _load_policies(
    specs: Sequence[str], cfg: SwarmConfig, seed: int, device: str, *, transfer: bool = False
) -> dict[str, Any]:
    """The policies of ``--policies``, each checked to fit ``cfg``; with ``transfer``,
    to be shared per-agent policies (a central one is refused)."""
    from agents import CONTROLLERS, analytic_name, baseline_names, make_controller
    from train.evaluate import CentralPolicyError, SpaceMismatchError, load_sb3_model, policy_mode
    from train.evaluate.policies import (
        config_for_policy,
        describe_trained_env,
        policy_label,
        split_label,
    )
    from train.evaluate.transfer import check_transferable

    policies: dict[str, Any] = {}

    def add(label: str | None, default: str, policy: Any) -> str:
        if label is not None and label in policies:
            raise CliError(f"--policies: the label {label!r} is given twice")
        name = label if label is not None else _unique(default, set(policies))
        policies[name] = policy
        return name

    for entry in specs:
        try:
            label, spec = split_label(entry)
        except ValueError as err:
            raise CliError(str(err)) from None
        if spec == "baselines":
            if label is not None:
                raise CliError("--policies: 'baselines' names several policies; it takes no label")
            for name in baseline_names(cfg):
                if name not in policies:
                    add(None, name, make_controller(name, cfg, seed=seed))
            continue
        if spec == "analytic":
            spec = analytic_name(cfg)
        if spec in CONTROLLERS:
            add(label, spec, make_controller(spec, cfg, seed=seed))
            continue
        path = Path(spec)
        looks_like_path = path.suffix == ".zip" or "/" in spec or "\\" in spec
        if path.is_dir():
            rllib_policy = _load_rllib(path, seed)
            try:
                policy_mode(rllib_policy, config_for_policy(rllib_policy, cfg))
            except SpaceMismatchError as err:
                raise CliError(f"checkpoint {spec} does not fit the env: {err}") from None
            rllib_policy.name = add(label, policy_label(path), rllib_policy)
            continue
        if not path.is_file():
            if looks_like_path:
                raise CliError(f"model file not found: {spec}")
            raise CliError(
                f"unknown policy {spec!r}; use one of baselines, analytic, "
                f"{', '.join(CONTROLLERS)} or a "
                "path to a Stable-Baselines3 model .zip (LABEL=POLICY names it)"
            )
        try:
            model = load_sb3_model(path, device=device)
        except (ValueError, OSError) as err:
            raise CliError(str(err)) from None
        name = label if label is not None else policy_label(path)
        if transfer:
            try:
                check_transferable(name, model, cfg)
            except CentralPolicyError as err:
                raise CliError(f"--n-agents: model {spec}: {err}") from None
            except SpaceMismatchError:
                pass  # reported below, as without --n-agents
        try:
            policy_mode(model, config_for_policy(model, cfg))
        except SpaceMismatchError as err:
            trained = describe_trained_env(model)
            extra = f"; it was {trained}" if trained else ""
            raise CliError(f"model {spec} does not fit the env: {err}{extra}") from None
        add(label, policy_label(path), model)
    return policies


def _load_rllib(path: Path, seed: int) -> Any:
    """The shared policy of the RLlib checkpoint at ``path`` (a folder)."""
    from train.rllib.policy import is_rllib_checkpoint, load_rllib_policy

    if not is_rllib_checkpoint(path):
        raise CliError(
            f"{path} is a folder but not an RLlib checkpoint (swarm-train --engine rllib "
            "writes one as <out>/checkpoint)"
        )
    try:
        return load_rllib_policy(path, seed=seed)
    except (ImportError, ValueError, OSError) as err:
        raise CliError(f"cannot load RLlib checkpoint {path}: {err}") from None


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``swarm-eval``; returns the exit status (0 ok, 2 user error, 130 Ctrl-C)."""
    args = build_parser().parse_args(argv)
    try:
        return _main(args)
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted by SIGINT", file=sys.stderr)
        return 130


def _main(args: argparse.Namespace) -> int:
    from swarm_envs.plugins import load_plugins
    from train.evaluate.robustness import ROBUSTNESS_FILES
    from train.evaluate.transfer import TRANSFER_FILES
    from train.outdir import EVAL_FILES, OutDirError, check_out_dir, prepare_out_dir

    tune_allocator()  # a long-running tool: keep freed heap for reuse
    out = Path(args.out)
    try:
        if args.episodes < 1:
            raise CliError(f"--episodes must be >= 1, got {args.episodes}")
        if not 32 <= args.gif_size <= 4096:
            raise CliError(f"--gif-size must be in [32, 4096] pixels, got {args.gif_size}")
        check_seed("--seed", args.seed)
        check_device("--device", args.device)
        if args.torch_threads < 0:
            raise CliError(f"--torch-threads must be >= 0, got {args.torch_threads}")
        try:
            load_plugins(args.plugin)
        except ValueError as err:
            raise CliError(str(err)) from None
        overrides = _parse_overrides(args.overrides, args.max_steps)
        sweeps = robustness_sweeps(args)
        if args.n_agents is not None and "n_agents" in overrides:
            raise CliError("--n-agents and --set n_agents=... both set the swarm size; use one")
        if args.n_agents and all(isinstance(n, int) and n >= 1 for n in args.n_agents):
            # the base config at the smallest size: the sizes are checked one by one below
            overrides = {**overrides, "n_agents": min(args.n_agents, default=1)}
        cfg = _make_config(args.env, args.config, overrides)
        if not _user_sets("on_unstable", args.config, overrides):
            # count unstable episodes instead of stopping at the first
            cfg = dataclasses.replace(cfg, on_unstable="truncate")
        if args.n_agents is not None:
            _size_configs(cfg, args.n_agents, args.episodes)
        elif sweeps:
            for row_cfg in robustness_configs(cfg, args, sweeps):
                check_backend(row_cfg, args.episodes)
        else:
            check_backend(cfg, args.episodes)
        transfer = args.n_agents is not None
        policies = _load_policies(args.policies, cfg, args.seed, args.device, transfer=transfer)
        check_out_dir(out, overwrite=args.overwrite)  # after every argument is checked
        patterns = tuple(dict.fromkeys(EVAL_FILES + TRANSFER_FILES + ROBUSTNESS_FILES))
        prepare_out_dir(out, overwrite=args.overwrite, patterns=patterns, prog=PROG)
    except (CliError, OutDirError) as err:
        return fail(PROG, err)

    from swarm_envs.envs.common import SwarmUnstableError
    from train.evaluate import TrainedEnvWarning

    if args.torch_threads > 0:
        import torch

        torch.set_num_threads(args.torch_threads)

    with warnings.catch_warnings():
        warnings.simplefilter("always", TrainedEnvWarning)
        warnings.showwarning = _one_line_warning
        try:
            table, written = _evaluate(args, policies, cfg, out, sweeps)
        except SwarmUnstableError as err:
            return fail(PROG, f"{err} (on_unstable=raise is set in the config or a --set)")
    print(table)
    print(f"\nwrote {written}")
    return 0


def _one_line_warning(message: Any, category: type, *_args: Any, **_kw: Any) -> None:
    print(f"{PROG}: warning: {one_line(str(message))}", file=sys.stderr)


def _evaluate(
    args: argparse.Namespace,
    policies: dict[str, Any],
    cfg: SwarmConfig,
    out: Path,
    sweeps: dict[str, list[float]],
) -> tuple[str, str]:
    """Run the evaluation ``args`` ask for; return its table and what it wrote."""
    from train.evaluate import (
        evaluate_policies,
        evaluate_robustness,
        evaluate_transfer,
        format_robustness_table,
        format_table,
        format_transfer_table,
    )

    extra = {"config_path": args.config, "overrides": _parse_overrides(args.overrides, None)}
    common = {
        "out_dir": out,
        "env_id": args.env,
        "deterministic": not args.stochastic,
        "progress": not args.no_progress,
        "plots": not args.no_plots,
        "extra": extra,
    }
    written = f"{out / 'results.json'}, {out / 'summary.md'}"
    if args.n_agents is not None:
        results = evaluate_transfer(
            policies, cfg, args.n_agents, args.episodes, args.seed, **common
        )
        written += f", {out / 'transfer.csv'}"
        if not args.no_plots:
            written += f", {out / 'transfer.png'}"
        return format_transfer_table(results), written
    if sweeps:
        results = evaluate_robustness(
            policies,
            cfg,
            sweeps,
            args.episodes,
            args.seed,
            **failure_options(args),
            **common,
        )
        written += f", {out / 'robustness.csv'}"
        if not args.no_plots:
            written += f", {out / 'robustness.png'}"
        return format_robustness_table(results), written
    results = evaluate_policies(
        policies,
        cfg,
        args.episodes,
        args.seed,
        gif=not args.no_gif,
        gif_size=args.gif_size,
        **common,
    )
    if not args.no_plots:
        written += f", {out / 'curves.png'}"
    if not args.no_gif:
        written += f" and {len(policies)} GIF(s) in {out}"
    return format_table(results), written


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
