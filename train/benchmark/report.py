"""What a benchmark writes: ``results.json``, ``results.md`` and ``results.png``.

``results.json`` holds everything: the run's settings (matrix, seeds, episodes,
evaluation seed, bootstrap), the package versions, and per entry its training config,
its models and, per evaluation and policy, every measure with its interval, the
per-seed values and the per-episode returns, successes and lengths. It never holds NaN
or infinity (an undefined value is ``null``; written with ``allow_nan=False``).

``results.md`` is one table, a row per entry, evaluation and policy; ``results.png``
shows the same values as points with their interval as whiskers, one panel per measure.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from train.evaluate.bound import NEAR_OPTIMAL
from train.evaluate.report import MISSING, write_json

__all__ = ["BENCHMARK_FILES", "MEASURE_DOCS", "format_results_table", "write_results"]

#: The files a benchmark writes into its output folder (beside ``models/``).
BENCHMARK_FILES = ("results.json", "results.md", "results.png")

#: One line per measure of the table (also in ``results.json`` as ``"measures"``).
MEASURE_DOCS = {
    "return": "mean episode return (the summed cooperative reward)",
    "success": "fraction of episodes that ended in success (terminated)",
    "time_to_goal": "mean simulated seconds (steps × dt) to success over the successful "
    "episodes, pooled over seeds; null when none succeeded",
    "iqm_return": "interquartile mean of the episode returns pooled over seeds (the "
    "mean of the middle 50 %)",
}

#: Table columns: (measure, header, format of one number).
COLUMNS = (
    ("return", "return", "{:.2f}"),
    ("success", "success", "{:.0%}"),
    ("time_to_goal", "time to goal (s)", "{:.1f}"),
    ("iqm_return", "IQM return", "{:.2f}"),
)


def _fmt(value: Any, spec: str) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return MISSING
    return spec.format(value)


def format_measure(measure: Mapping[str, Any], spec: str) -> str:
    """``value [low, high]``; :data:`~train.evaluate.report.MISSING` where undefined."""
    cell = _fmt(measure.get("value"), spec)
    ci = measure.get("ci")
    if cell != MISSING and ci is not None:
        cell += f" [{_fmt(ci[0], spec)}, {_fmt(ci[1], spec)}]"
    return cell


def _rows(results: Mapping[str, Any]) -> list[tuple[dict, dict, str, dict]]:
    return [
        (entry, ev, name, policy)
        for entry in results["entries"]
        for ev in entry["evaluations"]
        for name, policy in ev["policies"].items()
    ]


def _policy_label(name: str, policy: Mapping[str, Any], best: str | None = None) -> str:
    controller = policy.get("controller")
    label = f"{name} ({controller})" if controller and controller != name else name
    return f"{label} **best baseline**" if name == best else label


def _minus_best(policy: Mapping[str, Any]) -> str:
    diff = policy.get("minus_best")
    return format_measure(diff["return"], "{:+.2f}") if diff else ""


def _over_bound(policy: Mapping[str, Any]) -> str:
    return _fmt(policy.get("time_over_bound"), "{:+.0%}")


def format_results_table(results: Mapping[str, Any]) -> str:
    """The markdown table: entry, evaluation, policy, each measure ``value [95 % CI]``,
    and ``n`` (seeds × episodes)."""
    pct = f"{results['benchmark']['confidence']:.0%}"
    header = (
        "| entry | evaluation | policy | "
        + " | ".join(f"{h} [{pct} CI]" for _, h, _ in COLUMNS)
        + f" | time over bound | learned − best baseline, return [{pct} CI, paired]"
        + " | n (seeds × episodes) |"
    )
    rule = "|---|---|---|" + "---:|" * len(COLUMNS) + "---:|---:|---:|"
    rows = [
        f"| {entry['name']} | {ev['label']} | {_policy_label(name, p, ev.get('best_baseline'))} | "
        + " | ".join(format_measure(p[key], spec) for key, _, spec in COLUMNS)
        + f" | {_over_bound(p)} | {_minus_best(p)} | {p['n_seeds']} × {p['n_episodes']} |"
        for entry, ev, name, p in _rows(results)
    ]
    return "\n".join([header, rule, *rows])


def _markdown(results: Mapping[str, Any]) -> str:
    b = results["benchmark"]
    quick = " **Quick smoke run: tiny training, not a result.**" if b["quick"] else ""
    if b.get("baselines_only"):
        quick += " Baselines only: no policy was trained."
    lines = [
        "# Benchmark results",
        "",
        f"Matrix `{b['matrix']}`; learned policies trained with seeds "
        f"{', '.join(map(str, b['seeds']))}; every policy evaluated on the same "
        f"{b['episodes']} episodes (seed {b['eval_seed']}); the deterministic baselines "
        f"once.{quick}",
        "",
        format_results_table(results),
        "",
        f"Intervals: {b['confidence']:.0%} percentile bootstrap, {b['n_resamples']:,} "
        f"resamples (seed {b['bootstrap_seed']}); learned policies resample seeds, then "
        "episodes within each seed; baselines resample episodes. "
        f"{MISSING} marks an undefined value (no successful episode).",
        "",
        *[f"- `{k}`: {doc}" for k, doc in MEASURE_DOCS.items()],
        "- time over bound: the time to goal over its lower bound (no policy can do "
        "better; train/evaluate/bound.py), minus 1, over the successful episodes; "
        f"{MISSING} where no bound is defined (piecewise, Lagrangian, the mill).",
        "- learned − best baseline: the mean paired difference of the returns, on the "
        "same episodes, with the best baseline (the highest mean return) of its "
        "evaluation; above zero with its whole interval, learning wins.",
    ]
    near = [
        f"- {entry['name']} / {ev['label']}: the best baseline, "
        f"{ev['best_baseline']}, is within {NEAR_OPTIMAL:.0%} of the lower bound on the "
        f"time to goal ({over:+.2%}): no policy can arrive more than {NEAR_OPTIMAL:.0%} "
        "sooner, so learning has little to win here."
        for entry in results["entries"]
        for ev in entry["evaluations"]
        if ev.get("best_baseline")
        and (over := ev["policies"][ev["best_baseline"]].get("time_over_bound")) is not None
        and over <= NEAR_OPTIMAL
    ]
    if near:
        lines += ["", "Near-optimal baselines:", "", *near]
    notes = [
        f"- {entry['name']} / {ev['label']}: evaluated off its training env: {'; '.join(n)}"
        for entry, ev, name, p in _rows(results)
        if (n := p.get("notes"))
    ]
    if notes:
        lines += ["", "Notes:", "", *notes]
    return "\n".join(lines) + "\n"


def plot_results(results: Mapping[str, Any], path: Path) -> Path:
    """``results.png``: one panel per measure, a point per policy with its interval as
    whiskers, grouped by entry (and evaluation)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    groups = [
        (entry["name"] if len(entry["evaluations"]) == 1 else f"{entry['name']}\n{ev['label']}", ev)
        for entry in results["entries"]
        for ev in entry["evaluations"]
    ]
    names = list(dict.fromkeys(n for _, ev in groups for n in ev["policies"]))
    width = max(7.0, 1.1 * len(groups) + 2.0)
    fig = Figure(figsize=(width, 9.0), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(COLUMNS), 1, sharex=True)
    offsets = {
        n: (i - (len(names) - 1) / 2) * 0.6 / max(len(names), 1) for i, n in enumerate(names)
    }
    for ax, (key, header, _) in zip(axes, COLUMNS, strict=True):
        for i, name in enumerate(names):
            xs, ys, lows, highs = [], [], [], []
            for g, (_, ev) in enumerate(groups):
                m = ev["policies"].get(name, {}).get(key)
                if not m or m.get("value") is None:
                    continue
                ci = m.get("ci") or [m["value"], m["value"]]
                xs.append(g + offsets[name])
                ys.append(m["value"])
                lows.append(m["value"] - ci[0])
                highs.append(ci[1] - m["value"])
            ax.errorbar(
                xs,
                ys,
                yerr=[lows, highs],
                fmt="os"[i % 2],
                color=f"C{i}",
                capsize=3,
                label=name,
                lw=1.2,
            )
        ax.set_ylabel(header)
        ax.set_xlim(-0.6, len(groups) - 0.4)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    axes[-1].set_xticks(range(len(groups)), [g for g, _ in groups], rotation=20, fontsize=8)
    b = results["benchmark"]
    smoke = "SMOKE RUN (--quick): tiny training, not a result\n" if b["quick"] else ""
    learned = (
        "baselines only (nothing trained)"
        if b.get("baselines_only")
        else f"learned: {len(b['seeds'])} seeds × {b['episodes']} episodes"
    )
    fig.suptitle(
        f"{smoke}{b['confidence']:.0%} bootstrap intervals; {learned}, "
        f"baselines: {b['episodes']} episodes",
        fontsize=10,
        color="C3" if smoke else "black",
    )
    fig.savefig(path)
    return path


def write_results(results: Mapping[str, Any], out_dir: str | Path) -> dict[str, Path]:
    """Write ``results.json``, ``results.md`` and ``results.png`` into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"json": write_json(results, out / "results.json")}
    paths["md"] = out / "results.md"
    paths["md"].write_text(_markdown(results), encoding="utf-8")
    paths["png"] = plot_results(results, out / "results.png")
    return paths
