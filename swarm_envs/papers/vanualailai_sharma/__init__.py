"""Reproduction of Vanualailai & Sharma, *A Lagrangian-based swarming behavior* (Figs. 1–5).

Seed ``004``; model in :mod:`swarm_envs.physics.lagrangian` (``docs/models.md`` §5; eq.
6, printed form, which is what produced the paper's figures). Table 1 / §6 behaviours:

* Fig. 1 (Type A): ``α = 1, γ = 2, β = 50``, n = 30, bin 10 — compact cluster cruising
  in a straight line, well spaced, fixed formation.
* Fig. 2 (Type A): ``α = 0.1, γ = 0.2, β = 50``, n = 70, bin 20 — constant arrangement
  about a stationary centroid.
* Fig. 3 (Type B): ``α = 1``, ``γ_i ~ U[0.01, 1]``, ``β = 100``, n = 30, bin 10 —
  nonlinear cruise with an emergent leader.
* Fig. 4 (Type C): ``α = 5, γ = 1``, ``β_ij ~ U[200, 500]``, n = 30, bin 10 — Lévy-like
  random walk of the centroid.
* Fig. 5 (Type C): as Fig. 4 with ``γ = 2`` — random walk, then circular (clockwise)
  motion.

Where the paper is silent we choose (and the JSON records): "bin r" is read as the disk
radius ``r_i`` of eq. 3; initial positions uniform in a square (side 300 for n = 30,
600 for n = 70) with every pair at least ``2.4 r`` apart (so all ``R_ij > 0``); the
random ``β_ij`` are drawn independently per ordered pair (non-reciprocal); run lengths
and frame intervals in :data:`FIGURES`; the adaptive Euler of
:func:`~swarm_envs.physics.lagrangian.simulate_lagrangian`. The paper gives no numbers
to compare with, so every verdict is qualitative, on the measures computed here.

:func:`run` is the common entry point of the reproductions
(:mod:`swarm_envs.papers.result`); its parts ``vs_fig1`` … ``vs_fig5`` are the figures.
The runs and measures are in :mod:`~swarm_envs.papers.vanualailai_sharma.simulation`,
the claims in :mod:`~swarm_envs.papers.vanualailai_sharma.claims`, the plots in
:mod:`~swarm_envs.papers.vanualailai_sharma.plots`.
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

from swarm_envs.papers._io import to_jsonable, write_json
from swarm_envs.papers.claims import verdict
from swarm_envs.papers.result import (
    PaperResult,
    PartResult,
    check_seeds,
    finish,
    output_dir,
    select_parts,
)
from swarm_envs.papers.vanualailai_sharma.claims import (
    FIGURE_CLAIMS,
    exact_gradient_claims,
    is_circle,
)
from swarm_envs.papers.vanualailai_sharma.plots import plot_figure, write_fig5_gif
from swarm_envs.papers.vanualailai_sharma.simulation import (
    FIG5_SWEEP_SEEDS,
    FIGURES,
    FigureSetup,
    exact_gradient_run,
    initial_positions,
    leader_stats,
    measures,
    simulate_figure,
)

__all__ = [
    "FIG5_SWEEP_SEEDS",
    "FIGURES",
    "NAME",
    "PARTS",
    "TITLE",
    "TITLES",
    "FigureSetup",
    "initial_positions",
    "run",
    "simulate_figure",
]

NAME = "vanualailai_sharma"
TITLE = "J. Vanualailai and B. Sharma, A Lagrangian-based swarming behavior (Figs. 1-5)"
#: The parts: one per figure, named as their PNGs (``vs_fig1.png`` …).
PARTS: tuple[str, ...] = tuple(f"vs_{name}" for name in FIGURES)

#: What each figure shows (Table 1 / §6 of the paper).
TITLES = {
    "fig1": "Fig. 1: cruise in a fixed formation (Type A)",
    "fig2": "Fig. 2: constant arrangement, stationary centroid (Type A)",
    "fig3": "Fig. 3: nonlinear path with an emergent leader (Type B)",
    "fig4": "Fig. 4: Lévy-like random walk (Type C)",
    "fig5": "Fig. 5: random walk, then circular motion (Type C)",
}

_JSON = "vanualailai_sharma.json"


def _figure_entry(name: str, quick: bool) -> tuple[dict[str, Any], dict[str, Any]]:
    """The JSON entry of one figure (numbers, claims, verdict) and its run for the plot."""
    s = FIGURES[name]
    params, xs, vs, dt = simulate_figure(s, quick=quick)
    m = measures(params, xs, vs, dt)
    entry: dict[str, Any] = {
        "title": TITLES[name],
        "paper": {
            "n": s.n,
            "bin_radius": s.r,
            "alpha": s.alpha,
            "gamma": s.gamma if s.gamma_range is None else f"U{s.gamma_range}",
            "beta": s.beta if s.beta_range is None else f"U{s.beta_range}",
        },
        "choices": {"side": s.side, "dt": s.dt, "frames": len(xs) - 1, "seed": s.seed},
        "measures": m,
    }
    if name == "fig3":
        entry["leader"] = leader_stats(params, xs, vs)
    if name == "fig5":
        entry["seed_sweep"] = []
        if not quick:
            for sd in FIG5_SWEEP_SEEDS:
                ms = m if sd == s.seed else measures(*simulate_figure(s, seed=sd))
                entry["seed_sweep"].append(
                    {
                        "seed": sd,
                        "circle": is_circle(ms),
                        "late_total_turn_rad": ms["late_total_turn_rad"],
                    }
                )
    claims, why, note = FIGURE_CLAIMS[name](m, entry)
    entry["claims"] = claims
    entry["why"] = why
    entry["note"] = note
    return entry, {"params": params, "xs": xs, "dt": dt}


def _verdict_text(v: str, note: str, quick: bool) -> str:
    text = f"{v} ({note})" if note and v == "reproduced" else v
    return f"quick run (not meaningful): {text}" if quick else text


def _merge_previous(path: Path, results: dict[str, Any]) -> dict[str, Any]:
    """Keep the figures of an earlier JSON of the same mode that this run did not redo."""
    try:
        previous = json.loads(path.read_text())
    except (OSError, ValueError):
        return results
    if not isinstance(previous, dict) or previous.get("quick") != results["quick"]:
        return results
    kept = {k: v for k, v in previous.items() if k in FIGURES and k not in results}
    if "fig1" not in results and "fig1_exact_gradient" in previous:
        kept["fig1_exact_gradient"] = previous["fig1_exact_gradient"]
    merged = kept | results
    order = [*FIGURES, "fig1_exact_gradient", "runtime_s", "quick"]
    return {k: merged[k] for k in order if k in merged}


def run(
    out_dir: str | Path | None = None,
    *,
    quick: bool = False,
    seeds: int | None = None,
    only: Sequence[str] | None = None,
) -> PaperResult:
    """Reproduce Figs. 1–5: numbers, claims and a verdict per figure.

    Args:
        out_dir: where to write ``vs_fig1.png`` … ``vs_fig5.png``, ``vs_fig5.gif``
            (full run only), ``vanualailai_sharma.json`` and ``summary.json``;
            ``None`` writes nothing.
        quick: a few frames per figure (the verdicts are then not meaningful, and the
            JSON's say so).
        seeds: validated, not used: each figure is one seeded run, as in the paper
            (:data:`FIGURES`; Fig. 5 adds the seeds of :data:`FIG5_SWEEP_SEEDS`).
        only: parts of :data:`PARTS` to run (``None``: all); the JSON keeps the other
            figures of an earlier one of the same mode.

    Returns:
        The verdict and claims per figure. The result reads as the JSON document:
        per figure ``paper``, ``choices``, ``measures`` (``leader`` for Fig. 3,
        ``seed_sweep`` for Fig. 5), ``claims``, ``verdict`` (with its qualification),
        ``why``, ``runtime_s``; and ``fig1_exact_gradient``: Fig. 1 under the exact
        gradient ``∇L`` (a short run), where ``L`` decreases and the centroid stands
        still.
    """
    parts_run = select_parts(PARTS, only)
    check_seeds(seeds)
    start = time.perf_counter()
    out = output_dir(out_dir)
    results: dict[str, Any] = {}
    parts: dict[str, PartResult] = {}
    pngs: dict[str, list[Path]] = {}
    for part in parts_run:
        name = part.removeprefix("vs_")
        t0 = time.perf_counter()
        entry, run_ = _figure_entry(name, quick)
        if name == "fig1":
            exact = exact_gradient_run(quick=quick)
            results["fig1_exact_gradient"] = exact
            entry["claims"] += exact_gradient_claims(exact)
        v = verdict(entry["claims"])
        entry["verdict"] = _verdict_text(v, entry["note"], quick)
        entry["runtime_s"] = time.perf_counter() - t0
        results[name] = to_jsonable(entry)
        pngs[part] = []
        if out is not None:
            pngs[part].append(
                plot_figure(
                    name,
                    out / f"{part}.png",
                    params=run_["params"],
                    xs=run_["xs"],
                    dt=run_["dt"],
                    r=FIGURES[name].r,
                    verdict=entry["verdict"],
                    leader=entry.get("leader", {}).get("leader"),
                )
            )
            if name == "fig5" and not quick:
                pngs[part].append(write_fig5_gif(out / "vs_fig5.gif", run_["xs"]))
        note = (
            "quick run (not meaningful)" if quick else (entry["note"] if v == "reproduced" else "")
        )
        parts[part] = PartResult(
            name=part,
            title=TITLES[name],
            verdict=v,
            claims=results[name]["claims"],
            note=note,
            elapsed_s=time.perf_counter() - t0,
        )
    results["runtime_s"] = time.perf_counter() - start
    results["quick"] = quick
    results = to_jsonable(results)
    files = [f for fs in pngs.values() for f in fs]
    if out is not None:
        results = _merge_previous(out / _JSON, results)
        json_path = write_json(out / _JSON, results)
        files.append(json_path)
        parts = {k: replace(p, files=(*pngs[k], json_path)) for k, p in parts.items()}
    return finish(
        NAME,
        TITLE,
        quick=quick,
        setup={"figures": {k: asdict(s) for k, s in FIGURES.items()}, "quick": quick},
        parts=parts,
        data=results,
        files=files,
        out=out,
        order=PARTS,
        started=start,
    )
