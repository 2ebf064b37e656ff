"""Plots of Fig. 11 (PNG, matplotlib) and its animation (GIF, :mod:`swarm_envs.render`).

:func:`plot_fig11` draws the self-propelled mill of
:func:`~swarm_envs.papers.mabrouk_mcinnes.navigation.fig11_reproduction` (snapshots of
seed 0 and the rotation statistics over time), :func:`plot_fig11_decay` the decay law of
the angular momentum under the paper's linear friction and the paper's run, and
:func:`write_fig11_gif` re-simulates seed 0 of the self-propelled run.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from swarm_envs.papers.mabrouk_mcinnes.common import NAV_GOAL, RunSetup
from swarm_envs.papers.mabrouk_mcinnes.mill import (
    MILL_ALPHA,
    MILL_BETA,
    fig11_self_propelled_positions,
)
from swarm_envs.papers.mabrouk_mcinnes.plots import figure, save

__all__ = ["plot_fig11", "plot_fig11_decay", "write_fig11_gif"]


def _circle(center: np.ndarray, radius: float) -> Any:
    from matplotlib.patches import Circle

    return Circle(tuple(center), radius, fill=False, color="tab:red", lw=0.8)


def _snapshot(ax: Any, p: np.ndarray, vel: np.ndarray, g: np.ndarray, title: str) -> None:
    c = p.mean(axis=0)
    ax.scatter(p[:, 0], p[:, 1], s=8)
    speed = np.linalg.norm(vel, axis=-1, keepdims=True)
    u = vel / np.maximum(speed, 1e-12)
    ax.quiver(p[:, 0], p[:, 1], u[:, 0], u[:, 1], angles="xy", scale=25, width=0.006,
              color="0.4")  # fmt: skip
    half = max(0.5, 1.3 * float(np.abs(p - c).max()))
    ax.set_xlim(c[0] - half, c[0] + half)
    ax.set_ylim(c[1] - half, c[1] + half)
    ax.set_aspect("equal")
    if np.all(np.abs(g - c) <= half):
        ax.plot(*g, marker="x", color="tab:red", ms=8, mew=2)
    ax.set_title(title, fontsize=8)
    ax.tick_params(labelsize=6)


def _per_seed(ax: Any, t: Any, rows: Any, color: str, label: str) -> None:
    y = np.asarray(rows, dtype=float)
    for row in y:
        ax.plot(t, row, color=color, lw=0.5, alpha=0.35)
    ax.plot(t, y.mean(axis=0), color=color, lw=1.5, label=label)


def plot_fig11(result: dict[str, Any], path: str | Path, *, dpi: int = 80) -> Path:
    """Fig. 11 with self-propulsion: seed 0's approach and snapshots, rotation over time.

    Top: seed 0's centroid path with the snapshots, then the snapshots zoomed (unit
    headings as arrows). Then, per seed (thin) and their mean (thick): the centroid
    distance and mean radius ``R̄`` about ``G``, the unit-heading milling, ``σ·L_G``
    (symlog axis, with ``R̄·v₀``) and ``σ·v_t / v₀`` (``σ``: each seed's sense of
    rotation at the end), the mean speed and polarization.
    """
    sp = result["self_propelled"]
    v0 = sp["parameters"]["cruise_speed"]
    g = np.asarray(sp["goal"])
    snaps = sp["snapshots"]
    pos = np.asarray(snaps["positions_seed0"])
    vel = np.asarray(snaps["velocities_seed0"])
    n_snap = min(len(snaps["t"]), 6)
    fig, axes = figure(12.0, 8.6, 4, 3)
    flat = list(axes.ravel())
    overview = flat[0]
    for k in range(len(snaps["t"])):
        overview.scatter(pos[k, :, 0], pos[k, :, 1], s=2, label=f"t = {snaps['t'][k]:g}")
    overview.plot(*g, marker="x", color="tab:red", ms=8, mew=2)
    overview.add_patch(_circle(g, sp["goal_radius"]))
    overview.set_aspect("equal", adjustable="datalim")
    overview.set_title("seed 0 at the snapshot times; G = ×", fontsize=8)
    overview.legend(fontsize=5, markerscale=3)
    m = snaps["seed0"]
    panels = [flat[k] for k in (1, 2, 3, 4, 5, 6)][:n_snap]
    for k, ax in enumerate(panels):
        title = (
            f"t = {snaps['t'][k]:g}: |c − G| = {m['centroid_distance'][k]:.2g}, "
            f"mill {m['milling'][k]:.2f}, v_t = {m['tangential_speed'][k]:.2f}"
        )
        _snapshot(ax, pos[k], vel[k], g, title)
    for extra in flat[1 + n_snap : 7]:
        extra.set_axis_off()
    ts = sp["time_series"]
    t = np.asarray(ts["t"])
    sense = np.asarray(ts["sense"])[:, None]
    ax = flat[7]
    _per_seed(ax, t, ts["centroid_distance"], "tab:blue", "|centroid − G|")
    _per_seed(ax, t, ts["mean_radius"], "tab:purple", "mean radius R̄ about G")
    ax.set_yscale("log")
    ax.set(xlabel="t", title="distance to G")
    ax.legend(fontsize=6)
    hold = sp["hold_window"][0]
    for ax, key, scale, label, title in (
        (flat[8], "milling", None, "unit milling", "unit-heading milling |Σ r̂_c × v̂|/N"),
        (flat[9], "goal_angular_momentum", 1.0, "σ·L_G", "angular momentum about G"),
        (flat[10], "tangential_speed", v0, "σ·v_t/v₀", "tangential speed about G"),
    ):
        y = np.asarray(ts[key], dtype=float)
        if scale is not None:
            y = sense * y / scale
        _per_seed(ax, t, y, "tab:orange", label)
        ax.axvspan(hold, t[-1], color="0.9", lw=0, zorder=0)
        ax.set(xlabel="t", title=title)
        ax.title.set_fontsize(9)
        ax.legend(fontsize=6, loc="lower right")
    flat[8].set_ylim(0, 1.05)
    flat[9].set_yscale("symlog", linthresh=1.0)
    ring = np.asarray(ts["mean_radius"], dtype=float).mean(axis=0) * v0
    flat[9].plot(t, ring, color="k", ls="--", lw=0.8, label="R̄·v₀ (ring at v₀)")
    flat[9].legend(fontsize=6, loc="upper right")
    ax = flat[11]
    _per_seed(ax, t, ts["mean_speed"], "tab:green", "mean speed")
    _per_seed(ax, t, ts["polarization"], "tab:gray", "unit polarization")
    ax.axhline(v0, color="k", ls="--", lw=0.8, label="cruise speed v₀")
    ax.set(xlabel="t", title="speed and polarization")
    ax.legend(fontsize=6)
    p = sp["parameters"]
    fig.suptitle(
        f"Fig. 11 with self-propulsion (α = {p['alpha']:g}, β_R = {p['beta']:g}, v₀ = {v0:g}; "
        "N = 31, C_g = 15, l_g = 5, C_o = 0.7); shaded: hold window of the claims",
        fontsize=10,
    )
    return save(fig, path, dpi)


def plot_fig11_decay(result: dict[str, Any], path: str | Path, *, dpi: int = 80) -> Path:
    """The paper's linear friction: ``|L_G(t)|`` against ``L_G(0)(1 − β dt/m)^n``, and the run.

    Left: ``|L_G|/S₀`` of every seed per case (solid, ``S₀ = mean_i |r_i − G||v_i|`` at
    ``t = 0``) with the exact prediction (dashed black) on a log axis; below about
    ``1e-15`` only round-off is left. Right: the paper's run (β = 1): centroid distance
    to ``G`` and the unit-heading milling and polarization (seed means).
    """
    decay = result["decay_law"]
    fig, axes = figure(11.5, 3.8, 2)
    ax, right = axes[0]
    t = np.asarray(decay["t"])
    colors = ("tab:blue", "tab:green", "tab:red")
    for case, color in zip(decay["cases"], colors, strict=False):
        scale = np.asarray(case["scale_per_seed"])[:, None]
        meas = np.asarray(case["abs_L_per_seed"]) / scale
        pred = np.asarray(case["abs_prediction_per_seed"]) / scale
        first = color == colors[0]
        for k, (row, prow) in enumerate(zip(meas, pred, strict=True)):
            law = "L_G(0)(1 − β dt/m)^n" if k == 0 and first else None
            ax.semilogy(t, np.maximum(row, 1e-300), color=color, lw=1.4, alpha=0.6,
                        label=case["label"] if k == 0 else None)  # fmt: skip
            ax.semilogy(t, np.maximum(prow, 1e-300), color="k", ls="--", lw=0.6,
                        label=law)  # fmt: skip
    ax.set_ylim(1e-18, 10)
    ax.axhspan(1e-18, 1e-15, color="0.92", lw=0, zorder=0)
    ax.set(xlabel="t", ylabel="|L_G| / S₀", title="angular momentum about G, linear friction")
    ax.title.set_fontsize(9)
    ax.legend(fontsize=6, loc="upper right")
    nav = result["linear_friction"]
    ts, ss = nav["time_series"], nav["sampled_series"]
    right.plot(ts["t"], ts["centroid_distance"], color="tab:blue", label="|centroid − G|")
    right.set(xlabel="t", ylabel="distance")
    twin = right.twinx()
    twin.plot(ss["t"], ss["angular_momentum"], color="tab:orange", label="unit milling")
    twin.plot(ss["t"], ss["polarization"], color="tab:green", label="unit polarization")
    twin.set_ylim(0, 1.05)
    lines = right.get_legend_handles_labels()
    lines2 = twin.get_legend_handles_labels()
    right.legend(lines[0] + lines2[0], lines[1] + lines2[1], fontsize=6, loc="center left")
    right.set_title("the paper's run (β = 1), seed means", fontsize=9)
    fig.suptitle(
        "Fig. 11 — with linear friction L_G decays exactly: no lasting vortex "
        f"(dt = {decay['dt']:g}; grey band: round-off)",
        fontsize=10,
    )
    return save(fig, path, dpi)


def write_fig11_gif(
    path: str | Path,
    *,
    setup: RunSetup | None = None,
    goal: Sequence[float] = NAV_GOAL,
    duration: float = 318.0,
    alpha: float = MILL_ALPHA,
    beta: float = MILL_BETA,
    goal_radius: float = 1.0,
    n_agents: int = 31,
    frames: int = 56,
    size: tuple[int, int] = (300, 300),
    fps: float = 12,
    trail_time: float = 1.0,
) -> Path:
    """GIF of seed 0 of the self-propelled Fig. 11 run (the same start, re-simulated).

    The view is centred between the swarm's centroid and the goal and zooms in as the
    swarm approaches (half-width ``0.6·distance + 0.8``), so that the goal stays in
    view and the mill is visible at the sink. The ``frames`` frames are spaced evenly in
    a progress variable that mixes elapsed time and distance covered (half each), so the
    approach is not squeezed into a few frames; each agent has a trail over the last
    ``trail_time`` time units and a heading tick.
    """
    from swarm_envs.render import Viewport, draw_swarm, write_gif

    setup = RunSetup() if setup is None else setup
    g = np.asarray(goal, dtype=np.float64)
    xs, vs = fig11_self_propelled_positions(
        setup=setup, goal=goal, duration=duration, alpha=alpha, beta=beta, n_agents=n_agents
    )
    centres = xs.mean(axis=1)
    dist = np.linalg.norm(centres - g, axis=-1)
    covered = np.maximum.accumulate(dist[0] - dist)
    span = max(float(covered[-1]), 1e-12)
    progress = 0.5 * np.arange(dist.size) / max(1, dist.size - 1) + 0.5 * covered / span
    pick = np.unique(np.searchsorted(progress, np.linspace(0.0, progress[-1], frames)))
    pick = np.minimum(pick, dist.size - 1)
    back = max(2, round(trail_time / setup.dt))
    stride = max(1, back // 10)
    images = []
    for i in pick:
        vp = Viewport(center=tuple((centres[i] + g) / 2), half_width=0.6 * dist[i] + 0.8, size=size)
        trail = xs[max(0, i - back) : i : stride] if i > 0 else None
        images.append(
            draw_swarm(
                xs[i],
                goal=g,
                goal_radius=goal_radius,
                trails=trail,
                velocities=vs[i],
                viewport=vp,
                agent_radius_px=max(2.0, min(size) / 110),
            )
        )
    return write_gif(images, path, fps=fps, max_frames=None)
