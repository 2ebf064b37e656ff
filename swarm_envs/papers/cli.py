"""``swarm-reproduce``: regenerate the reproduced figures as PNG, JSON and GIF.

Usage::

    swarm-reproduce [--out DIR] [--seeds K] [--quick] [--only fig1,fig9,...] [--docs-img [DIR]]

Writes ``DIR/<fig>.png`` and ``DIR/<fig>.json`` for every figure, ``DIR/fig11.gif``
and ``DIR/summary.json`` (the claims, verdicts and timings; a ``--only`` run updates
its figures' entries of an earlier summary made with the same setup), and prints a
table of the trends with the elapsed time per figure. ``--docs-img`` also copies the
PNGs and the GIF into ``docs/img`` (or the given folder). Exit status 2 for bad
arguments (an unknown figure name, ``--seeds 0``).

Figures (:data:`swarm_envs.papers.mabrouk_mcinnes.FIGURES`): ``fig1``, ``fig4_5``,
``fig6_8``, ``fig9``, ``fig10``, ``fig11``.

The other seed papers (``--papers``, all by default) write into ``DIR/<paper>/``:
``naterop_zone`` (Naterop et al. table 3, zone model), ``naterop_piecewise`` (their
force model's dispersal and the drag fix) and ``vanualailai_sharma`` (Figs. 1–5 of the
Lagrangian model). ``--only`` selects Mabrouk & McInnes figures and implies
``--papers mabrouk_mcinnes``.
"""

from __future__ import annotations

import argparse
import importlib
import inspect
import json
import shutil
import sys
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from swarm_envs.papers._io import to_jsonable
from swarm_envs.papers.mabrouk_mcinnes import (
    FIGURES,
    PAPER,
    RunSetup,
    write_fig11_gif,
)

__all__ = ["PAPERS", "main", "parse_only", "parse_papers", "run", "run_other_paper"]

#: The other seed papers: name → module whose ``run(out_dir, *, quick[, seeds])``
#: reproduces it and returns a JSON-ready dict with a ``verdict``.
OTHER_PAPERS = {
    "naterop_zone": "swarm_envs.papers.naterop.zone",
    "naterop_piecewise": "swarm_envs.papers.naterop.piecewise",
    "vanualailai_sharma": "swarm_envs.papers.vanualailai_sharma",
}
PAPERS = ("mabrouk_mcinnes", *OTHER_PAPERS)


def parse_papers(text: str | None) -> list[str]:
    """Paper names from a comma-separated list (``None``: all, in order).

    >>> parse_papers("vanualailai_sharma,mabrouk_mcinnes")
    ['mabrouk_mcinnes', 'vanualailai_sharma']
    """
    if text is None or not text.strip():
        return list(PAPERS)
    wanted = [w.strip() for w in text.split(",") if w.strip()]
    unknown = [w for w in wanted if w not in PAPERS]
    if unknown:
        raise ValueError(f"unknown paper name(s) {', '.join(unknown)}; known: {', '.join(PAPERS)}")
    return [name for name in PAPERS if name in wanted]


def run_other_paper(
    name: str, out: str | Path, *, quick: bool = False, seeds: int | None = None, log: Any = print
) -> dict[str, Any]:
    """Run one of :data:`OTHER_PAPERS` into ``out/<name>/`` and log its verdict."""
    module = importlib.import_module(OTHER_PAPERS[name])
    kwargs: dict[str, Any] = {"quick": quick}
    if seeds is not None and "seeds" in inspect.signature(module.run).parameters:
        kwargs["seeds"] = seeds
    t0 = time.perf_counter()
    result = module.run(Path(out) / name, **kwargs)
    verdict = result.get("verdict")
    if verdict is None:  # per-figure verdicts (Vanualailai & Sharma)
        verdict = {
            k: v["verdict"] for k, v in result.items() if isinstance(v, dict) and "verdict" in v
        }
    log(f"  {name:18s} {time.perf_counter() - t0:6.1f} s  {json.dumps(to_jsonable(verdict))[:300]}")
    return result


def parse_only(text: str | None) -> list[str]:
    """Figure names from a comma-separated list (``None`` or empty: all, in order).

    Raises:
        ValueError: naming the unknown figure(s) and the known ones.

    >>> parse_only("fig9, fig1")
    ['fig1', 'fig9']
    """
    if text is None or not text.strip():
        return list(FIGURES)
    wanted = [w.strip() for w in text.split(",") if w.strip()]
    unknown = [w for w in wanted if w not in FIGURES]
    if unknown:
        raise ValueError(
            f"unknown figure name(s) {', '.join(unknown)}; known: {', '.join(FIGURES)}"
        )
    return [name for name in FIGURES if name in wanted]


def _format_claim(claim: dict[str, Any]) -> str:
    mark = "yes" if claim["holds"] else "NO "
    form = "paper" if claim["paper_form"] else "extra"
    return (
        f"    [{mark}] ({form}) {claim['claim']} — {claim['measure']}, {claim['statistic']}: "
        f"expected {claim['expected']}, observed {claim['observed']}"
    )


def run(
    out: str | Path = "reproductions",
    *,
    figures: Sequence[str] | None = None,
    seeds: int | None = None,
    quick: bool = False,
    docs_img: str | Path | None = None,
    log: Any = print,
) -> dict[str, Any]:
    """Compute, plot and write the figures; return the summary (also written as JSON)."""
    names = list(FIGURES) if figures is None else list(figures)
    for name in names:
        if name not in FIGURES:
            raise ValueError(f"unknown figure name {name!r}; known: {', '.join(FIGURES)}")
    setup = RunSetup.quick() if quick else RunSetup()
    if seeds is not None:
        setup = replace(setup, seeds=seeds)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    img = None if docs_img is None else Path(docs_img)
    if img is not None:
        img.mkdir(parents=True, exist_ok=True)
    summary: dict[str, Any] = {
        "paper": PAPER,
        "mode": "quick" if quick else "full",
        "setup": setup.as_dict(),
        "figures": {},
    }
    start_all = time.perf_counter()
    log(f"swarm-reproduce: {len(names)} figure(s), {setup.seeds} seeds, writing to {out}/")
    for name in names:
        spec = FIGURES[name]
        t0 = time.perf_counter()
        result = spec.compute(setup, quick)
        files = []
        json_path = out / f"{name}.json"
        json_path.write_text(json.dumps(to_jsonable(result), indent=1, ensure_ascii=False))
        files.append(json_path)
        files.append(spec.plot(result, out / f"{name}.png"))
        if name == "fig11":
            files.append(
                write_fig11_gif(
                    out / "fig11.gif",
                    setup=setup,
                    duration=result["setup"]["duration"],
                    frames=20 if quick else 64,
                    size=(120, 120) if quick else (300, 300),
                )
            )
        if img is not None:
            for f in files:
                if f.suffix in (".png", ".gif"):
                    shutil.copyfile(f, img / f.name)
        elapsed = time.perf_counter() - t0
        summary["figures"][name] = {
            "title": result["title"],
            "verdict": result["verdict"],
            "claims": result["claims"],
            "elapsed_s": elapsed,
            "files": [f.name for f in files],
        }
        log(f"  {name:7s} {elapsed:6.1f} s  {result['verdict']:18s} {spec.title}")
        for claim in result["claims"]:
            log(_format_claim(claim))
    total = time.perf_counter() - start_all
    summary["total_elapsed_s"] = total
    summary = _merge_previous(out / "summary.json", summary)
    (out / "summary.json").write_text(
        json.dumps(to_jsonable(summary), indent=1, ensure_ascii=False)
    )
    log(f"total {total:.1f} s; summary in {out / 'summary.json'}")
    return summary


def _merge_previous(path: Path, summary: dict[str, Any]) -> dict[str, Any]:
    """Keep the other figures of an earlier ``summary.json`` made with the same setup.

    So that ``--only fig9`` after a full run updates fig9's entry instead of dropping
    the rest. ``total_elapsed_s`` stays this run's time.
    """
    try:
        previous = json.loads(path.read_text())
    except (OSError, ValueError):
        return summary
    same = previous.get("mode") == summary["mode"] and previous.get("setup") == to_jsonable(
        summary["setup"]
    )
    if not same or not isinstance(previous.get("figures"), dict):
        return summary
    figures = {k: v for k, v in previous["figures"].items() if k in FIGURES}
    figures.update(summary["figures"])
    ordered = {name: figures[name] for name in FIGURES if name in figures}
    return summary | {"figures": ordered}


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {value}")
    return value


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="swarm-reproduce",
        description=(
            "Regenerate Mabrouk & McInnes' Figs. 1, 4-5, 6-8, 9, 10 and 11 "
            "(PNG + JSON, Fig. 11 also as GIF) and the other seed papers' reproductions "
            "(Naterop et al. zone and force models, Vanualailai & Sharma), and print the "
            "verdicts."
        ),
    )
    parser.add_argument(
        "--out", default="reproductions", help="output folder (default: %(default)s)"
    )
    parser.add_argument(
        "--seeds",
        type=_positive_int,
        default=None,
        help="random initial conditions averaged over (default: 8; quick: 2)",
    )
    parser.add_argument("--quick", action="store_true", help="tiny sizes, for tests (seconds)")
    parser.add_argument(
        "--only",
        default=None,
        metavar="FIGS",
        help=f"comma-separated subset of: {', '.join(FIGURES)}",
    )
    parser.add_argument(
        "--papers",
        default=None,
        metavar="PAPERS",
        help=f"comma-separated subset of: {', '.join(PAPERS)} (default: all)",
    )
    parser.add_argument(
        "--docs-img",
        nargs="?",
        const="docs/img",
        default=None,
        metavar="DIR",
        help="also copy the PNGs and the GIF into DIR (default when given: docs/img)",
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Console entry point; returns the exit status (0, or 2 for bad arguments)."""
    parser = _parser()
    args = parser.parse_args(argv)
    try:
        figures = parse_only(args.only)
        papers = ["mabrouk_mcinnes"] if args.only else parse_papers(args.papers)
    except ValueError as err:
        parser.error(str(err))  # exits with status 2
    if "mabrouk_mcinnes" in papers:
        run(args.out, figures=figures, seeds=args.seeds, quick=args.quick, docs_img=args.docs_img)
    for name in papers:
        if name in OTHER_PAPERS:
            run_other_paper(name, args.out, quick=args.quick, seeds=args.seeds)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
