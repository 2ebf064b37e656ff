"""Robustness: every policy on the same seeded episodes under growing perturbations.

:func:`evaluate_robustness` sweeps perturbations of the ``perturbations`` section of a
config (:class:`~swarm_envs.perturbations.Perturbations`): agents that fail
(``failed_fraction``, with the config's or a given ``failure_mode`` and
``failure_time``), observation noise (``obs_noise``), action noise (``action_noise``)
and dropped neighbour slots (``neighbor_dropout``). Each swept option gives one row per
value; in a row that option has its value and the other swept options are 0, unless one
is *fixed*: an option given with a single value while another lists several keeps that
value in every row (where no option lists several, each given option is a sweep of its
values). The rest of the section (absent and joining agents) stays as the config says.

Each row's config is the given config with only its ``perturbations`` replaced
(``dataclasses.replace``); each policy then runs with the observation layout it was
trained on (``observe_status`` as its observation space has it,
:func:`~train.evaluate.policies.config_for_policy`), so a model trained without status
flags is evaluated, blind to failures, beside one trained with them. Every policy runs
each row on the same seeded episodes (:func:`~train.evaluate.episodes.run_episodes`, the
same seed in every row): the same starts, and, the perturbations being drawn from the
episodes' generator, the same failing agents and noise for every policy. A failed,
frozen, removed or absent agent's action is ignored by the core, so what a policy asks
of it does not matter.

Measures per row and policy (:func:`~train.evaluate.measures.summarize`): success
rate, return, time to goal, collisions and the fraction of the swarm's members (the
agents that still move: passive failures included, removed and frozen ones not) that
arrived at the episode's end (``final_fraction_arrived``), among the others.

Outputs (:func:`write_robustness_outputs`): ``results.json`` (no NaN or infinity; an
undefined measure is ``null``), ``summary.md`` (the table of
:func:`format_robustness_table`), ``robustness.csv`` (one row per option, policy and
value; an undefined measure is an empty cell) and ``robustness.png`` (success rate,
return, time to goal, collisions and fraction arrived against each option's value,
one line per policy; :func:`~train.evaluate.figures.plot_robustness`).
"""

from __future__ import annotations

import csv
import dataclasses
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agents.base import swarm_config_of
from swarm_envs import ENV_ID
from swarm_envs.config import SwarmConfig, as_dict
from swarm_envs.perturbations import Perturbations
from train.evaluate.harness import check_policies, measure_row
from train.evaluate.measures import METRIC_DOCS
from train.evaluate.report import (
    SWEEP_COLUMNS,
    SWEEP_CSV_KEYS,
    csv_cell,
    format_cell,
    sweep_summary,
    write_sweep_outputs,
)

__all__ = [
    "ROBUSTNESS_COLUMNS",
    "ROBUSTNESS_CSV_KEYS",
    "ROBUSTNESS_FILES",
    "SWEPT",
    "SweepRow",
    "evaluate_robustness",
    "format_robustness_table",
    "robustness_configs",
    "sweep_values",
    "write_robustness_outputs",
]

#: The options a robustness evaluation sweeps (fields of ``Perturbations``).
SWEPT = ("failed_fraction", "obs_noise", "action_noise", "neighbor_dropout")

#: What a robustness evaluation writes (``--overwrite`` removes these).
ROBUSTNESS_FILES = ("results.json", "summary.md", "robustness.csv", "robustness.png")

_AFTER_COLLISIONS = 1 + [key for key, _, _ in SWEEP_COLUMNS].index("collisions_per_episode")
_AFTER_STD_COLLISIONS = 1 + SWEEP_CSV_KEYS.index("std_collisions")

#: Columns of the robustness table after policy, perturbation, value and backend: a
#: sweep's (:data:`~train.evaluate.report.SWEEP_COLUMNS`) with the fraction of the
#: swarm's members arrived after the collisions.
ROBUSTNESS_COLUMNS = (
    *SWEEP_COLUMNS[:_AFTER_COLLISIONS],
    ("final_fraction_arrived", "arrived", "{:.0%}"),
    *SWEEP_COLUMNS[_AFTER_COLLISIONS:],
)

#: Measures of ``robustness.csv`` after the row's policy, option, value, perturbations,
#: backend and episodes: a sweep's, with the fraction arrived after the collisions.
ROBUSTNESS_CSV_KEYS = (
    *SWEEP_CSV_KEYS[:_AFTER_STD_COLLISIONS],
    "final_fraction_arrived",
    *SWEEP_CSV_KEYS[_AFTER_STD_COLLISIONS:],
)


@dataclasses.dataclass(frozen=True)
class SweepRow:
    """One row of a sweep: ``option`` at ``value``, evaluated on ``cfg``."""

    option: str
    value: float
    cfg: SwarmConfig


def sweep_values(option: str, values: Sequence[float]) -> list[float]:
    """The values of one swept ``option`` (one of :data:`SWEPT`), checked and in
    increasing order.

    Raises:
        ValueError: an unknown option (naming the allowed ones), an empty list, a value
            that is not a number, a value listed twice, or one that ``Perturbations``
            refuses (its message names the option and the allowed range).
    """
    if option not in SWEPT:
        raise ValueError(f"cannot sweep {option!r}; sweepable options: {', '.join(SWEPT)}")
    if isinstance(values, (str, bytes)) or not isinstance(values, Sequence):
        raise ValueError(f"{option} must be a list of numbers, got {values!r}")
    out = []
    for value in values:
        if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
            raise ValueError(f"{option} values must be numbers, got {value!r}")
        one: dict[str, Any] = {option: float(value)}
        checked = Perturbations(**one)  # its range, its message
        out.append(float(getattr(checked, option)))
    if not out:
        raise ValueError(f"{option} must list at least one value")
    repeated = sorted({v for v in out if out.count(v) > 1})
    if repeated:
        raise ValueError(f"{option} lists {', '.join(f'{v:g}' for v in repeated)} more than once")
    return sorted(out)


def _swept_and_fixed(
    sweeps: Mapping[str, Sequence[float]],
) -> tuple[dict[str, list[float]], dict[str, float]]:
    """The options swept (several values; all given ones where none has several) and
    those fixed (a single value while another option is swept)."""
    checked = {option: sweep_values(option, values) for option, values in sweeps.items()}
    if not checked:
        raise ValueError(f"no option to sweep; give values for one of {', '.join(SWEPT)}")
    swept = {o: v for o, v in checked.items() if len(v) > 1} or checked
    fixed = {o: v[0] for o, v in checked.items() if o not in swept}
    return swept, fixed


def robustness_configs(
    cfg: SwarmConfig,
    sweeps: Mapping[str, Sequence[float]],
    *,
    failure_mode: str | None = None,
    failure_time: int | Sequence[int] | None = None,
) -> list[SweepRow]:
    """The rows of a sweep: ``cfg`` with its ``perturbations`` set for each option and
    value of ``sweeps`` (options in :data:`SWEPT` order, values increasing).

    Args:
        cfg: the scenario; only its ``perturbations`` section is replaced.
        sweeps: ``{option: values}``, options of :data:`SWEPT` (module docstring: which
            are swept and which are fixed).
        failure_mode, failure_time: replace the section's own (``None``: keep them).

    Raises:
        ValueError: a bad option or value (:func:`sweep_values`), a bad failure mode or
            time, or a row whose config is not valid (e.g. fractions that sum to 1 or
            more with the config's absent or joining agents, physics masks with another
            dynamics or integrator), naming the option and value.
    """
    swept, fixed = _swept_and_fixed(sweeps)
    background: dict[str, Any] = {option: 0.0 for option in SWEPT}
    background.update(fixed)
    if failure_mode is not None:
        background["failure_mode"] = failure_mode
    if failure_time is not None:
        background["failure_time"] = failure_time
    base = dataclasses.replace(cfg.perturbations, **background)
    rows = []
    for option in SWEPT:
        for value in swept.get(option, ()):
            try:
                change: dict[str, Any] = {option: value}
                p = dataclasses.replace(base, **change)
                row_cfg = dataclasses.replace(cfg, perturbations=p)
            except ValueError as err:
                raise ValueError(f"the config is not valid at {option}={value:g}: {err}") from None
            rows.append(SweepRow(option, value, row_cfg))
    return rows


def evaluate_robustness(
    policies: Mapping[str, Any],
    cfg: SwarmConfig | Any,
    sweeps: Mapping[str, Sequence[float]],
    episodes: int = 20,
    seed: int = 0,
    *,
    failure_mode: str | None = None,
    failure_time: int | Sequence[int] | None = None,
    out_dir: str | Path | None = None,
    env_id: str = ENV_ID,
    deterministic: bool = True,
    progress: bool = True,
    plots: bool = True,
    extra: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Evaluate every policy at each perturbation of ``sweeps`` on the same episodes.

    Args:
        policies: ``{name: policy}``; each with SB3's ``predict`` (shared or central).
        cfg: the scenario, a :class:`SwarmConfig` or any swarm_envs env; only its
            ``perturbations`` is replaced (:func:`robustness_configs`). Its
            ``on_unstable`` is used as it is.
        sweeps: ``{option: values}`` for options of :data:`SWEPT`, e.g.
            ``{"failed_fraction": [0, 0.1, 0.3], "obs_noise": [0, 0.5]}``.
        episodes: episodes per policy and row.
        seed: seed of the episodes, the same for every policy and row.
        failure_mode, failure_time: how and when agents fail (``None``: the config's).
        out_dir: if given, write the outputs there (:func:`write_robustness_outputs`).
        env_id: recorded as ``"env"``.
        deterministic: passed to every ``predict``.
        progress: a tqdm progress bar per policy and row.
        plots: write ``robustness.png`` (with ``out_dir``).
        extra: more top-level entries for the results (e.g. the config path).

    Returns:
        ``{"env", "config", "sweeps", "perturbations", "episodes", "seed",
        "on_unstable", "metrics", "rows": [{"option", "value", "perturbations",
        "backend", "policies": {name: measures}}, ...]}`` (JSON-ready; undefined
        measures are None). ``config`` is the scenario as given, ``sweeps`` the swept
        options' values, ``perturbations`` the section every row starts from (the fixed
        options included) and each row's ``perturbations`` its whole section.

    Raises:
        SpaceMismatchError: a policy's spaces do not fit ``cfg`` (checked for all
            before running).
        ValueError: no policies, or a bad sweep (:func:`robustness_configs`).
        SwarmUnstableError: a step went unstable with ``on_unstable="raise"``.
    """
    cfg = swarm_config_of(cfg)
    rows = robustness_configs(cfg, sweeps, failure_mode=failure_mode, failure_time=failure_time)
    check_policies(policies, cfg)  # warns where a model's env meant something else
    entries = [
        {
            "option": row.option,
            "value": row.value,
            "perturbations": as_dict(row.cfg.perturbations),
            **measure_row(
                policies,
                row.cfg,
                episodes,
                seed,
                label=f"{row.option}={row.value:g}",
                deterministic=deterministic,
                progress=progress,
            ),
        }
        for row in rows
    ]
    swept: dict[str, list[float]] = {}
    for row in rows:
        swept.setdefault(row.option, []).append(row.value)
    swept_off: dict[str, Any] = {rows[0].option: 0.0}
    background = dataclasses.replace(rows[0].cfg.perturbations, **swept_off)
    results: dict[str, Any] = {
        "env": env_id,
        **dict(extra or {}),
        "config": as_dict(cfg),
        "sweeps": swept,
        "perturbations": as_dict(background),
        "episodes": int(episodes),
        "seed": int(seed),
        "on_unstable": cfg.on_unstable,
        "metrics": METRIC_DOCS,
        "rows": entries,
    }
    if out_dir is not None:
        write_robustness_outputs(results, out_dir, plots=plots)
    return results


def _names(results: Mapping[str, Any]) -> list[str]:
    names: list[str] = []
    for row in results["rows"]:
        names += [n for n in row["policies"] if n not in names]
    return names


def _rows(results: Mapping[str, Any]) -> list[tuple[str, Mapping[str, Any], Mapping[str, Any]]]:
    """``(policy, row, measures)`` grouped by option, then policy, values increasing."""
    options = list(dict.fromkeys(row["option"] for row in results["rows"]))
    return [
        (name, row, row["policies"][name])
        for option in options
        for name in _names(results)
        for row in results["rows"]
        if row["option"] == option and name in row["policies"]
    ]


def _value(value: float) -> str:
    return f"{value:g}" if math.isfinite(value) else str(value)


def format_robustness_table(results: Mapping[str, Any]) -> str:
    """The robustness measures as a markdown table, one row per option, policy and value
    (:data:`ROBUSTNESS_COLUMNS`); an undefined measure shows as ``—``, and the last
    column marks each row's best baseline."""
    headers = ["policy", "perturbation", "value", "backend"]
    headers += [h for _, h, _ in ROBUSTNESS_COLUMNS]
    lines = [
        "| " + " | ".join([*headers, "best baseline"]) + " |",
        "|---|---|---:|---|" + "---:|" * len(ROBUSTNESS_COLUMNS) + ":---:|",
    ]
    for name, row, m in _rows(results):
        cells = [name, row["option"], _value(row["value"]), row["backend"]]
        cells += [format_cell(m, key, spec) for key, _, spec in ROBUSTNESS_COLUMNS]
        cells.append("✓" if row.get("best_baseline") == name else "")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_robustness_csv(results: Mapping[str, Any], path: Path) -> Path:
    """``robustness.csv``: one row per option, policy and value, with the row's swept
    perturbations and failure mode (:data:`ROBUSTNESS_CSV_KEYS`)."""
    with path.open("w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh)
        head = ["policy", "perturbation", "value", *SWEPT, "failure_mode", "failure_time"]
        writer.writerow([*head, "backend", "episodes", *ROBUSTNESS_CSV_KEYS])
        for name, row, m in _rows(results):
            p = row["perturbations"]
            failure_time = p["failure_time"]
            if isinstance(failure_time, list):
                failure_time = f"{failure_time[0]}-{failure_time[1]}"
            cells = [name, row["option"], row["value"], *(csv_cell(p, k) for k in SWEPT)]
            cells += [p["failure_mode"], failure_time, row["backend"], results["episodes"]]
            writer.writerow(cells + [csv_cell(m, k) for k in ROBUSTNESS_CSV_KEYS])
    return path


def _describe_background(p: Mapping[str, Any]) -> str:
    """The perturbations every row starts from, in words."""
    parts = [f"{k} = {p[k]}" for k in SWEPT if p[k] not in (0, 0.0)]
    parts.append(f"failure_mode = {p['failure_mode']}, failure_time = {p['failure_time']}")
    for k in ("absent_fraction", "join_fraction"):
        if p[k] not in (0, 0.0):
            parts.append(f"{k} = {p[k]}")
    if p["join_fraction"] not in (0, 0.0):
        parts.append(f"join_time = {p['join_time']}")
    return ", ".join(parts)


def _summary_markdown(results: Mapping[str, Any]) -> str:
    cfg = results["config"]
    swept = "; ".join(
        f"{option} = {', '.join(_value(v) for v in values)}"
        for option, values in results["sweeps"].items()
    )
    return sweep_summary(
        results,
        title="Robustness",
        setting=f"Every policy on the same seeded episodes at {swept} (each option alone, "
        f"the others as below); {results['episodes']} episodes per policy and value, seed "
        f"{results['seed']}, N = {cfg['n_agents']}, dt = {cfg['dt']}, max_steps = "
        f"{cfg['max_steps']}, on_unstable = {results['on_unstable']}",
        notes=[f"Every row: {_describe_background(results['perturbations'])}."],
        table=format_robustness_table(results),
        columns=ROBUSTNESS_COLUMNS,
    )


def write_robustness_outputs(
    results: Mapping[str, Any], out_dir: str | Path, *, plots: bool = True
) -> dict[str, Path]:
    """Write ``results.json``, ``summary.md``, ``robustness.csv`` and (``plots``)
    ``robustness.png`` into ``out_dir``; return their paths."""
    from train.evaluate.figures import plot_robustness

    return write_sweep_outputs(
        results,
        out_dir,
        stem="robustness",
        write_csv=write_robustness_csv,
        summary=_summary_markdown(results),
        plot=plot_robustness if plots else None,
    )
