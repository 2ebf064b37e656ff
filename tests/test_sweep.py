"""Parameter sweeps (train.sweep, swarm-sweep): strict configs, the local engine without Ray,
and (with the ``distributed`` extra) a Ray Tune sweep that matches the local numbers."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from swarm_envs.config import CONFIG_ROOT
from train import cli_sweep
from train.sweep import (
    RELAX_STATISTICS,
    SweepConfig,
    load_sweep_config,
    measure_columns,
    run_local,
    run_sweep,
    run_trial,
    summarize_rows,
    sweep_config_from_mapping,
    trial_seed,
    write_outputs,
)

SWEEP_CONFIGS = sorted((CONFIG_ROOT / "sweeps").glob("*.yaml"))

#: A 2 × 2 grid over a short simulation: milliseconds per trial.
SMALL = {
    "task": "relax",
    "grid": {"l_r": [0.2, 0.4], "C_r": [1.2, 2.0]},
    "seeds": 2,
    "relax": {"n_agents": 8, "duration": 1.0, "dt": 0.05, "samples": 5},
}

NAV = {
    "task": "navigate",
    "grid": {"C_g": [5.0, 30.0]},
    "seeds": [3],
    "navigate": {"env": {"n_agents": 3, "max_steps": 40, "n_neighbors": 2}},
}


def small(**kw) -> SweepConfig:
    return sweep_config_from_mapping({**SMALL, **kw})


# --------------------------------------------------------------------------- configs


def test_shipped_sweep_configs_validate():
    names = {p.stem for p in SWEEP_CONFIGS}
    assert {"quick", "fig9_fig10_large", "controller_gain"} <= names
    for path in SWEEP_CONFIGS:
        sc = load_sweep_config(path)
        assert len(sc.trial_specs()) == len(sc.points()) * len(sc.seeds)


def test_large_sweep_contains_the_paper_figures_as_row_and_column():
    from swarm_envs.papers.mabrouk_mcinnes import DEFAULT_C_RATIOS, DEFAULT_L_RATIOS

    sc = load_sweep_config(CONFIG_ROOT / "sweeps" / "fig9_fig10_large.yaml")
    assert sc.grid["l_r"] == DEFAULT_L_RATIOS and sc.grid["C_r"] == DEFAULT_C_RATIOS
    assert sc.relax.n_agents >= 10 * 30 and len(sc.seeds) >= 16


@pytest.mark.parametrize(
    ("data", "fragment"),
    [
        ({**SMALL, "seed": 3}, "unknown config key 'seed'"),
        ({**SMALL, "relax": {"n_agent": 3}}, "unknown config key 'relax.n_agent'"),
        ({**SMALL, "relax": {"physics": {"C_x": 1}}}, "unknown config key 'relax.physics.C_x'"),
        ({**SMALL, "task": "fly"}, "task must be one of ('relax', 'navigate')"),
        ({**SMALL, "grid": {}}, "grid must be a non-empty mapping"),
        ({**SMALL, "grid": {"l_x": [1.0]}}, "grid.l_x is not a parameter of the relax task"),
        ({**SMALL, "grid": {"samples": [1, 2]}}, "grid.samples is not a parameter"),
        ({**SMALL, "grid": {"l_r": 0.2}}, "grid.l_r must be a non-empty list"),
        ({**SMALL, "grid": {"l_r": []}}, "grid.l_r must be a non-empty list"),
        ({**SMALL, "grid": {"l_r": [0.2, 0.2]}}, "grid.l_r has repeated values"),
        ({**SMALL, "grid": {"l_r": [0.2, [1]]}}, "grid.l_r values must be finite scalars"),
        ({**SMALL, "grid": {"l_r": [0.2, -1.0]}}, "grid point {'l_r': -1.0}: "),
        ({**SMALL, "grid": {"n_agents": [0]}}, "relax.n_agents must be an integer >= 1"),
        ({**SMALL, "seeds": 0}, "seeds must be an integer >= 1 or a list"),
        ({**SMALL, "seeds": [1, -1]}, "seeds must be integers >= 0"),
        ({**SMALL, "seeds": [1, 1]}, "seeds has repeated values"),
        ({**SMALL, "plot": ["expanse"]}, "plot: 'expanse' is not a measure of the relax task"),
        ({**SMALL, "relax": {"integrator": "rk4"}}, "relax.integrator must be one of"),
        ({**SMALL, "cpus_per_trial": 0}, "cpus_per_trial must be a finite number > 0"),
        ({**NAV, "grid": {"l_r": [0.2], "n_agent": [3]}}, "grid.n_agent is not a parameter"),
        ({**NAV, "navigate": {"policy": "ppo"}}, "navigate.policy must be one of"),
        ({**NAV, "navigate": {"env": {"n_agent": 3}}}, "unknown config key 'n_agent'"),
    ],
)
def test_bad_sweep_configs_name_the_key(data, fragment):
    with pytest.raises(ValueError) as err:
        sweep_config_from_mapping(data)
    assert fragment in str(err.value)


def test_load_merges_overrides_into_sections(tmp_path: Path):
    sc = load_sweep_config(
        CONFIG_ROOT / "sweeps" / "quick.yaml", {"seeds": 3, "grid": {"l_r": [0.3]}}
    )
    assert sc.seeds == (0, 1, 2)
    assert sc.grid == {"l_r": (0.3,), "C_r": (1.2, 2.0)}  # C_r kept from the file
    with pytest.raises(ValueError, match="sweep config not found"):
        load_sweep_config(tmp_path / "missing.yaml")


# --------------------------------------------------------------------------- local engine


def test_specs_and_seeds_are_deterministic_and_common_random_numbers():
    crn = small().trial_specs()
    assert [s["index"] for s in crn] == list(range(8))
    assert [s["seed"] for s in crn] == [0, 1] * 4
    # common random numbers: a seed's start is the same at every grid point
    assert {tuple(s["entropy"]) for s in crn} == {(0, 0), (0, 1)}
    own = small(common_random_numbers=False).trial_specs()
    assert len({tuple(s["entropy"]) for s in own}) == 8
    assert own == small(common_random_numbers=False).trial_specs()
    assert trial_seed([0, 1]) == trial_seed([0, 1]) != trial_seed([1, 0])


def test_local_sweep_is_a_pure_function_of_each_trial():
    specs = small().trial_specs()
    rows = run_local(specs)
    assert rows == [run_trial(s) for s in reversed(specs)][::-1]  # order does not matter
    columns = ["index", "l_r", "C_r", "seed", *measure_columns("relax")]
    assert all(list(r) == columns for r in rows)
    assert all(np.isfinite(r[c]) for r in rows for c in measure_columns("relax"))
    # the same start for a seed: the trials differ only by the physics
    by_point = {(r["l_r"], r["C_r"], r["seed"]): r for r in rows}
    assert by_point[(0.2, 1.2, 0)]["final_expanse"] < by_point[(0.4, 1.2, 0)]["final_expanse"]
    # alignment and the pair forces conserve momentum: eq. 2 polarization is the same
    # at every grid point for a seed (common random numbers)
    pol = [r["final_velocity_polarization"] for r in rows if r["seed"] == 0]
    np.testing.assert_allclose(pol, pol[0], rtol=1e-9)
    assert len(RELAX_STATISTICS) * 2 == len(measure_columns("relax"))


def test_summary_is_mean_and_population_std_over_seeds():
    sc = small()
    rows = run_local(sc.trial_specs())
    summary = summarize_rows(sc, rows)
    assert [(e["l_r"], e["C_r"]) for e in summary] == [
        (0.2, 1.2),
        (0.2, 2.0),
        (0.4, 1.2),
        (0.4, 2.0),
    ]
    first = [r["final_expanse"] for r in rows[:2]]
    assert summary[0]["n_seeds"] == 2
    assert summary[0]["final_expanse_mean"] == pytest.approx(np.mean(first))
    assert summary[0]["final_expanse_std"] == pytest.approx(np.std(first))


def test_navigate_sweep_measures_the_controller(tmp_path: Path):
    sc = sweep_config_from_mapping(NAV)
    result = run_sweep(sc, engine="local")
    assert [r["C_g"] for r in result.rows] == [5.0, 30.0]
    for row in result.rows:
        assert row["success"] in (0.0, 1.0)
        assert (row["time_to_goal"] is None) == (row["success"] == 0.0)
        assert 1 <= row["episode_length"] <= 40
    out = write_outputs(result, tmp_path / "nav")
    for name in ("trials.csv", "summary.csv", "results.json", "sweep.png", "sweep_config.yaml"):
        assert (out / name).is_file()
    data = json.loads((out / "results.json").read_text())
    assert data["rows"] == result.rows and data["engine"] == "local"
    assert load_sweep_config(out / "sweep_config.yaml") == sc  # the saved config reloads


def test_cli_local_engine_writes_the_table_and_plot(tmp_path: Path, capsys):
    out = tmp_path / "quick"
    code = cli_sweep.main(
        [
            "--config",
            str(CONFIG_ROOT / "sweeps" / "quick.yaml"),
            "--engine",
            "local",
            "--out",
            str(out),
            "--no-progress",
            "relax.n_agents=6",
            "relax.duration=0.5",
        ]
    )
    assert code == 0
    header = (out / "trials.csv").read_text().splitlines()[0].split(",")
    assert header[:4] == ["index", "l_r", "C_r", "seed"]
    assert len((out / "trials.csv").read_text().splitlines()) == 1 + 8
    assert (out / "sweep.png").stat().st_size > 1000
    assert "8 trials" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["seeds=0"], "seeds must be an integer >= 1"),
        (["--engine", "local", "--address", "auto"], "apply only to --engine ray"),
        (["--engine", "ray", "--address", " "], "address must be HOST:PORT"),
        (["grid.l_x=[1]"], "grid.l_x is not a parameter"),
    ],
)
def test_cli_rejects_bad_input_with_exit_2(tmp_path: Path, capsys, args, fragment):
    config = str(CONFIG_ROOT / "sweeps" / "quick.yaml")
    code = cli_sweep.main(["--config", config, "--out", str(tmp_path), *args])
    assert code == 2
    assert fragment in capsys.readouterr().err


def test_cli_ray_engine_without_ray_says_how_to_install(tmp_path: Path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    config = str(CONFIG_ROOT / "sweeps" / "quick.yaml")
    assert cli_sweep.main(["--config", config, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert 'pip install -e ".[distributed]"' in err and "--engine local" in err


# --------------------------------------------------------------------------- Ray Tune


def test_ray_tune_sweep_matches_the_local_engine(tmp_path: Path):
    pytest.importorskip("ray.tune", reason="Ray is not installed (pip install -e '.[distributed]')")
    config = tmp_path / "small.yaml"
    import yaml

    config.write_text(yaml.safe_dump(SMALL))
    out = tmp_path / "ray"
    code = cli_sweep.main(
        [
            "--config",
            str(config),
            "--engine",
            "ray",
            "--num-cpus",
            "2",
            "--out",
            str(out),
            "--no-progress",
            "--no-plot",
        ]
    )
    assert code == 0
    ray_result = json.loads((out / "results.json").read_text())
    local = run_sweep(load_sweep_config(config), engine="local")
    assert ray_result["engine"] == "ray"
    assert ray_result["rows"] == local.rows  # the same numbers, bit for bit
    assert ray_result["summary"] == local.summary
    assert (out / "ray_tune" / "sweep_small").is_dir()  # Tune's own logs
