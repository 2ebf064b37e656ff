"""The ``sweep.png`` figure: the plotted measures against the first grid key.

matplotlib is imported when :func:`plot_summary` is called, not with this module.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from train.sweep.config import SweepConfig

__all__ = ["plot_summary"]


def plot_summary(sc: SweepConfig, summary: Sequence[Mapping[str, Any]], path: Path) -> None:
    """One panel per plotted measure: mean ± std over seeds against the first grid key,
    one line per combination of the other keys."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    keys = list(sc.grid)
    xkey, others = keys[0], keys[1:]
    xs = list(sc.grid[xkey])
    numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in xs)
    measures = sc.plot_measures()
    cols = min(2, len(measures))
    rows_n = math.ceil(len(measures) / cols)
    fig, axes = plt.subplots(rows_n, cols, figsize=(5.2 * cols, 3.6 * rows_n), squeeze=False)
    combos = list(itertools.product(*(sc.grid[k] for k in others))) or [()]
    for ax, measure in zip(axes.flat, measures, strict=False):
        for combo in combos:
            fixed = dict(zip(others, combo, strict=True))
            line = [e for e in summary if all(e[k] == v for k, v in fixed.items())]
            line.sort(key=lambda e: xs.index(e[xkey]))
            ys = [e[f"{measure}_mean"] for e in line]
            es = [e[f"{measure}_std"] for e in line]
            xv = [e[xkey] for e in line] if numeric else list(range(len(line)))
            y = np.array([np.nan if v is None else v for v in ys], np.float64)
            err = np.array([0.0 if v is None else v for v in es], np.float64)
            label = ", ".join(f"{k} = {v}" for k, v in fixed.items()) or None
            ax.errorbar(xv, y, yerr=err, marker="o", ms=3, capsize=2, label=label)
        if not numeric:
            ax.set_xticks(range(len(xs)), [str(v) for v in xs])
        ax.set_xlabel(xkey)
        ax.set_ylabel(measure.replace("_", " "))
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(measures) :]:
        ax.set_visible(False)
    if others and len(combos) <= 10:
        axes.flat[0].legend(fontsize=7)
    fig.suptitle(f"{sc.task} sweep: mean ± std over {len(sc.seeds)} seeds", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
