"""Plots of the Vanualailai & Sharma reproduction: one PNG per figure, a GIF of Fig. 5.

They draw the trajectories of
:func:`~swarm_envs.papers.vanualailai_sharma.simulation.simulate_figure`; matplotlib is
imported inside the functions only.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from swarm_envs.metrics import centroid
from swarm_envs.physics.lagrangian import LagrangianParams, lagrangian_value

__all__ = ["plot_figure", "write_fig5_gif"]


def _figure(width: float, height: float, ncols: int) -> tuple[Any, Any]:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), layout="constrained")
    return fig, fig.subplots(1, ncols, squeeze=False)[0]


def _traj(ax: Any, xs: np.ndarray, title: str, *, sl: slice = slice(None)) -> None:
    c = centroid(xs)
    ax.plot(xs[sl, :, 0], xs[sl, :, 1], lw=0.4, color="0.65")
    ax.plot(c[sl, 0], c[sl, 1], color="k", lw=2.2, label="centroid")
    end = xs[sl][-1]
    ax.plot(end[:, 0], end[:, 1], "o", ms=3, color="tab:blue")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title(title, fontsize=9)


def _initial(ax: Any, xs: np.ndarray, r: float, title: str = "(a) t = 0") -> None:
    from matplotlib.patches import Circle

    for p in xs[0]:
        ax.add_patch(Circle(p, r, fill=False, lw=0.6, color="tab:blue"))
    ax.plot(xs[0, :, 0], xs[0, :, 1], ".", ms=2, color="tab:blue")
    ax.set_aspect("equal", adjustable="datalim")
    ax.autoscale_view()
    ax.set_title(title, fontsize=9)


def _energy(ax: Any, xs: np.ndarray, params: LagrangianParams, dt: float) -> None:
    L = lagrangian_value(xs, params)
    ax.semilogy(np.arange(len(L)) * dt, L, color="tab:red")
    ax.set_xlabel("t")
    ax.set_title("L(t) (eq. 6 is not ∇L: L need not decrease)", fontsize=9)


def plot_figure(
    name: str,
    path: str | Path,
    *,
    params: LagrangianParams,
    xs: np.ndarray,
    dt: float,
    r: float,
    verdict: str,
    leader: int | None = None,
    dpi: int = 90,
) -> Path:
    """Figure ``name`` (``"fig1"`` … ``"fig5"``): start, paths, and a third panel.

    The third panel is ``L(t)`` for Figs. 1–2, the final positions coloured by ``γ_i``
    with the ``leader`` marked for Fig. 3, agent 0's late path for Fig. 4, and the
    circling phase for Fig. 5 (whose second panel shows the first half only).
    """
    T = len(xs) - 1
    fig, ax = _figure(13, 4.2, 3)
    _initial(ax[0], xs, r)
    if name == "fig3":
        _traj(ax[1], xs, "(b) paths, centroid thick")
        g = np.asarray(params.gamma)
        sc = ax[2].scatter(xs[-1, :, 0], xs[-1, :, 1], c=g, cmap="viridis", s=25)
        lead = 0 if leader is None else leader
        ax[2].plot(*xs[-1, lead], "r*", ms=14, label=f"leader (γ={g[lead]:.2f})")
        c = centroid(xs)
        ax[2].annotate(
            "", xy=c[-1] + (c[-1] - c[-20]), xytext=c[-1], arrowprops={"arrowstyle": "->"}
        )
        ax[2].set_aspect("equal", adjustable="datalim")
        ax[2].legend(fontsize=7)
        ax[2].set_title("(c) final positions, colour = γ_i, arrow = heading", fontsize=9)
        fig.colorbar(sc, ax=ax[2], shrink=0.7)
    elif name == "fig4":
        _traj(ax[1], xs, "(b) paths, centroid thick")
        c = centroid(xs)
        ax[2].plot(xs[T // 2 :, 0, 0], xs[T // 2 :, 0, 1], lw=0.8, color="tab:green")
        ax[2].plot(c[T // 2 :, 0], c[T // 2 :, 1], lw=0.6, color="k", alpha=0.5)
        ax[2].set_aspect("equal", adjustable="datalim")
        ax[2].set_title("(c) agent 0 (green) and centroid, late half", fontsize=9)
    elif name == "fig5":
        _traj(
            ax[1],
            xs,
            f"(b) t ≤ {T // 2 * dt:g}: random walk, then circling",
            sl=slice(0, T // 2 + 1),
        )
        _traj(ax[2], xs, f"(c) t ≥ {T * 3 // 4 * dt:g}", sl=slice(T * 3 // 4, T + 1))
    else:
        _traj(ax[1], xs, "(b) paths, centroid thick")
        _energy(ax[2], xs, params, dt)
    fig.suptitle(f"Vanualailai & Sharma {name}: {verdict}", fontsize=10)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    return path


def write_fig5_gif(path: str | Path, xs: np.ndarray) -> Path:
    """Fig. 5's circling phase (last quarter), 36 frames at 200 px, short trails (< 400 KB)."""
    from swarm_envs.render import Viewport, draw_swarm, write_gif

    T = len(xs) - 1
    late = xs[T * 3 // 4 :]
    vp = Viewport.fit(late.reshape(-1, 2), size=(200, 200))
    frames = []
    for k in np.linspace(T * 3 // 4 + 16, T, 36).astype(int):
        frames.append(draw_swarm(xs[k], trails=xs[k - 16 : k : 4], viewport=vp))
    return write_gif(frames, path, fps=12)
