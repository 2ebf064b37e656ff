"""Reproductions of the seed papers' figures and tables, one interface for all.

Physics and metrics only: nothing here imports the environments, the agents or the
trainers. Every paper module has ``NAME``, ``TITLE``, ``PARTS`` and
``run(out_dir=None, *, quick=False, seeds=None, only=None) -> PaperResult``
(:mod:`swarm_envs.papers.result`); the claims and verdicts are built with
:mod:`swarm_envs.papers.claims`. The console script ``swarm-reproduce``
(:mod:`swarm_envs.papers.cli`) and ``make reproduce`` run every paper of
:data:`PAPERS` and write PNG, JSON and GIF files.

- :mod:`swarm_envs.papers.mabrouk_mcinnes`: Mabrouk & McInnes, *Social potential model
  to simulate emergent behaviour for swarm robots*, Figs. 1, 4–5, 6–8, 9, 10 and 11.
- :mod:`swarm_envs.papers.naterop.zone`: Naterop, Petrides & Prasad, table 3 (zone
  model).
- :mod:`swarm_envs.papers.naterop.piecewise`: the same report's force model, its
  dispersal (§5.1) and the drag fix.
- :mod:`swarm_envs.papers.vanualailai_sharma`: Vanualailai & Sharma, *A
  Lagrangian-based swarming behavior*, Figs. 1–5.

>>> sorted(PAPERS) == sorted(["mabrouk_mcinnes", "naterop_zone", "naterop_piecewise",
...                           "vanualailai_sharma"])
True
>>> load("naterop_zone").PARTS
('zone_table3',)
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import cast

from swarm_envs.papers.claims import VERDICTS, classify_trend, verdict
from swarm_envs.papers.result import Paper, PaperResult, PartResult

__all__ = [
    "PAPERS",
    "VERDICTS",
    "Paper",
    "PaperResult",
    "PartResult",
    "Registered",
    "classify_trend",
    "load",
    "verdict",
]


@dataclass(frozen=True)
class Registered:
    """A paper of the registry: its module and the folder the CLI writes it to.

    ``folder`` is relative to ``swarm-reproduce --out``; ``""`` is that folder itself.
    """

    name: str
    module: str
    folder: str

    def load(self) -> Paper:
        """The paper module (imported on first use)."""
        return cast(Paper, importlib.import_module(self.module))


#: The reproduced papers, in the order the CLI runs them.
PAPERS: dict[str, Registered] = {
    entry.name: entry
    for entry in (
        Registered("mabrouk_mcinnes", "swarm_envs.papers.mabrouk_mcinnes", ""),
        Registered("naterop_zone", "swarm_envs.papers.naterop.zone", "naterop_zone"),
        Registered("naterop_piecewise", "swarm_envs.papers.naterop.piecewise", "naterop_piecewise"),
        Registered(
            "vanualailai_sharma", "swarm_envs.papers.vanualailai_sharma", "vanualailai_sharma"
        ),
    )
}


def load(name: str) -> Paper:
    """The module of the registered paper ``name`` (``KeyError`` naming the known ones)."""
    if name not in PAPERS:
        raise KeyError(f"unknown paper {name!r}; known: {', '.join(PAPERS)}")
    return PAPERS[name].load()
