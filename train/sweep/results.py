"""What a sweep produced: per-trial rows, per-point summary, and the files written.

:func:`write_outputs` writes ``trials.csv`` (one row per trial), ``summary.csv`` (per
grid point: mean and population std over seeds of every measure), ``results.json``
(both, with the config), ``sweep_config.yaml`` and ``sweep.png``
(:func:`train.sweep.plot.plot_summary`).
"""

from __future__ import annotations

import csv
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from train.sweep.config import SweepConfig
from train.sweep.measures import measure_columns
from train.sweep.plot import plot_summary

__all__ = ["SweepResult", "summarize_rows", "write_outputs"]


@dataclass
class SweepResult:
    """What a sweep produced: the per-trial ``rows`` and the per-point ``summary``."""

    config: SweepConfig
    engine: str
    rows: list[dict[str, Any]]
    summary: list[dict[str, Any]]
    seconds: float


def summarize_rows(sc: SweepConfig, rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Per grid point: ``<measure>_mean`` and ``<measure>_std`` (population) over seeds.

    Missing values (a failed episode's ``time_to_goal``) are left out of that measure;
    ``n_seeds`` counts the trials of the point. A measure with no value is ``None``.
    """
    keys = list(sc.grid)
    groups: dict[tuple, list[Mapping[str, Any]]] = {}
    for row in rows:
        groups.setdefault(tuple(row[k] for k in keys), []).append(row)
    out = []
    for point in sc.points():
        members = groups.get(tuple(point[k] for k in keys), [])
        entry: dict[str, Any] = {**point, "n_seeds": len(members)}
        for col in measure_columns(sc.task):
            values = np.array([r[col] for r in members if r.get(col) is not None], np.float64)
            entry[f"{col}_mean"] = float(values.mean()) if values.size else None
            entry[f"{col}_std"] = float(values.std()) if values.size else None
        out.append(entry)
    return out


def _write_csv(path: Path, rows: Sequence[Mapping[str, Any]]) -> None:
    columns = list(rows[0]) if rows else []
    with path.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=columns)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: ("" if row.get(k) is None else row.get(k)) for k in columns})


def write_outputs(result: SweepResult, out_dir: str | Path, *, plot: bool = True) -> Path:
    """Write ``trials.csv``, ``summary.csv``, ``results.json``, ``sweep_config.yaml`` and
    (``plot``) ``sweep.png`` into ``out_dir``; returns the folder."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    sc = result.config
    _write_csv(out / "trials.csv", result.rows)
    _write_csv(out / "summary.csv", result.summary)
    (out / "sweep_config.yaml").write_text(yaml.safe_dump(sc.to_dict(), sort_keys=False))
    payload = {
        "config": sc.to_dict(),
        "engine": result.engine,
        "trials": len(result.rows),
        "seconds": round(result.seconds, 3),
        "measures": list(measure_columns(sc.task)),
        "summary": result.summary,
        "rows": result.rows,
    }
    (out / "results.json").write_text(json.dumps(payload, indent=1) + "\n")
    if plot:
        plot_summary(sc, result.summary, out / "sweep.png")
    return out
