"""What an evaluation writes: ``results.json``, ``summary.md``, ``curves.png``, GIFs.

``summary.md`` holds the markdown table of :func:`format_table`; the figures are drawn
by :mod:`train.evaluate.figures`. ``results.json`` never holds NaN or infinity
(:func:`write_json`): an undefined measure is ``null``, shown as ``—`` in the tables.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from swarm_envs.config import SwarmConfig
from train.evaluate.bound import NEAR_OPTIMAL
from train.evaluate.episodes import EpisodeBatch
from train.evaluate.figures import plot_curves, write_episode_gif
from train.evaluate.measures import METRIC_DOCS, json_safe

__all__ = [
    "MISSING",
    "SWEEP_COLUMNS",
    "SWEEP_CSV_KEYS",
    "TABLE_COLUMNS",
    "bound_line",
    "csv_cell",
    "format_cell",
    "format_table",
    "sweep_summary",
    "write_json",
    "write_outputs",
]

#: Columns of the summary table: (key, header, format).
TABLE_COLUMNS = (
    ("success_rate", "success", "{:.0%}"),
    ("mean_return", "return (mean ± std)", "{:.2f}"),
    ("mean_time_to_goal", "time to goal (s)", "{:.1f}"),
    ("time_over_bound", "over bound", "{:+.0%}"),
    ("collisions_per_episode", "collisions / ep.", "{:.1f}"),
    ("control_effort", "control effort", "{:.1f}"),
    ("final_centroid_distance", "final centroid dist.", "{:.2f}"),
    ("final_expanse", "final expanse", "{:.2f}"),
    ("final_polarization", "final polarization", "{:.2f}"),
    ("unstable_episodes", "unstable", "{:d}"),
    ("mean_substeps", "substeps / step", "{:.1f}"),
)

#: Columns of a sweep's table (size transfer, robustness) after the row's own cells:
#: (key, header, format). A sweep may add its own measures to these.
SWEEP_COLUMNS = (
    ("success_rate", "success", "{:.0%}"),
    ("mean_return", "return (mean ± std)", "{:.2f}"),
    ("mean_time_to_goal", "time to goal (s)", "{:.1f}"),
    ("collisions_per_episode", "collisions / ep.", "{:.1f}"),
    ("unstable_episodes", "unstable", "{:d}"),
    ("mean_substeps", "substeps / step", "{:.2f}"),
)

#: Measures of a sweep's CSV after the row's own cells (a sweep may add its own).
SWEEP_CSV_KEYS = (
    "success_rate",
    "success_ci95_low",
    "success_ci95_high",
    "mean_return",
    "std_return",
    "mean_time_to_goal",
    "std_time_to_goal",
    "collisions_per_episode",
    "std_collisions",
    "unstable_episodes",
    "mean_substeps",
    "mean_episode_length",
    "control_effort",
    "final_centroid_distance",
    "final_expanse",
)

#: The spread shown after a mean in the tables, as ``mean ± std``.
STD_OF = {
    "mean_return": "std_return",
    "mean_time_to_goal": "std_time_to_goal",
    "collisions_per_episode": "std_collisions",
}

#: What a table shows for an undefined measure (``null`` in ``results.json``).
MISSING = "—"


def _fmt(value: Any, spec: str) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return MISSING
    return spec.format(value)


def format_cell(measures: Mapping[str, Any], key: str, spec: str) -> str:
    """One table cell: the measure ``key`` formatted with ``spec``, followed by
    ``± std`` where :data:`STD_OF` names its spread; :data:`MISSING` if undefined."""
    cell = _fmt(measures.get(key), spec)
    std_key = STD_OF.get(key)
    if cell != MISSING and std_key is not None and measures.get(std_key) is not None:
        cell += " ± " + _fmt(measures[std_key], spec)
    return cell


def csv_cell(measures: Mapping[str, Any], key: str) -> Any:
    """One CSV cell: the measure ``key`` (``success_ci95_low`` / ``_high``: an end of
    the interval), or an empty cell where it is undefined."""
    if key.startswith("success_ci95_"):
        ci = measures.get("success_ci95")
        return "" if ci is None else ci[0 if key.endswith("low") else 1]
    value = measures.get(key)
    return "" if value is None else value


def bound_line(results: Mapping[str, Any]) -> str:
    """One sentence on the lower bound on the time to goal of ``results``' episodes
    (:mod:`train.evaluate.bound`), how close the best baseline comes to it, and which
    other baselines arrive within :data:`~train.evaluate.bound.NEAR_OPTIMAL` of it (the
    best baseline is the one with the highest return, not always the fastest)."""
    bound = results.get("time_to_goal_bound")
    if bound is None:
        why = results.get("bound_undefined") or "not computed"
        return f"Lower bound on the time to goal: none defined here ({why})."
    line = (
        f"Lower bound on the time to goal (no policy can do better): {bound:.2f} s, "
        "the mean over the episodes."
    )
    best = results.get("best_baseline")
    over = results["policies"].get(best, {}).get("time_over_bound") if best else None
    if over is not None:
        near = (
            f"within {NEAR_OPTIMAL:.0%} of it: near-optimal"
            if over <= NEAR_OPTIMAL
            else "room to gain"
        )
        line += f" The best baseline, {best}, takes {over:+.2%} more ({near})."
    for name in results.get("baselines", ()):
        other = results["policies"].get(name, {}).get("time_over_bound")
        if name != best and other is not None and other <= NEAR_OPTIMAL:
            line += (
                f" {name} takes {other:+.2%} more, within {NEAR_OPTIMAL:.0%} of it: "
                "near-optimal on time, though not the best by return."
            )
    alone = results.get("free_agent_time")
    if alone is not None:
        line += (
            f" Each agent alone at full thrust, pair forces ignored (an estimate, not a "
            f"bound): {alone:.2f} s."
        )
    return line


def format_table(results: Mapping[str, Any]) -> str:
    """The policies' main measures as a markdown table (one row per policy); the last
    column marks the best baseline (``results["best_baseline"]``)."""
    header = "| policy | " + " | ".join(h for _, h, _ in TABLE_COLUMNS) + " | best baseline |"
    rule = "|---|" + "---:|" * len(TABLE_COLUMNS) + ":---:|"
    rows = []
    best = results.get("best_baseline")
    for name, m in results["policies"].items():
        cells = [format_cell(m, key, spec) for key, _, spec in TABLE_COLUMNS]
        cells.append("✓" if name == best else "")
        rows.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join([header, rule, *rows])


def write_json(results: Mapping[str, Any], path: Path) -> Path:
    """Write ``results`` as JSON with every non-finite number as ``null``
    (:func:`~train.evaluate.measures.json_safe`); NaN and infinity never reach the file
    (``allow_nan=False``)."""
    text = json.dumps(json_safe(results), indent=2, ensure_ascii=False, allow_nan=False)
    path.write_text(text + "\n", encoding="utf-8")
    return path


def measure_legend(columns: Any) -> list[str]:
    """Markdown lines naming each measure of the table ``columns`` (``(key, header,
    spec)`` triples) and of its spreads, with its documentation."""
    shown = {k for k, _, _ in columns} | set(STD_OF.values())
    return [f"- `{k}`: {doc}" for k, doc in METRIC_DOCS.items() if k in shown]


def sweep_summary(
    results: Mapping[str, Any],
    *,
    title: str,
    setting: str,
    table: str,
    columns: Any,
    notes: Sequence[str] = (),
) -> str:
    """A sweep's ``summary.md``: the heading ``<title>: <env>``, the ``setting`` (a
    sentence without its full stop; the config's path is added where the results
    record one), each of ``notes`` as a paragraph, the ``table`` and the legend of its
    ``columns`` (:func:`measure_legend`)."""
    path = results.get("config_path")
    lines = [
        f"# {title}: {results['env']}",
        "",
        setting + (f", config `{path}`" if path else "") + ".",
        "",
    ]
    for note in notes:
        lines += [note, ""]
    lines += [
        table,
        "",
        "Measures (means over episodes; — where undefined):",
        "",
        *measure_legend(columns),
    ]
    return "\n".join(lines) + "\n"


def write_sweep_outputs(
    results: Mapping[str, Any],
    out_dir: str | Path,
    *,
    stem: str,
    write_csv: Any,
    summary: str,
    plot: Any | None,
) -> dict[str, Path]:
    """Write a sweep's ``results.json``, ``summary.md``, ``<stem>.csv`` (``write_csv``)
    and, unless ``plot`` is None, ``<stem>.png`` into ``out_dir``; return their paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {
        "results": write_json(results, out / "results.json"),
        "csv": write_csv(results, out / f"{stem}.csv"),
    }
    paths["summary"] = out / "summary.md"
    paths["summary"].write_text(summary, encoding="utf-8")
    if plot is not None:
        paths["plot"] = plot(results, out / f"{stem}.png")
    return paths


def _summary_markdown(results: Mapping[str, Any]) -> str:
    cfg = results["config"]
    lines = [
        f"# Evaluation: {results['env']}",
        "",
        f"{results['episodes']} episodes per policy, seed {results['seed']}, "
        f"N = {cfg['n_agents']}, dt = {cfg['dt']}, max_steps = {cfg['max_steps']}"
        + (f", config `{results['config_path']}`" if results.get("config_path") else "")
        + ".",
        "",
        format_table(results),
        "",
        bound_line(results),
        "",
        "Measures (means over episodes):",
        "",
        *measure_legend(TABLE_COLUMNS),
    ]
    return "\n".join(lines) + "\n"


def _safe_name(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._") or "policy"


def write_outputs(
    results: Mapping[str, Any],
    batches: Mapping[str, EpisodeBatch],
    cfg: SwarmConfig,
    out_dir: str | Path,
    *,
    gif: bool = True,
    plots: bool = True,
    gif_size: int = 300,
) -> dict[str, Path]:
    """Write ``results.json``, ``summary.md``, ``curves.png`` and the GIFs; return paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths: dict[str, Path] = {"results": out / "results.json", "summary": out / "summary.md"}
    write_json(results, paths["results"])
    paths["summary"].write_text(_summary_markdown(results), encoding="utf-8")
    if plots:
        paths["curves"] = plot_curves(batches, cfg, out / "curves.png")
    if gif:
        for name, b in batches.items():
            if b.trajectory:
                key = f"gif_{name}"
                paths[key] = write_episode_gif(
                    b, cfg, out / f"episode0_{_safe_name(name)}.gif", gif_size, title=name
                )
    return paths
