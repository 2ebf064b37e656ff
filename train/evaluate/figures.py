"""The figures of an evaluation: ``curves.png`` and one GIF of episode 0 per policy;
``transfer.png`` of a size-transfer evaluation (:func:`plot_transfer`); ``robustness.png``
of a robustness sweep (:func:`plot_robustness`).

matplotlib and :mod:`swarm_envs.render` are imported when a figure is drawn, not with
this module.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from swarm_envs.config import SwarmConfig
from train.evaluate.episodes import CURVE_KEYS, EpisodeBatch

__all__ = [
    "NON_NEGATIVE",
    "ROBUSTNESS_PANELS",
    "TRANSFER_PANELS",
    "informative",
    "plot_curves",
    "plot_robustness",
    "plot_transfer",
    "write_episode_gif",
]


def plot_curves(batches: Mapping[str, EpisodeBatch], cfg: SwarmConfig, path: Path) -> Path:
    """Four panels (centroid distance, expanse, polarization, angular momentum) vs time;
    the ± std bands stop at 0, below which none of them goes."""
    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    titles = {
        "centroid_distance": "centroid distance to goal",
        "expanse": "expanse",
        "polarization": "polarization (unit headings)",
        "angular_momentum": "angular momentum (unit headings)",
    }
    fig = Figure(figsize=(9.0, 6.5), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, 2, sharex=True).ravel()
    for ax, key in zip(axes, CURVE_KEYS, strict=True):
        for name, b in batches.items():
            c = b.curves[key]
            mean, std = c.mean(axis=1), c.std(axis=1)
            (line,) = ax.plot(b.times, mean, label=name, lw=1.6)
            low = np.maximum(mean - std, 0.0)  # every curve is a distance or a norm: >= 0
            ax.fill_between(b.times, low, mean + std, color=line.get_color(), alpha=0.15)
        if key == "centroid_distance":
            ax.axhline(cfg.goal_radius, color="0.5", ls="--", lw=1, label="goal radius")
        ax.set_title(titles[key], fontsize=10)
        ax.grid(alpha=0.3)
    for ax in axes[2:]:
        ax.set_xlabel("time (s)")
    axes[0].legend(fontsize=8)
    episodes = next(iter(batches.values())).returns.size
    fig.suptitle(
        f"mean ± std over {episodes} episodes; an ended episode holds its last value, "
        "a curve stops when the policy's last episode ends",
        fontsize=10,
    )
    fig.savefig(path)
    return path


def write_episode_gif(
    batch: EpisodeBatch, cfg: SwarmConfig, path: Path, size: int, title: str = ""
) -> Path:
    """GIF of episode 0: at most ~100 frames of ``size``², trail of recent positions.

    Every frame carries ``title`` (the policy's name), the simulated time and a scale
    bar (the camera follows the swarm, so the scale changes during the episode).
    """
    from swarm_envs.render import SwarmRenderer, annotate, write_gif

    xs, vs, goal = batch.trajectory["x"], batch.trajectory["v"], batch.trajectory["goal"]
    every = max(1, math.ceil(len(xs) / 100))
    renderer = SwarmRenderer(size=(size, size), trail_length=4 * every)
    end = (len(xs) - 1) * cfg.dt
    frames = []
    for t in range(len(xs)):
        renderer.record(xs[t])
        if t % every == 0 or t == len(xs) - 1:
            frame = renderer.frame(xs[t], goal=goal, goal_radius=cfg.goal_radius, velocities=vs[t])
            caption = [title] if title else []
            caption.append(f"t = {t * cfg.dt:.1f} s of {end:.1f} s")
            frames.append(annotate(frame, renderer.viewport, caption))
    renderer.close()
    fps = min(25.0, 4.0 / (cfg.dt * every))  # about four times real time
    write_gif(frames, path, fps=fps, max_frames=None)
    if path.stat().st_size > 1_000_000:  # keep it small: halve the frames
        write_gif(frames[::2], path, fps=fps / 2, max_frames=None)
    return path


#: The panels of ``transfer.png``: (measure, its spread, title).
TRANSFER_PANELS = (
    ("success_rate", "success_ci95", "success rate (95 % Wilson interval)"),
    ("mean_return", "std_return", "return (mean ± std)"),
    ("mean_time_to_goal", "std_time_to_goal", "time to goal, s (mean ± std over successes)"),
    ("collisions_per_episode", "std_collisions", "collisions per episode (mean ± std)"),
)


def _draw_panel(
    ax: Any,
    xs: Any,
    entries: Sequence[Mapping[str, Any]],
    names: Sequence[str],
    key: str,
    spread: str | None,
    where: str,
) -> None:
    """One panel: ``key`` of each policy against ``xs`` (one measures mapping per x in
    ``entries[i]["policies"]``), its spread as a band (``success_ci95``: the interval;
    another key: ± that std; ``None``: no band). An undefined value leaves a gap; a
    panel with no defined value says so ("undefined at every <where>")."""
    import numpy as np

    def value(x: Any) -> float:
        return np.nan if x is None else float(x)

    defined = False
    for name in names:
        ms = [e["policies"].get(name, {}) for e in entries]
        mean = np.array([value(m.get(key)) for m in ms])
        defined |= bool(np.isfinite(mean).any())
        (line,) = ax.plot(xs, mean, marker="o", ms=4, lw=1.6, label=name)
        if spread is None:
            continue
        if spread == "success_ci95":
            ci = [m.get(spread) or (None, None) for m in ms]
            low = np.array([value(c[0]) for c in ci])
            high = np.array([value(c[1]) for c in ci])
        else:
            std = np.array([value(m.get(spread)) for m in ms])
            low, high = mean - std, mean + std
            if key in NON_NEGATIVE:
                low = np.maximum(low, 0.0)
        ax.fill_between(xs, low, high, color=line.get_color(), alpha=0.15)
    if not defined:
        ax.text(
            0.5,
            0.5,
            f"undefined at every {where}",
            ha="center",
            va="center",
            transform=ax.transAxes,
            color="0.4",
        )
    ax.grid(alpha=0.3)


#: Measures that cannot be negative: their ± std bands stop at 0.
NON_NEGATIVE = frozenset(
    {"success_rate", "mean_time_to_goal", "collisions_per_episode", "final_fraction_arrived"}
)


def informative(entries: Sequence[Mapping[str, Any]], key: str, spread: str | None) -> bool:
    """Whether a panel of ``key`` says anything: some policy has a defined value other
    than 0 (or a spread other than 0) at some x. A panel of zeros alone, such as
    collisions that never happen, is left out of the figure (and named in its title)."""
    for e in entries:
        for m in e["policies"].values():
            for k in (key, spread):
                v = m.get(k) if k else None
                if isinstance(v, (list, tuple)):
                    if any(x not in (None, 0) for x in v):
                        return True
                elif v not in (None, 0):
                    return True
    return False


def _dropped_note(dropped: Sequence[str]) -> str:
    return f"\nleft out, 0 everywhere: {', '.join(dropped)}" if dropped else ""


def _policy_names(entries: Sequence[Mapping[str, Any]]) -> list[str]:
    names: list[str] = []
    for e in entries:
        names += [n for n in e["policies"] if n not in names]
    return names


def plot_transfer(results: Mapping[str, Any], path: Path) -> Path:
    """Four panels against the swarm size N (success rate, return, time to goal,
    collisions), one line per policy with its spread as a band; an undefined value
    (``None``, e.g. the time to goal without a success) leaves a gap. N is on a log
    axis when the sizes span a factor of 10 or more."""
    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    sizes = results["sizes"]
    ns = np.array([s["n_agents"] for s in sizes], dtype=float)
    names = _policy_names(sizes)
    panels = [p for p in TRANSFER_PANELS if informative(sizes, p[0], p[1])]
    dropped = [p[2] for p in TRANSFER_PANELS if p not in panels]
    fig = Figure(figsize=(9.0, 6.5), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, 2, sharex=True).ravel()
    for ax in axes[len(panels) :]:
        ax.set_visible(False)
    for ax, (key, spread, title) in zip(axes, panels, strict=False):
        _draw_panel(ax, ns, sizes, names, key, spread, "N")
        ax.set_title(title, fontsize=10)
        if ns.size and ns.max() >= 10 * ns.min():
            ax.set_xscale("log")
        ax.set_xticks(ns, [str(int(n)) for n in ns])
        ax.minorticks_off()
    for ax in axes[max(len(panels) - 2, 0) : len(panels)]:
        ax.set_xlabel("swarm size N")
        ax.xaxis.set_tick_params(labelbottom=True)
    if panels and panels[0][0] == "success_rate":
        axes[0].set_ylim(-0.05, 1.05)
    axes[0].legend(fontsize=8)
    fig.suptitle(
        f"size transfer: {results['episodes']} episodes per policy and N, "
        f"on_unstable={results['on_unstable']}{_dropped_note(dropped)}",
        fontsize=10,
    )
    fig.savefig(path)
    return path


#: The panels of ``robustness.png``: (measure, its spread or None, title).
ROBUSTNESS_PANELS = (
    ("success_rate", "success_ci95", "success rate (95 % Wilson)"),
    ("mean_return", "std_return", "return (mean ± std)"),
    ("mean_time_to_goal", "std_time_to_goal", "time to goal, s"),
    ("collisions_per_episode", "std_collisions", "collisions per episode"),
    ("final_fraction_arrived", None, "fraction of members arrived"),
)


def plot_robustness(results: Mapping[str, Any], path: Path) -> Path:
    """One row of five panels per swept option (success rate, return, time to goal,
    collisions, fraction of the members arrived) against the option's value, one line
    per policy with its spread as a band (the time to goal: ± std over successes); an
    undefined value leaves a gap."""
    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    options = list(results["sweeps"])
    names = _policy_names(results["rows"])
    panels = [p for p in ROBUSTNESS_PANELS if informative(results["rows"], p[0], p[1])]
    dropped = [p[2] for p in ROBUSTNESS_PANELS if p not in panels]
    cols = max(len(panels), 1)
    fig = Figure(figsize=(3.0 * cols, 0.6 + 2.6 * len(options)), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(options), cols, squeeze=False)
    for r, option in enumerate(options):
        entries = [row for row in results["rows"] if row["option"] == option]
        xs = np.array([row["value"] for row in entries], dtype=float)
        for ax, (key, spread, title) in zip(axes[r], panels, strict=False):
            _draw_panel(ax, xs, entries, names, key, spread, "value")
            ax.set_title(title, fontsize=9)
            ax.set_xticks(xs, [f"{x:g}" for x in xs])
            ax.set_xlabel(option)
            if key in ("success_rate", "final_fraction_arrived"):
                ax.set_ylim(-0.05, 1.05)
    axes[0][0].legend(fontsize=8)
    fig.suptitle(
        f"robustness: {results['episodes']} episodes per policy and value, seed "
        f"{results['seed']}, the same episodes at every value; on_unstable="
        f"{results['on_unstable']}{_dropped_note(dropped)}",
        fontsize=10,
    )
    fig.savefig(path)
    return path
