"""The common interface of the reproductions.

Every paper module (the registry is :data:`swarm_envs.papers.PAPERS`) has

``NAME``
    its registry name, e.g. ``"mabrouk_mcinnes"``.
``TITLE``
    the paper (authors, title, the sections reproduced).
``PARTS``
    the figures or tables it reproduces, named after the files they write (unique
    across papers, so that ``swarm-reproduce --only`` can name them).
``run(out_dir=None, *, quick=False, seeds=None, only=None) -> PaperResult``
    computes the selected parts (``only``: names of ``PARTS``, ``None`` for all) and,
    with an ``out_dir``, writes their files there (PNG, JSON, GIF) and
    ``summary.json``. ``quick`` runs tiny sizes for tests (the verdicts are then not
    meaningful). ``seeds`` is the number of random initial conditions averaged over
    (``None``: the paper's default; papers that show single seeded runs ignore it).

:class:`PaperResult` holds the verdict and claims of every part
(:mod:`swarm_envs.papers.claims`) and the paper's JSON document; it also reads as
that document (``result["key"]`` is ``result.data["key"]``).
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from swarm_envs.papers._io import to_jsonable, write_json
from swarm_envs.papers.claims import VERDICTS, Claim

__all__ = [
    "Paper",
    "PaperResult",
    "PartResult",
    "check_seeds",
    "finish",
    "output_dir",
    "select_parts",
    "write_summary",
]


class Paper(Protocol):
    """What every paper module provides (the module docstring)."""

    NAME: str
    TITLE: str
    PARTS: tuple[str, ...]

    def run(
        self,
        out_dir: str | Path | None = None,
        *,
        quick: bool = False,
        seeds: int | None = None,
        only: Sequence[str] | None = None,
    ) -> PaperResult: ...


@dataclass(frozen=True)
class PartResult:
    """One reproduced figure or table.

    Attributes:
        name: its name in the paper module's ``PARTS``.
        title: what it shows.
        verdict: one of :data:`~swarm_envs.papers.claims.VERDICTS`, from ``claims``.
        claims: the claims tested (:mod:`swarm_envs.papers.claims`).
        note: a qualification of the verdict (empty if none).
        elapsed_s: wall time to compute and write it.
        files: the files written for it (empty without an output folder).
    """

    name: str
    title: str
    verdict: str
    claims: list[Claim]
    note: str = ""
    elapsed_s: float = 0.0
    files: tuple[Path, ...] = ()

    def __post_init__(self) -> None:
        if self.verdict not in VERDICTS:
            raise ValueError(f"PartResult.verdict must be one of {VERDICTS}, got {self.verdict!r}")

    def as_dict(self) -> dict[str, Any]:
        """The entry of ``summary.json``."""
        return {
            "title": self.title,
            "verdict": self.verdict,
            "note": self.note,
            "claims": self.claims,
            "elapsed_s": self.elapsed_s,
            "files": [f.name for f in self.files],
        }


@dataclass(frozen=True, eq=False)
class PaperResult(Mapping[str, Any]):
    """What a paper module's ``run`` returns.

    Attributes:
        name, title: the module's ``NAME`` and ``TITLE``.
        quick: whether this was a quick (test-sized) run.
        setup: the choices of the run (JSON-ready), as written to ``summary.json``.
        parts: the parts run, in the order of ``PARTS``.
        data: the paper's JSON-ready document (what its JSON files hold); the result
            reads as this mapping.
        elapsed_s: wall time of the whole run.
        files: every file written, ``summary.json`` included.
    """

    name: str
    title: str
    quick: bool
    setup: dict[str, Any]
    parts: dict[str, PartResult]
    data: dict[str, Any] = field(repr=False)
    elapsed_s: float = 0.0
    files: tuple[Path, ...] = ()

    def __getitem__(self, key: str) -> Any:
        return self.data[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self.data)

    def __len__(self) -> int:
        return len(self.data)

    @property
    def verdicts(self) -> dict[str, str]:
        """Part name → verdict."""
        return {name: part.verdict for name, part in self.parts.items()}

    def summary(self) -> dict[str, Any]:
        """The ``summary.json`` document (JSON-ready)."""
        return to_jsonable(
            {
                "paper": self.title,
                "name": self.name,
                "mode": "quick" if self.quick else "full",
                "setup": self.setup,
                "figures": {name: part.as_dict() for name, part in self.parts.items()},
                "total_elapsed_s": self.elapsed_s,
            }
        )


def check_seeds(seeds: int | None) -> int | None:
    """``seeds`` unchanged if ``None`` or an integer >= 1, else ``ValueError``.

    >>> check_seeds(None), check_seeds(3)
    (None, 3)
    """
    if seeds is None:
        return None
    if isinstance(seeds, bool) or not isinstance(seeds, (int, np.integer)) or seeds < 1:
        raise ValueError(f"seeds must be an integer >= 1 or None, got {seeds!r}")
    return int(seeds)


def select_parts(parts: Sequence[str], only: Sequence[str] | None) -> list[str]:
    """The parts to run, in the order of ``parts``: all for ``None``, else ``only``.

    Raises:
        ValueError: for an unknown name or an empty selection.

    >>> select_parts(("fig1", "fig9"), ["fig9"])
    ['fig9']
    """
    if only is None:
        return list(parts)
    if isinstance(only, str):
        only = [only]
    unknown = [name for name in only if name not in parts]
    if unknown:
        raise ValueError(f"unknown part(s) {', '.join(unknown)}; known: {', '.join(parts)}")
    chosen = [name for name in parts if name in only]
    if not chosen:
        raise ValueError(f"no part selected; known: {', '.join(parts)}")
    return chosen


def output_dir(out_dir: str | Path | None) -> Path | None:
    """``out_dir`` as a created folder, or ``None``."""
    if out_dir is None:
        return None
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    return out


def write_summary(result: PaperResult, path: str | Path, order: Sequence[str]) -> Path:
    """Write ``result.summary()`` to ``path``, keeping an earlier summary's other parts.

    When ``path`` holds a summary of the same mode and setup, its entries for parts
    this run did not compute are kept (so that a run of one figure after a full run
    updates that figure instead of dropping the rest), in the order of ``order``.
    ``total_elapsed_s`` stays this run's time.
    """
    path = Path(path)
    summary = result.summary()
    try:
        previous = json.loads(path.read_text())
    except (OSError, ValueError):
        previous = None
    if (
        isinstance(previous, dict)
        and previous.get("mode") == summary["mode"]
        and previous.get("setup") == summary["setup"]
        and isinstance(previous.get("figures"), dict)
    ):
        merged = {k: v for k, v in previous["figures"].items() if k in order}
        merged.update(summary["figures"])
        summary["figures"] = {name: merged[name] for name in order if name in merged}
    return write_json(path, summary)


def finish(
    name: str,
    title: str,
    *,
    quick: bool,
    setup: dict[str, Any],
    parts: dict[str, PartResult],
    data: dict[str, Any],
    files: Sequence[Path],
    out: Path | None,
    order: Sequence[str],
    started: float,
) -> PaperResult:
    """The :class:`PaperResult` of a run started at ``started`` (``time.perf_counter``).

    With an output folder ``out``, also writes ``out/summary.json``
    (:func:`write_summary`, parts in the order of ``order``).
    """
    summary_path = None if out is None else out / "summary.json"
    result = PaperResult(
        name=name,
        title=title,
        quick=quick,
        setup=to_jsonable(setup),
        parts=parts,
        data=data,
        elapsed_s=time.perf_counter() - started,
        files=(*files, summary_path) if summary_path is not None else tuple(files),
    )
    if summary_path is not None:
        write_summary(result, summary_path, order)
    return result
