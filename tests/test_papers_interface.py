"""Every registered paper has the same interface, writes its files, and states claims.

Also: the reproductions import the physics and the metrics, never the environments,
the agents or the trainers, and matplotlib only inside functions.
"""

from __future__ import annotations

import ast
import inspect
import json
from pathlib import Path

import pytest

import swarm_envs.papers as papers
from swarm_envs.papers import PAPERS, PaperResult, load
from swarm_envs.papers.claims import CLAIM_KEYS, VERDICTS
from swarm_envs.papers.cli import all_parts, main

NAMES = list(PAPERS)
PAPERS_DIR = Path(papers.__file__).parent


def _signature(name: str) -> list[tuple[str, object, object]]:
    params = inspect.signature(load(name).run).parameters.values()
    return [(p.name, p.kind, p.default) for p in params]


def test_registry_order_and_folders():
    assert NAMES == ["mabrouk_mcinnes", "naterop_zone", "naterop_piecewise", "vanualailai_sharma"]
    assert PAPERS["mabrouk_mcinnes"].folder == ""
    assert all(PAPERS[n].folder == n for n in NAMES[1:])
    with pytest.raises(KeyError, match="unknown paper"):
        load("nope")


@pytest.mark.parametrize("name", NAMES)
def test_same_interface(name: str):
    module = load(name)
    assert module.NAME == name
    assert isinstance(module.TITLE, str) and module.TITLE
    assert isinstance(module.PARTS, tuple) and module.PARTS
    assert all(isinstance(p, str) and p for p in module.PARTS)
    assert _signature(name) == _signature(NAMES[0])
    assert [n for n, _, _ in _signature(name)] == ["out_dir", "quick", "seeds", "only"]
    assert inspect.signature(module.run).parameters["out_dir"].default is None


def test_part_names_unique_across_papers():
    parts = all_parts()
    assert len(parts) == len(set(parts))


@pytest.mark.parametrize("name", NAMES)
def test_bad_arguments_raise_before_running(name: str, tmp_path: Path):
    module = load(name)
    with pytest.raises(ValueError, match="unknown part"):
        module.run(tmp_path, quick=True, only=["no_such_part"])
    with pytest.raises(ValueError, match="seeds"):
        module.run(tmp_path, quick=True, seeds=0)
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("name", NAMES)
def test_quick_run_writes_its_outputs(name: str, tmp_path: Path):
    """A quick run of the paper's last part (all of it for one-part papers)."""
    module = load(name)
    part = module.PARTS[-1]
    result = module.run(tmp_path, quick=True, only=[part])
    assert isinstance(result, PaperResult)
    assert result.name == name and result.title == module.TITLE and result.quick
    assert list(result.parts) == [part]
    assert result.verdicts[part] in VERDICTS
    entry = result.parts[part]
    assert entry.claims and any(c["paper_form"] for c in entry.claims)
    for claim in entry.claims:
        assert set(CLAIM_KEYS) <= set(claim)
        assert isinstance(claim["holds"], bool)
    assert entry.files and all(f in result.files for f in entry.files)
    assert any(f.suffix == ".png" for f in entry.files)
    assert any(f.suffix == ".json" for f in entry.files)
    for f in result.files:
        assert f.parent == tmp_path and f.is_file() and f.stat().st_size > 0, f
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["name"] == name and summary["mode"] == "quick"
    assert list(summary["figures"]) == [part]
    assert summary["figures"][part]["verdict"] == result.verdicts[part]
    assert sorted(summary["figures"][part]["files"]) == sorted(f.name for f in entry.files)
    # the result reads as the paper's JSON document
    assert len(result) > 0 and dict(result) == result.data


def test_run_without_out_dir_writes_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    monkeypatch.chdir(tmp_path)
    result = load("naterop_zone").run(quick=True)
    assert result.files == () and not any(tmp_path.iterdir())
    assert result.parts["zone_table3"].verdict in VERDICTS


def test_a_second_part_keeps_the_first_in_summary_and_json(tmp_path: Path):
    module = load("vanualailai_sharma")
    module.run(tmp_path, quick=True, only=["vs_fig5"])
    module.run(tmp_path, quick=True, only=["vs_fig2"])
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert list(summary["figures"]) == ["vs_fig2", "vs_fig5"]
    doc = json.loads((tmp_path / "vanualailai_sharma.json").read_text())
    assert {"fig2", "fig5"} <= set(doc) and "fig1" not in doc


def test_cli_only_runs_the_papers_that_have_the_parts(tmp_path: Path):
    assert main(["--quick", "--out", str(tmp_path), "--only", "zone_table3"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["naterop_zone"]
    assert (tmp_path / "naterop_zone" / "summary.json").is_file()
    with pytest.raises(SystemExit) as err:
        main(["--quick", "--out", str(tmp_path), "--papers", "naterop_zone", "--only", "fig9"])
    assert err.value.code == 2


def _imports(path: Path) -> tuple[set[str], set[str]]:
    """Modules imported anywhere in ``path``, and those imported at module level."""
    tree = ast.parse(path.read_text())
    anywhere, top = set(), set()
    for node in ast.walk(tree):
        names = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [node.module, *(f"{node.module}.{a.name}" for a in node.names)]
        anywhere.update(names)
        if node in tree.body:
            top.update(names)
    return anywhere, top


@pytest.mark.parametrize(
    "path", sorted(PAPERS_DIR.rglob("*.py")), ids=lambda p: str(p.relative_to(PAPERS_DIR))
)
def test_physics_and_metrics_only(path: Path):
    anywhere, top = _imports(path)
    allowed = (
        "swarm_envs.physics",
        "swarm_envs.metrics",
        "swarm_envs.papers",
        "swarm_envs.render",
        "swarm_envs._runtime",
    )
    ours = {m for m in anywhere if m == "swarm_envs" or m.startswith("swarm_envs.")}
    assert all(m == "swarm_envs" or m.startswith(allowed) for m in ours), ours
    assert not any(
        m.split(".")[0] in ("agents", "train", "gymnasium", "pettingzoo") for m in anywhere
    )
    assert not any(m.split(".")[0] == "matplotlib" for m in top), "import matplotlib lazily"
