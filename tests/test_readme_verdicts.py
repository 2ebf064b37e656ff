"""The README's table of reproduction verdicts says what ``make reproduce`` prints.

:data:`FULL_RUN_VERDICTS` holds the verdict of every part in a full (default) run. The
fast test compares the README's table with it; the slow tests run the papers at full
size and compare their verdicts with it (Mabrouk & McInnes: tests/test_papers.py).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from swarm_envs.papers import PAPERS
from swarm_envs.papers.claims import VERDICTS
from swarm_envs.papers.cli import main

ROOT = Path(__file__).resolve().parents[1]

#: part -> verdict of a full ``swarm-reproduce`` run (each paper's default seeds).
FULL_RUN_VERDICTS = {
    "fig1": "reproduced",
    "fig4_5": "reproduced",
    "fig6_8": "partly reproduced",
    "fig9": "reproduced",
    "fig10": "reproduced",
    "fig11": "partly reproduced",
    "zone_table3": "partly reproduced",
    "piecewise_dispersal": "reproduced",
    "vs_fig1": "reproduced",
    "vs_fig2": "reproduced",
    "vs_fig3": "partly reproduced",
    "vs_fig4": "reproduced",
    "vs_fig5": "reproduced",
}
#: Fig. 11's second verdict, with self-propulsion (``self_propelled_verdict``).
FIG11_SELF_PROPELLED = "reproduced"


def readme_verdicts(text: str) -> dict[str, str]:
    """part -> verdict from the README's table whose header names the verdicts."""
    header = "| paper | " + " | ".join(VERDICTS) + " |"
    assert header in text, f"README has no verdict table headed {header!r}"
    table = text[text.index(header) :].split("\n\n")[0].splitlines()[2:]
    out: dict[str, str] = {}
    for row in table:
        cells = [c.strip() for c in row.strip().strip("|").split("|")][1:]
        assert len(cells) == len(VERDICTS), f"README verdict row with other columns: {row}"
        for verdict, cell in zip(VERDICTS, cells, strict=True):
            for part in re.findall(r"`(\w+)`", re.sub(r"\(.*?\)", "", cell)):
                assert part not in out, f"README lists {part} twice"
                out[part] = verdict
    return out


def test_every_part_of_every_paper_has_a_recorded_verdict():
    parts = [part for entry in PAPERS.values() for part in entry.load().PARTS]
    assert sorted(parts) == sorted(FULL_RUN_VERDICTS)
    assert set(FULL_RUN_VERDICTS.values()) <= set(VERDICTS)


def test_readme_verdicts_are_the_full_runs():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert readme_verdicts(text) == FULL_RUN_VERDICTS
    assert f"with self-propulsion: {FIG11_SELF_PROPELLED}" in text


@pytest.mark.slow
def test_full_runs_of_the_other_papers_give_the_recorded_verdicts(tmp_path: Path):
    papers = [name for name in PAPERS if name != "mabrouk_mcinnes"]
    assert main(["--out", str(tmp_path), "--papers", ",".join(papers)]) == 0
    for name in papers:
        doc = json.loads((tmp_path / PAPERS[name].folder / "summary.json").read_text())
        for part, entry in doc["figures"].items():
            assert entry["verdict"] == FULL_RUN_VERDICTS[part], (name, part)
