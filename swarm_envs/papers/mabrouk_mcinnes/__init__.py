"""Reproductions of Mabrouk & McInnes' figures 1, 4–5, 6–8, 9, 10 and 11.

Paper: M. H. Mabrouk and C. R. McInnes, *Social potential model to simulate emergent
behaviour for swarm robots* (seeds ``000``/``001``; section 4 and the figure captions).
The model is the reading fixed in ``docs/models.md`` §1 (:mod:`swarm_envs.physics`),
the statistics those of ``docs/models.md`` §2 (:mod:`swarm_envs.metrics`).

:func:`run` is the common entry point of the reproductions
(:mod:`swarm_envs.papers.result`); its parts are the figures of :data:`FIGURES`. The
modules:

- :mod:`~swarm_envs.papers.mabrouk_mcinnes.common`: :class:`RunSetup` and the
  statistics helpers;
- :mod:`~swarm_envs.papers.mabrouk_mcinnes.sweeps` (Figs. 1–10) and
  :mod:`~swarm_envs.papers.mabrouk_mcinnes.navigation` (Fig. 11, with the decay law
  and the self-propelled mill of :mod:`~swarm_envs.papers.mabrouk_mcinnes.mill`): one
  function per figure, computing its numbers;
- :mod:`~swarm_envs.papers.mabrouk_mcinnes.claims`: what the paper states, as claims
  on those numbers;
- :mod:`~swarm_envs.papers.mabrouk_mcinnes.plots` and
  :mod:`~swarm_envs.papers.mabrouk_mcinnes.plots_fig11`: the PNGs and the Fig. 11 GIF.

Every ``fig*`` function runs the physics for several random seeds at once (leading
batch dimension), and returns a plain, JSON-ready ``dict`` of numbers:

``figure``, ``title``
    identifiers.
``paper``
    what the paper states and the parameters its caption gives.
``setup``
    the choices made where the paper is silent (:class:`RunSetup`).
``x``, ``metrics`` (sweeps)
    the swept values and, per statistic, ``time_mean`` / ``final`` (mean over seeds)
    with ``*_std`` (standard deviation over seeds).
``claims``
    one entry per trend the paper states, per statistic form: what was expected,
    what was observed (:func:`~swarm_envs.papers.claims.classify_trend`), and whether
    it ``holds``.
``verdict``
    from the claims on the paper's own statistic forms (``paper_form``):
    ``"reproduced"`` (all hold), ``"partly reproduced"`` or ``"not reproduced"``
    (none holds). Claims on other forms are reported beside them but not counted.

Choices where the paper is silent (the same for every figure, :class:`RunSetup`):

- **Time step and run length.** The paper runs "500 simulation steps (time enough to
  reach the minimum-energy state)" and gives no ``dt``. We read this as 500 steps of
  ``dt = 0.1``, i.e. **50 time units**: with the default ``β = 0.1`` that is five
  e-folding times of the momentum, enough to relax, which is what the sentence claims.
  We integrate those 50 time units with ``dt = 0.05`` (1000 semi-implicit Euler
  steps) because the stiffest settings of the sweeps (``C_o = 1``, ``l_r = 0.1``,
  ``C_r = 3``) need the margin: at the default parameters ``dt = 0.1`` gives the
  same expanse and NND to about 1 %, but at ``l_r = 0.1`` its relaxed expanse is 17 %
  too large, while ``dt = 0.05`` and ``dt = 0.025`` agree to 0.1 %.
- **Initial conditions.** Positions uniform in a disc of radius 2 around the origin,
  velocities uniform in a disc of radius 0.1 (small random velocities), drawn from
  ``numpy.random.default_rng(base_seed)``. The same initial conditions (common random
  numbers) are used for every value of a sweep, so differences along a sweep come from
  the parameter, not from the draw.
- **Seeds.** 8 by default (``RunSetup.seeds``); all statistics are averaged over them.
- **Statistics over time.** Each statistic is reported at the end of the run
  (``final``, t = 50) and averaged over the run (``time_mean``, t ∈ [0, 50], sampled
  every few steps). The paper does not say which it plots; where they differ, both
  are reported and the docs say which one carries the trend.
- **Polarization and angular momentum.** The paper's eq. 2 (``|Σ v_i|/N``) and eq. 3
  (``|Σ r̂_ic × v_i|/N``) scale with the speed: they are
  :func:`~swarm_envs.metrics.velocity_polarization` and
  :func:`~swarm_envs.metrics.velocity_angular_momentum`. The unit-heading (Couzin)
  forms :func:`~swarm_envs.metrics.polarization` and
  :func:`~swarm_envs.metrics.angular_momentum` are reported beside them. Claims on
  the paper's forms carry ``"paper_form": true``.

A structural fact worth knowing when reading the results: the pair forces
(cohesion and alignment) are central and antisymmetric, so they conserve the total
linear and angular momentum; only ``−βv`` changes them. Hence
``Σ v_i(t) = Σ v_i(0) · (1 − β dt)^n ≈ Σ v_i(0) e^{−βt}`` exactly, whatever ``C_o``,
``C``, ``l``: eq. 2 polarization depends only on the initial momentum and on ``β``.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from swarm_envs.papers._io import to_jsonable, write_json
from swarm_envs.papers.mabrouk_mcinnes.common import (
    DEFAULT_BETAS,
    DEFAULT_C_OS,
    DEFAULT_C_RATIOS,
    DEFAULT_L_RATIOS,
    NAV_GOAL,
    NAV_SNAPSHOT_TIMES,
    RELAX_SPEED,
    RunSetup,
)
from swarm_envs.papers.mabrouk_mcinnes.mill import (
    MILL_ALPHA,
    MILL_BETA,
    fig11_decay_law,
    fig11_self_propelled,
)
from swarm_envs.papers.mabrouk_mcinnes.navigation import fig11_navigation, fig11_reproduction
from swarm_envs.papers.mabrouk_mcinnes.plots import (
    plot_fig1,
    plot_fig4_5,
    plot_fig6_8,
    plot_fig9,
    plot_fig10,
)
from swarm_envs.papers.mabrouk_mcinnes.plots_fig11 import (
    plot_fig11,
    plot_fig11_decay,
    write_fig11_gif,
)
from swarm_envs.papers.mabrouk_mcinnes.sweeps import (
    fig1_polarization_vs_beta,
    fig4_5_variance_and_angular_momentum,
    fig6_8_alignment_sweep,
    fig9_range_ratio_sweep,
    fig10_amplitude_ratio_sweep,
)
from swarm_envs.papers.result import (
    PaperResult,
    PartResult,
    check_seeds,
    finish,
    output_dir,
    select_parts,
)

__all__ = [
    "DEFAULT_BETAS",
    "DEFAULT_C_OS",
    "DEFAULT_C_RATIOS",
    "DEFAULT_L_RATIOS",
    "FIGURES",
    "MILL_ALPHA",
    "MILL_BETA",
    "NAME",
    "NAV_GOAL",
    "NAV_SNAPSHOT_TIMES",
    "PARTS",
    "RELAX_SPEED",
    "TITLE",
    "FigureSpec",
    "RunSetup",
    "fig1_polarization_vs_beta",
    "fig4_5_variance_and_angular_momentum",
    "fig6_8_alignment_sweep",
    "fig9_range_ratio_sweep",
    "fig10_amplitude_ratio_sweep",
    "fig11_decay_law",
    "fig11_navigation",
    "fig11_reproduction",
    "fig11_self_propelled",
    "plot_fig1",
    "plot_fig4_5",
    "plot_fig6_8",
    "plot_fig9",
    "plot_fig10",
    "plot_fig11",
    "plot_fig11_decay",
    "run",
    "write_fig11_gif",
]

NAME = "mabrouk_mcinnes"
TITLE = (
    "M. H. Mabrouk and C. R. McInnes, Social potential model to simulate emergent "
    "behaviour for swarm robots"
)


@dataclass(frozen=True)
class FigureSpec:
    """One reproduced figure: how to compute it (full or quick), plot it, extra files.

    ``extras(result, out, setup, quick)`` writes further files (another PNG, a GIF)
    into ``out`` and returns their paths; ``None`` for the figures without any.
    """

    name: str
    title: str
    compute: Callable[[RunSetup, bool], dict[str, Any]]
    plot: Callable[..., Path]
    extras: Callable[[dict[str, Any], Path, RunSetup, bool], list[Path]] | None = None


def _quick_values(values: Sequence[float]) -> tuple[float, ...]:
    return (values[0], values[len(values) // 2], values[-1])


def _fig11_extras(result: dict[str, Any], out: Path, setup: RunSetup, quick: bool) -> list[Path]:
    params = result["self_propelled"]["parameters"]
    return [
        plot_fig11_decay(result, out / "fig11_decay.png"),
        write_fig11_gif(
            out / "fig11.gif",
            setup=setup,
            duration=result["setup"]["duration"],
            alpha=params["alpha"],
            beta=params["beta"],
            frames=20 if quick else 56,
            size=(120, 120) if quick else (300, 300),
        ),
    ]


FIGURES: dict[str, FigureSpec] = {
    spec.name: spec
    for spec in (
        FigureSpec(
            "fig1",
            "polarization vs β",
            lambda s, q: fig1_polarization_vs_beta(
                _quick_values(DEFAULT_BETAS) if q else DEFAULT_BETAS, setup=s
            ),
            plot_fig1,
        ),
        FigureSpec(
            "fig4_5",
            "spherical variance, angular momentum vs t",
            lambda s, q: fig4_5_variance_and_angular_momentum(setup=s),
            plot_fig4_5,
        ),
        FigureSpec(
            "fig6_8",
            "C_o sweep",
            lambda s, q: fig6_8_alignment_sweep(
                _quick_values(DEFAULT_C_OS) if q else DEFAULT_C_OS, setup=s
            ),
            plot_fig6_8,
        ),
        FigureSpec(
            "fig9",
            "l = l_r/l_a sweep",
            lambda s, q: fig9_range_ratio_sweep(
                _quick_values(DEFAULT_L_RATIOS) if q else DEFAULT_L_RATIOS, setup=s
            ),
            plot_fig9,
        ),
        FigureSpec(
            "fig10",
            "C = C_r/C_a sweep",
            lambda s, q: fig10_amplitude_ratio_sweep(
                _quick_values(DEFAULT_C_RATIOS) if q else DEFAULT_C_RATIOS, setup=s
            ),
            plot_fig10,
        ),
        FigureSpec(
            "fig11",
            "navigation to a sink",
            lambda s, q: fig11_reproduction(
                setup=s,
                duration=20.0 if q else 318.0,
                snapshot_times=(0.0, 5.0, 10.0, 20.0) if q else NAV_SNAPSHOT_TIMES,
                decay_duration=10.0 if q else 100.0,
            ),
            plot_fig11,
            _fig11_extras,
        ),
    )
}

#: The parts of :func:`run`: the figures, named as their files (``fig9.png`` …).
PARTS: tuple[str, ...] = tuple(FIGURES)


def run(
    out_dir: str | Path | None = None,
    *,
    quick: bool = False,
    seeds: int | None = None,
    only: Sequence[str] | None = None,
) -> PaperResult:
    """Reproduce the figures; with ``out_dir``, write their files and ``summary.json``.

    Args:
        out_dir: where to write ``<fig>.json`` and ``<fig>.png`` per figure,
            ``fig11_decay.png``, ``fig11.gif`` and ``summary.json``; ``None`` writes
            nothing.
        quick: :meth:`RunSetup.quick` sizes and three values per sweep (seconds).
        seeds: random initial conditions averaged over (``None``: 8, quick 2).
        only: figures of :data:`PARTS` to run (``None``: all). ``summary.json`` keeps
            the other figures' entries of an earlier summary with the same setup.

    Returns:
        The verdict and claims per figure; ``result["fig9"]`` is fig9's JSON document.
    """
    names = select_parts(PARTS, only)
    seeds = check_seeds(seeds)
    setup = RunSetup.quick() if quick else RunSetup()
    if seeds is not None:
        setup = replace(setup, seeds=seeds)
    out = output_dir(out_dir)
    start = time.perf_counter()
    parts: dict[str, PartResult] = {}
    data: dict[str, Any] = {}
    files: list[Path] = []
    for name in names:
        spec = FIGURES[name]
        t0 = time.perf_counter()
        result = spec.compute(setup, quick)
        doc = to_jsonable(result)
        written: list[Path] = []
        if out is not None:
            written.append(write_json(out / f"{name}.json", doc))
            written.append(spec.plot(result, out / f"{name}.png"))
            if spec.extras is not None:
                written += spec.extras(result, out, setup, quick)
        parts[name] = PartResult(
            name=name,
            title=doc["title"],
            verdict=doc["verdict"],
            claims=doc["claims"],
            elapsed_s=time.perf_counter() - t0,
            files=tuple(written),
        )
        data[name] = doc
        files += written
    return finish(
        NAME,
        TITLE,
        quick=quick,
        setup=setup.as_dict(),
        parts=parts,
        data=data,
        files=files,
        out=out,
        order=PARTS,
        started=start,
    )
