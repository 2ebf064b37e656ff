"""``swarm-reproduce``: regenerate the reproduced figures and tables as PNG, JSON and GIF.

Usage::

    swarm-reproduce [--out DIR] [--overwrite] [--seeds K] [--quick] [--papers P,...]
                    [--only PART,...] [--docs-img [DIR]]

Runs every paper of :data:`swarm_envs.papers.PAPERS` (``--papers``: a subset) through
its ``run`` (:mod:`swarm_envs.papers.result`), each into its registry folder under
``DIR``: Mabrouk & McInnes into ``DIR/`` itself (``<fig>.png``, ``<fig>.json``,
``fig11.gif``), the others into ``DIR/<paper>/``. Every paper folder gets a
``summary.json`` (claims, verdicts, timings; a ``--only`` run updates its parts'
entries of an earlier summary made with the same setup). Prints the verdict and the
claims of every part and the elapsed times. ``--only`` names parts (figures or tables,
as their files are named: ``fig9``, ``zone_table3``, ``vs_fig5`` …) and runs only the
papers that have them. ``--docs-img`` also copies the PNGs and GIFs into
``docs/img`` (or the given folder). As every tool of the project, it refuses a ``DIR``
that already holds files unless ``--overwrite`` is given; then the run writes over the
earlier files (a ``--only`` run into an earlier reproduction needs it). Exit status 2
for bad arguments (an unknown paper or part name, ``--seeds 0``, an occupied ``DIR``).
"""

from __future__ import annotations

import argparse
import shutil
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from swarm_envs._runtime.allocator import tune_allocator
from swarm_envs.papers import PAPERS
from swarm_envs.papers.claims import format_claim, tally
from swarm_envs.papers.result import PaperResult

__all__ = ["all_parts", "main", "parse_only", "parse_papers", "run"]


def parse_papers(text: str | None) -> list[str]:
    """Paper names from a comma-separated list (``None`` or empty: all, in order).

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


def all_parts(papers: Sequence[str] | None = None) -> list[str]:
    """The parts of the given papers (``None``: all), in registry order.

    >>> all_parts(["naterop_zone", "naterop_piecewise"])
    ['zone_table3', 'piecewise_dispersal']
    """
    names = list(PAPERS) if papers is None else list(papers)
    return [part for name in names for part in PAPERS[name].load().PARTS]


def parse_only(text: str | None, known: Sequence[str] | None = None) -> list[str]:
    """Part names from a comma-separated list (``None`` or empty: all ``known``), in order.

    ``known`` defaults to :func:`all_parts`.

    Raises:
        ValueError: naming the unknown part(s) and the known ones.

    >>> parse_only("fig9, fig1")
    ['fig1', 'fig9']
    """
    known = all_parts() if known is None else list(known)
    if text is None or not text.strip():
        return known
    wanted = [w.strip() for w in text.split(",") if w.strip()]
    unknown = [w for w in wanted if w not in known]
    if unknown:
        raise ValueError(f"unknown part name(s) {', '.join(unknown)}; known: {', '.join(known)}")
    return [name for name in known if name in wanted]


def _log_result(result: PaperResult, log: Callable[[str], None]) -> None:
    for name, part in result.parts.items():
        held, counted = tally(part.claims)
        note = f" ({part.note})" if part.note else ""
        log(
            f"  {name:12s} {part.elapsed_s:6.1f} s  {part.verdict:18s} "
            f"[{held}/{counted}] {part.title}{note}"
        )
        for claim in part.claims:
            log(f"    {format_claim(claim)}")


def run(
    out: str | Path = "reproductions",
    *,
    papers: Sequence[str] | None = None,
    only: Sequence[str] | None = None,
    seeds: int | None = None,
    quick: bool = False,
    docs_img: str | Path | None = None,
    log: Callable[[str], None] = print,
) -> dict[str, PaperResult]:
    """Run the papers (``None``: all) into their folders under ``out``; return the results.

    ``only`` selects parts (``None``: all); a paper with none of them is skipped.
    ``docs_img`` also receives a copy of every PNG and GIF written.
    """
    names = list(PAPERS) if papers is None else list(papers)
    out = Path(out)
    img = None if docs_img is None else Path(docs_img)
    if img is not None:
        img.mkdir(parents=True, exist_ok=True)
    results: dict[str, PaperResult] = {}
    start = time.perf_counter()
    log(f"swarm-reproduce: writing to {out}/" + (" (quick)" if quick else ""))
    for name in names:
        entry = PAPERS[name]
        paper = entry.load()
        selected = None if only is None else [p for p in paper.PARTS if p in only]
        if selected == []:
            continue
        folder = out / entry.folder if entry.folder else out
        log(f"{name} -> {folder}/: {paper.TITLE}")
        result = paper.run(folder, quick=quick, seeds=seeds, only=selected)
        _log_result(result, log)
        log(f"  {name} took {result.elapsed_s:.1f} s")
        if img is not None:
            for f in result.files:
                if f.suffix in (".png", ".gif"):
                    shutil.copyfile(f, img / f.name)
        results[name] = result
    log(f"total {time.perf_counter() - start:.1f} s")
    return results


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
            "Regenerate the seed papers' reproductions (PNG + JSON, some GIFs): Mabrouk & "
            "McInnes' Figs. 1, 4-5, 6-8, 9, 10 and 11, Naterop et al.'s zone and force "
            "models, Vanualailai & Sharma's Figs. 1-5; print the verdicts."
        ),
    )
    parser.add_argument(
        "--out", default="reproductions", help="output folder (default: %(default)s)"
    )
    parser.add_argument(
        "--seeds",
        type=_positive_int,
        default=None,
        help="random initial conditions averaged over (default: each paper's own)",
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="--out may hold an earlier reproduction: write over its files",
    )
    parser.add_argument("--quick", action="store_true", help="tiny sizes, for tests (seconds)")
    parser.add_argument(
        "--only",
        default=None,
        metavar="PARTS",
        help=f"comma-separated subset of: {', '.join(all_parts())}",
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
        help="also copy the PNGs and GIFs into DIR (default when given: docs/img)",
    )
    return parser


def _check_out(out: Path, *, overwrite: bool) -> None:
    """Refuse an ``--out`` that is a file, or a folder with files unless ``overwrite``."""
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} is a file; give a folder")
    if not overwrite and out.is_dir() and any(out.iterdir()):
        raise ValueError(
            f"--out {out} already holds files; choose a new folder, or add --overwrite to "
            "write over the earlier reproduction there"
        )


def main(argv: Sequence[str] | None = None) -> int:
    """Console entry point; returns the exit status (0, or 2 for bad arguments)."""
    parser = _parser()
    args = parser.parse_args(argv)
    tune_allocator()  # a long-running tool: keep freed heap for reuse
    try:
        papers = parse_papers(args.papers)
        only = None if args.only is None else parse_only(args.only, all_parts(papers))
        _check_out(Path(args.out), overwrite=args.overwrite)
    except ValueError as err:
        parser.error(str(err))  # exits with status 2
    run(
        args.out,
        papers=papers,
        only=only,
        seeds=args.seeds,
        quick=args.quick,
        docs_img=args.docs_img,
    )
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
