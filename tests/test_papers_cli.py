"""``swarm-reproduce`` runs the other seed papers too (``--papers``)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from swarm_envs.papers import cli


def test_other_papers_write_into_their_folders(tmp_path: Path):
    code = cli.main(
        ["--out", str(tmp_path), "--quick", "--papers", "naterop_zone,naterop_piecewise"]
    )
    assert code == 0
    zone = json.loads((tmp_path / "naterop_zone" / "zone_table3.json").read_text())
    assert set(zone["verdict"]) == {"swarm", "torus", "dynamic parallel", "highly parallel"}
    assert (tmp_path / "naterop_piecewise" / "piecewise_dispersal.png").is_file()
    assert not (tmp_path / "fig1.json").exists()  # Mabrouk & McInnes was not asked for


def test_unknown_paper_exits_with_status_2(tmp_path: Path, capsys):
    with pytest.raises(SystemExit) as info:
        cli.main(["--out", str(tmp_path), "--papers", "naterop_zonee"])
    assert info.value.code == 2
    assert "unknown paper name(s) naterop_zonee" in capsys.readouterr().err


def test_only_selects_mabrouk_figures_alone(tmp_path: Path):
    assert cli.main(["--out", str(tmp_path), "--quick", "--only", "fig9"]) == 0
    assert (tmp_path / "fig9.json").is_file()
    assert not (tmp_path / "naterop_zone").exists()


def test_an_occupied_out_needs_overwrite(tmp_path: Path, capsys):
    (tmp_path / "fig9.json").write_text("{}")
    with pytest.raises(SystemExit) as info:
        cli.main(["--out", str(tmp_path), "--quick", "--only", "fig9"])
    assert info.value.code == 2
    assert "already holds files" in capsys.readouterr().err
    assert (tmp_path / "fig9.json").read_text() == "{}"
    assert cli.main(["--out", str(tmp_path), "--quick", "--only", "fig9", "--overwrite"]) == 0
    assert (tmp_path / "fig9.json").read_text() != "{}"
