"""``swarm-demo`` (``make demo``): train, evaluate against the best baseline, report.

1. trains ``configs/train/demo_zone.yaml`` into ``OUT``: a shared policy that corrects
   the strongest simple controller of navigation on Couzin's zone model (his
   informed-individual rule, ``informed``; a residual policy), trained by evolution
   strategies;
2. evaluates the trained policy beside every baseline of the task
   (:func:`agents.baseline_names`: ``informed`` and the saturated PD law ``pd``, with
   the gains ``swarm-tune`` found on training seeds),
   ``zero`` (the passive swarm) and ``random``, on ``--episodes`` episodes whose seed
   (``--seed``) training never used, writing ``results.json``, ``summary.md``,
   ``curves.png`` and one GIF per policy into ``OUT``;
3. writes ``OUT/report.md`` with the lower bound on the time to goal
   (:mod:`train.evaluate.bound`) and the verdict: does the learned policy beat the best
   baseline (the one with the highest mean return) on the task's own measures (higher
   mean return, success rate at least as high, shorter mean time to goal, no more
   collisions)?

``OUT`` must be new or empty; ``--overwrite`` removes an earlier run's files there
first. Ctrl-C or SIGTERM during training saves a checkpoint and ``model.zip`` (see
``swarm-train``); ``swarm-train --resume OUT`` continues that training.

Exit status 0 when it does, 1 when it does not (the report says which measure failed),
2 with one line on stderr on a bad flag, config or output folder, 130/143 when stopped
by SIGINT/SIGTERM.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from swarm_envs import tune_allocator
from swarm_envs.config import CONFIG_ROOT
from train.cli_common import CliError, OneLineParser, check_seed, fail, one_line
from train.config import load_train_config, parse_overrides

PROG = "swarm-demo"

DEFAULT_CONFIG = CONFIG_ROOT / "train" / "demo_zone.yaml"
LEARNED = "learned"


def compare(learned: dict[str, Any], baseline: dict[str, Any]) -> list[tuple[str, bool, str]]:
    """The four criteria: ``(name, passed, detail)`` each."""
    lt, bt = learned["mean_time_to_goal"], baseline["mean_time_to_goal"]
    time_ok = lt is not None and (bt is None or lt < bt)
    return [
        (
            "higher mean return",
            learned["mean_return"] > baseline["mean_return"],
            f"{learned['mean_return']:.2f} vs {baseline['mean_return']:.2f}",
        ),
        (
            "success rate at least as high",
            learned["success_rate"] >= baseline["success_rate"],
            f"{learned['success_rate']:.0%} vs {baseline['success_rate']:.0%}",
        ),
        (
            "shorter mean time to goal",
            time_ok,
            f"{_seconds(lt)} vs {_seconds(bt)}",
        ),
        (
            "no more collisions",
            learned["collisions_per_episode"] <= baseline["collisions_per_episode"],
            f"{learned['collisions_per_episode']:.2f} vs "
            f"{baseline['collisions_per_episode']:.2f} per episode",
        ),
    ]


def paired_line(results: dict[str, Any], best: str) -> str:
    """The learned policy's mean paired difference of return with ``best``, with its
    95 % bootstrap interval over the episodes (each learned episode against the
    baseline's run from the same start)."""
    import numpy as np

    from train.benchmark.stats import paired_difference

    learned = results["policies"][LEARNED]["per_episode"]["return"]
    baseline = results["policies"][best]["per_episode"]["return"]
    diff = paired_difference(np.array([learned], float), np.array(baseline, float))
    low, high = diff["ci"]
    return (
        f"Learned − `{best}`, return: {diff['value']:+.2f} [{low:+.2f}, {high:+.2f}] "
        "(mean paired difference over the episodes, 95 % bootstrap interval)."
    )


def _seconds(value: float | None) -> str:
    return "never" if value is None else f"{value:.1f} s"


def write_report(results: dict[str, Any], out: Path, train_seconds: float | None) -> bool:
    """Write ``report.md``; return whether the learned policy beats the best baseline."""
    from train.evaluate import format_table
    from train.evaluate.report import bound_line

    best = results["best_baseline"]
    criteria = compare(results["policies"][LEARNED], results["policies"][best])
    beaten = all(ok for _, ok, _ in criteria)
    lines = [
        f"# {results['env']} demo: learned shared policy vs the best baseline",
        "",
        f"Evaluation: {results['episodes']} episodes, seed {results['seed']} "
        "(never used in training), deterministic actions. Baselines: "
        + ", ".join(f"`{n}`" for n in results["baselines"])
        + f"; the best (highest mean return) is `{best}`.",
    ]
    if train_seconds is not None:
        lines.append(f"Training time: {train_seconds:.0f} s.")
    lines += ["", format_table(results), "", bound_line(results), "", "## Verdict", ""]
    lines += [f"- {'✅' if ok else '❌'} {name}: {detail}" for name, ok, detail in criteria]
    lines += ["", paired_line(results, best)]
    lines += [
        "",
        f"**The learned policy beats the best baseline, `{best}`.**"
        if beaten
        else f"**The learned policy does NOT beat the best baseline, `{best}`, on every measure.**",
        "",
        f"![learned](episode0_{LEARNED}.gif) ![{best}](episode0_{best}.gif)",
        "",
    ]
    (out / "report.md").write_text("\n".join(lines), encoding="utf-8")
    return beaten


def main(argv: list[str] | None = None) -> int:
    """Run ``swarm-demo``; returns the exit status (see the module docstring)."""
    parser = OneLineParser(prog=PROG, description=__doc__.splitlines()[0])
    parser.add_argument("--config", default=str(DEFAULT_CONFIG), help="train config YAML")
    parser.add_argument("--out", default="runs/demo", help="output folder (default runs/demo)")
    parser.add_argument(
        "--overwrite", action="store_true", help="OUT may hold an earlier run: remove it first"
    )
    parser.add_argument(
        "--episodes", type=int, default=100, help="evaluation episodes (default %(default)s)"
    )
    parser.add_argument(
        "--seed", type=int, default=2026, help="evaluation seed (default %(default)s)"
    )
    parser.add_argument(
        "--no-progress", action="store_true", help="no progress bar or progress lines"
    )
    parser.add_argument("overrides", nargs="*", help="key=value overrides of the train config")
    args = parser.parse_args(argv)
    try:
        return _main(args)
    except KeyboardInterrupt:  # outside training, which saves and stops on its own
        print(f"{PROG}: interrupted by SIGINT", file=sys.stderr)
        return 130


def _main(args: argparse.Namespace) -> int:
    from train.outdir import OutDirError, check_out_dir

    tune_allocator()  # a long-running tool: keep freed heap for reuse
    out = Path(args.out)
    try:
        tc = load_train_config(args.config, parse_overrides(args.overrides))
        if args.episodes < 1:
            raise CliError(f"--episodes must be >= 1, got {args.episodes}")
        check_seed("--seed", args.seed)
        if args.seed in (tc.seed, tc.eval_seed):
            raise CliError(
                f"--seed must differ from the training seeds ({tc.seed}, {tc.eval_seed})"
            )
        check_out_dir(out, overwrite=args.overwrite)
    except (CliError, ValueError, OSError) as err:
        return fail(PROG, err)

    import json

    from agents import baseline_names, make_controller
    from train.evaluate import evaluate_policies, load_sb3_model
    from train.interrupt import TrainingAborted, TrainingInterrupted, exit_status
    from train.train import TrainSetupError, train

    try:
        model_path = train(
            tc, out, progress_bar=not args.no_progress, overwrite=args.overwrite, prog=PROG
        )
    except (TrainSetupError, OutDirError) as err:
        return fail(PROG, err)
    except (TrainingInterrupted, TrainingAborted) as err:
        print(f"{PROG}: {one_line(str(err))}", file=sys.stderr)
        return exit_status(err.signum)
    cfg = tc.swarm_config()
    baselines = baseline_names(cfg)
    policies = {name: make_controller(name, cfg) for name in baselines}
    policies["zero"] = make_controller("zero", cfg)
    policies["random"] = make_controller("random", cfg, seed=args.seed)
    policies[LEARNED] = load_sb3_model(model_path)
    print(f"evaluating on {args.episodes} episodes (seed {args.seed}) ...")
    results = evaluate_policies(
        policies,
        cfg,
        args.episodes,
        args.seed,
        out_dir=out,
        env_id=tc.env_id,
        progress=not args.no_progress,
        extra={"model": str(model_path), "train_config": tc.to_dict(), "baselines": baselines},
        baselines=baselines,
    )
    meta = json.loads((out / "meta.json").read_text())
    beaten = write_report(results, out, meta.get("train_seconds"))
    print((out / "report.md").read_text(encoding="utf-8"))
    return 0 if beaten else 1


if __name__ == "__main__":
    sys.exit(main())
