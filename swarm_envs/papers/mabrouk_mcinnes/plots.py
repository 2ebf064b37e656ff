"""Plots of Mabrouk & McInnes' Figs. 1–10 (PNG, matplotlib); Fig. 11 is in ``plots_fig11``.

Every ``plot_*`` function draws the ``dict`` its figure function returned (or the
figure's JSON file, loaded) and writes a PNG; matplotlib is imported inside the
functions only. :func:`figure` and :func:`save` are shared with
:mod:`~swarm_envs.papers.mabrouk_mcinnes.plots_fig11`.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "LABELS",
    "figure",
    "plot_fig1",
    "plot_fig4_5",
    "plot_fig6_8",
    "plot_fig9",
    "plot_fig10",
    "save",
]

#: Axis labels of the statistics.
LABELS = {
    "velocity_polarization": "polarization |Σv|/N (eq. 2)",
    "polarization": "polarization |Σv̂|/N (unit headings)",
    "spherical_variance": "spherical variance 1 − |Σv̂|/N (eq. 4)",
    "velocity_angular_momentum": "angular momentum |Σr̂×v|/N (eq. 3)",
    "angular_momentum": "angular momentum |Σr̂×v̂|/N (unit headings)",
    "expanse": "expanse (mean distance to centre)",
    "nearest_neighbor_distance": "average NND (eq. 5)",
    "mean_speed": "mean speed",
}


def figure(width: float, height: float, ncols: int, nrows: int = 1) -> tuple[Any, Any]:
    """A constrained-layout matplotlib figure and its ``(nrows, ncols)`` axes array."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False)
    return fig, axes


def save(fig: Any, path: str | Path, dpi: int) -> Path:
    """Write ``fig`` to ``path`` (parent folders created) and return the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    return path


def _errorline(
    ax: Any, x: Sequence[float], stat: dict[str, list[float]], key: str, **kw: Any
) -> None:
    y = np.asarray(stat[key], dtype=float)
    err = np.asarray(stat[f"{key}_std"], dtype=float)
    ax.errorbar(x, y, yerr=err, capsize=2, marker="o", ms=3, **kw)


def plot_fig1(result: dict[str, Any], path: str | Path, *, dpi: int = 80) -> Path:
    """Fig. 1 as three panels: eq. 2 polarization over time per β; both forms vs β."""
    fig, axes = figure(11.5, 3.4, 3)
    ax0, ax1, ax2 = axes[0]
    betas = result["x"]["values"]
    ts = result["time_series"]
    from matplotlib import colormaps

    cmap = colormaps["viridis"]
    for k, (beta, curve) in enumerate(zip(betas, ts["velocity_polarization"], strict=True)):
        y = np.maximum(np.asarray(curve, dtype=float), 1e-12)
        ax0.semilogy(ts["t"], y, color=cmap(k / max(1, len(betas) - 1)), label=f"β={beta:g}")
    ax0.set(xlabel="t", ylabel="|Σv|/N (eq. 2)", title="polarization (eq. 2) vs time")
    ax0.set_ylim(bottom=1e-6)
    ax0.legend(fontsize=6, ncol=2)
    for ax, name, title in (
        (ax1, "velocity_polarization", "eq. 2 polarization vs β"),
        (ax2, "polarization", "unit-heading polarization vs β"),
    ):
        stat = result["metrics"][name]
        _errorline(ax, betas, stat, "time_mean", label="time mean")
        _errorline(ax, betas, stat, "final", label="final (t = T)", ls="--")
        ax.set_xscale("symlog", linthresh=0.01)
        ax.set(xlabel="β", title=title)
        ax.axvline(0.1, color="0.7", lw=0.8)
        ax.legend(fontsize=7)
    ax1.set_yscale("log")
    ax1.set_ylim(bottom=1e-10)  # below: rounding noise of a momentum that is zero
    fig.suptitle("Fig. 1 — polarization vs dissipation β (mean ± sd over seeds)", fontsize=10)
    return save(fig, path, dpi)


def plot_fig4_5(result: dict[str, Any], path: str | Path, *, dpi: int = 80) -> Path:
    """Figs. 4–5: spherical variance, eq. 3 and unit angular momentum vs time, per β."""
    fig, axes = figure(11.5, 3.4, 3)
    t = np.asarray(result["t"])
    for run, color in zip(result["runs"], ("tab:blue", "tab:red"), strict=False):
        for ax, name in zip(
            axes[0],
            ("spherical_variance", "velocity_angular_momentum", "angular_momentum"),
            strict=True,
        ):
            m = np.asarray(run["series_mean"][name])
            s = np.asarray(run["series_std"][name])
            ax.plot(t, m, color=color, label=f"β = {run['beta']:g}")
            ax.fill_between(t, m - s, m + s, color=color, alpha=0.2, lw=0)
    for ax, name in zip(
        axes[0],
        ("spherical_variance", "velocity_angular_momentum", "angular_momentum"),
        strict=True,
    ):
        ax.set(xlabel="t", title=LABELS[name])
        ax.title.set_fontsize(9)
        ax.legend(fontsize=7)
    fig.suptitle("Figs. 4–5 — β = 0.01 vs β = 1.8 (mean ± sd over seeds)", fontsize=10)
    return save(fig, path, dpi)


def plot_fig6_8(result: dict[str, Any], path: str | Path, *, dpi: int = 80) -> Path:
    """Figs. 6–8: angular momentum, polarization, expanse and NND vs ``C_o``."""
    fig, axes = figure(11.5, 3.4, 3)
    x = result["x"]["values"]
    m = result["metrics"]
    panels = (
        ("velocity_angular_momentum", "angular_momentum", "Fig. 6 — angular momentum"),
        ("velocity_polarization", "polarization", "Fig. 7 — polarization"),
    )
    for ax, (paper, unit, title) in zip(axes[0][:2], panels, strict=True):
        _errorline(ax, x, m[paper], "time_mean", color="tab:blue", label="eq. form, time mean")
        ax.set_ylabel("eq. 2/3 form (speed-weighted)", color="tab:blue", fontsize=8)
        twin = ax.twinx()
        _errorline(twin, x, m[unit], "time_mean", color="tab:orange", label="unit, time mean")
        _errorline(twin, x, m[unit], "final", color="tab:orange", ls="--", label="unit, final")
        twin.set_ylabel("unit-heading form", color="tab:orange", fontsize=8)
        ax.set(xlabel="C_o", title=title)
        lines = ax.get_legend_handles_labels()
        lines2 = twin.get_legend_handles_labels()
        ax.legend(lines[0] + lines2[0], lines[1] + lines2[1], fontsize=6, loc="center right")
    ax = axes[0][2]
    for name, color in (("expanse", "tab:green"), ("nearest_neighbor_distance", "tab:purple")):
        short = "expanse" if name == "expanse" else "NND"
        _errorline(ax, x, m[name], "time_mean", color=color, label=f"{short}, time mean")
        _errorline(ax, x, m[name], "final", color=color, ls="--", label=f"{short}, final")
    ax.set(xlabel="C_o", title="Fig. 8 — expanse and average NND")
    ax.legend(fontsize=6)
    fig.suptitle("Figs. 6–8 — alignment strength C_o (β = 0.1; mean ± sd over seeds)", fontsize=10)
    return save(fig, path, dpi)


def _plot_ratio(
    result: dict[str, Any], path: str | Path, dpi: int, keys: tuple[str, str], title: str
) -> Path:
    fig, axes = figure(9.0, 3.4, 2)
    x = result["x"]["values"]
    for ax, stat in zip(axes[0], ("final", "time_mean"), strict=True):
        for key, ls in zip(keys, ("-", "--"), strict=True):
            series = result["series"][key]
            _errorline(ax, x, series["expanse"], stat, color="tab:green", ls=ls,
                       label=f"expanse ({key})")  # fmt: skip
            _errorline(ax, x, series["nearest_neighbor_distance"], stat, color="tab:purple",
                       ls=ls, label=f"NND ({key})")  # fmt: skip
        ax.set(xlabel=result["x"]["name"], title=f"{stat.replace('_', ' ')} of the run")
        ax.legend(fontsize=7)
    fig.suptitle(title, fontsize=10)
    return save(fig, path, dpi)


def plot_fig9(result: dict[str, Any], path: str | Path, *, dpi: int = 80) -> Path:
    """Fig. 9: expanse and NND vs ``l``, for ``l_r`` varied and for ``l_a`` varied."""
    return _plot_ratio(
        result, path, dpi, ("vary_l_r", "vary_l_a"),
        "Fig. 9 — range ratio l = l_r/l_a (C = 1.2, β = 0.1; mean ± sd over seeds)",
    )  # fmt: skip


def plot_fig10(result: dict[str, Any], path: str | Path, *, dpi: int = 80) -> Path:
    """Fig. 10: expanse and NND vs ``C``, for ``C_r`` varied and for ``C_a`` varied."""
    return _plot_ratio(
        result, path, dpi, ("vary_C_r", "vary_C_a"),
        "Fig. 10 — amplitude ratio C = C_r/C_a (l = 0.2, β = 0.1; mean ± sd over seeds)",
    )  # fmt: skip
