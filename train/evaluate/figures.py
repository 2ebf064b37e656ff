"""The figures of an evaluation: ``curves.png`` and one GIF of episode 0 per policy.

matplotlib and :mod:`swarm_envs.render` are imported when a figure is drawn, not with
this module.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path

from swarm_envs.config import SwarmConfig
from train.evaluate.episodes import CURVE_KEYS, EpisodeBatch

__all__ = ["plot_curves", "write_episode_gif"]


def plot_curves(batches: Mapping[str, EpisodeBatch], cfg: SwarmConfig, path: Path) -> Path:
    """Four panels (centroid distance, expanse, polarization, angular momentum) vs time."""
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
            ax.fill_between(b.times, mean - std, mean + std, color=line.get_color(), alpha=0.15)
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


def write_episode_gif(batch: EpisodeBatch, cfg: SwarmConfig, path: Path, size: int) -> Path:
    """GIF of episode 0: at most ~100 frames of ``size``², trail of recent positions."""
    from swarm_envs.render import SwarmRenderer, write_gif

    xs, vs, goal = batch.trajectory["x"], batch.trajectory["v"], batch.trajectory["goal"]
    every = max(1, math.ceil(len(xs) / 100))
    renderer = SwarmRenderer(size=(size, size), trail_length=4 * every)
    frames = []
    for t in range(len(xs)):
        renderer.record(xs[t])
        if t % every == 0 or t == len(xs) - 1:
            frames.append(
                renderer.frame(xs[t], goal=goal, goal_radius=cfg.goal_radius, velocities=vs[t])
            )
    renderer.close()
    fps = min(25.0, 4.0 / (cfg.dt * every))  # about four times real time
    write_gif(frames, path, fps=fps, max_frames=None)
    if path.stat().st_size > 1_000_000:  # keep it small: halve the frames
        write_gif(frames[::2], path, fps=fps / 2, max_frames=None)
    return path
