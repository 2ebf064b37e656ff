"""Robustness sweeps (``train.evaluate.robustness``, ``swarm-eval --failed-fraction ...``):
every policy on the same seeded episodes under failed agents, noise and dropout."""

from __future__ import annotations

import csv
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from agents import PotentialFieldController, RandomController, ZeroController
from swarm_envs.config import SwarmConfig, load_swarm_config
from swarm_envs.envs.backends import STATUS_BACKENDS
from swarm_envs.perturbations import Perturbations
from train.cli_eval import main
from train.evaluate import evaluate_policies, evaluate_robustness, format_robustness_table
from train.evaluate.robustness import SWEPT, robustness_configs, sweep_values

# A short task the goal-sink controller solves in ~40 steps.
QUICK = {"n_agents": 4, "max_steps": 80, "goal_distance_min": 3.0, "goal_distance_max": 4.0}
PNG = b"\x89PNG\r\n\x1a\n"


def _no_nan(text: str) -> dict:
    def refuse(name: str) -> None:
        raise AssertionError(f"results.json holds {name}")

    return json.loads(text, parse_constant=refuse)


class Constant:
    """Every agent asks for the action (1, ..., 1), whatever it observes."""

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        return np.ones((len(obs), 2), np.float32), state


def _exit_status(argv: list[str]) -> int:
    """``main(argv)``'s exit status, whether returned or raised by argparse."""
    try:
        return main(argv)
    except SystemExit as exit_:
        return int(exit_.code)


def _per_episode(res: dict, option: str, value: float, name: str) -> dict:
    (row,) = [r for r in res["rows"] if r["option"] == option and r["value"] == value]
    return row["policies"][name]["per_episode"]


# --------------------------------------------------------------------------- Python API


def test_every_policy_runs_every_row_on_the_same_episodes():
    cfg = SwarmConfig(**QUICK)
    policies = {
        "potential": PotentialFieldController(cfg),
        "zero": ZeroController(cfg),
        "random": RandomController(cfg, seed=0),
    }
    sweeps = {"obs_noise": [0.5, 0], "failed_fraction": [0.5, 0, 0.25]}
    res = evaluate_robustness(policies, cfg, sweeps, episodes=2, seed=3, progress=False)
    json.dumps(res, allow_nan=False)
    # options in a fixed order, values increasing
    assert res["sweeps"] == {"failed_fraction": [0.0, 0.25, 0.5], "obs_noise": [0.0, 0.5]}
    assert [(r["option"], r["value"]) for r in res["rows"]] == [
        ("failed_fraction", 0.0),
        ("failed_fraction", 0.25),
        ("failed_fraction", 0.5),
        ("obs_noise", 0.0),
        ("obs_noise", 0.5),
    ]
    for row in res["rows"]:
        assert list(row["policies"]) == ["potential", "zero", "random"]
        p = row["perturbations"]
        for option in SWEPT:  # the swept option at its value, the others at 0
            assert p[option] == (row["value"] if option == row["option"] else 0.0)
        assert p["failure_mode"] == "passive" and p["failure_time"] == 0
        for m in row["policies"].values():
            assert 0.0 <= m["final_fraction_arrived"] <= 1.0
    assert all(res["perturbations"][option] == 0.0 for option in SWEPT)
    assert res["config"]["observe_status"] is False and res["seed"] == 3
    # The unperturbed rows of both options are the same episodes as a plain evaluation.
    plain = evaluate_policies(
        {"potential": PotentialFieldController(cfg)}, cfg, 2, 3, progress=False
    )
    expected = plain["policies"]["potential"]["per_episode"]
    assert expected["success"] == [True, True]
    for option in ("failed_fraction", "obs_noise"):
        assert _per_episode(res, option, 0.0, "potential") == expected
    # The zero policy asks nothing: a passive failure (its actions ignored) and noise on
    # what it observes change nothing, so every row repeats the same episodes exactly.
    zero = _per_episode(res, "failed_fraction", 0.0, "zero")
    for row in res["rows"]:
        assert row["policies"]["zero"]["per_episode"] == zero
    table = format_robustness_table(res)
    assert table.count("\n| ") == 15  # 3 policies × 5 rows
    assert (
        "| potential | failed_fraction | 0.25 |" in table and "| zero | obs_noise | 0.5 |" in table
    )


@pytest.mark.parametrize("mode", ["passive", "removed", "frozen"])
def test_a_failed_agents_action_is_ignored_and_costs_nothing(mode):
    cfg = SwarmConfig(**{**QUICK, "max_steps": 5})
    res = evaluate_robustness(
        {"ones": Constant()},
        cfg,
        {"failed_fraction": [0, 0.5]},
        episodes=2,
        failure_mode=mode,
        failure_time=0,
        progress=False,
    )
    calm, failing = (row["policies"]["ones"] for row in res["rows"])
    # |(1, 1)|² = 2 per agent, mean over the N agents: all 4 act, then 2 of 4
    assert calm["control_effort_per_step"] == pytest.approx(2.0)
    assert failing["control_effort_per_step"] == pytest.approx(1.0)
    assert res["rows"][1]["perturbations"]["failure_mode"] == mode


def test_single_values_are_fixed_where_another_option_is_swept():
    cfg = SwarmConfig(**QUICK)
    rows = robustness_configs(cfg, {"failed_fraction": [0, 0.5], "obs_noise": [0.3]})
    assert [(r.option, r.value) for r in rows] == [
        ("failed_fraction", 0.0),
        ("failed_fraction", 0.5),
    ]
    assert [r.cfg.perturbations.obs_noise for r in rows] == [0.3, 0.3]
    # where no option lists several values, each given option is swept
    rows = robustness_configs(cfg, {"obs_noise": [0.3], "action_noise": [0.1]})
    assert [(r.option, r.value) for r in rows] == [("obs_noise", 0.3), ("action_noise", 0.1)]
    assert rows[0].cfg.perturbations.action_noise == 0.0
    assert rows[1].cfg.perturbations.obs_noise == 0.0
    # only the perturbations change; the config's own swept fields are reset, the rest kept
    base = load_swarm_config(
        None,
        {
            **QUICK,
            "observe_status": True,
            "perturbations": {"absent_fraction": 0.25, "obs_noise": 1},
        },
    )
    rows = robustness_configs(
        base, {"failed_fraction": [0.25, 0.5]}, failure_mode="frozen", failure_time=[2, 5]
    )
    for r in rows:
        p = r.cfg.perturbations
        assert p.absent_fraction == 0.25 and p.obs_noise == 0.0
        assert p.failure_mode == "frozen" and p.failure_time == (2, 5)
        assert r.cfg.observe_status is True and r.cfg.n_agents == base.n_agents
        assert dataclasses.replace(r.cfg, perturbations=base.perturbations) == base


@pytest.mark.parametrize(
    ("option", "values", "message"),
    [
        ("obs_noise", [0, -1], r"Perturbations.obs_noise must be in \[0, inf\), got -1.0"),
        ("failed_fraction", [0, 1], r"Perturbations.failed_fraction must be in \[0, 1\)"),
        ("neighbor_dropout", [1.5], r"Perturbations.neighbor_dropout must be in \[0, 1\)"),
        ("action_noise", [float("nan")], "Perturbations.action_noise"),
        ("failed_fraction", [0.1, 0.3, 0.1], "failed_fraction lists 0.1 more than once"),
        ("obs_noise", [], "obs_noise must list at least one value"),
        ("obs_noise", [True], "obs_noise values must be numbers"),
        ("absent_fraction", [0.1], "cannot sweep 'absent_fraction'; sweepable options: "),
    ],
)
def test_bad_values_are_refused(option, values, message):
    with pytest.raises(ValueError, match=message):
        sweep_values(option, values)


def test_bad_rows_are_refused_naming_the_value():
    cfg = SwarmConfig(**QUICK)
    with pytest.raises(ValueError, match="no option to sweep"):
        robustness_configs(cfg, {})
    with pytest.raises(ValueError, match="failure_mode must be one of"):
        robustness_configs(cfg, {"failed_fraction": [0.5]}, failure_mode="gone")
    with pytest.raises(ValueError, match=r"failure_time must be in \[0, inf\), got -1"):
        robustness_configs(cfg, {"failed_fraction": [0.5]}, failure_time=-1)
    crowded = SwarmConfig(**QUICK, perturbations=Perturbations(absent_fraction=0.5))
    with pytest.raises(ValueError, match=r"not valid at failed_fraction=0\.5: .*below 1"):
        robustness_configs(crowded, {"failed_fraction": [0, 0.5]})
    zone = load_swarm_config(None, {**QUICK, "dynamics": "zone"})
    with pytest.raises(ValueError, match=r"not valid at failed_fraction=0\.5"):
        robustness_configs(zone, {"failed_fraction": [0, 0.5]}, failure_mode="removed")


# --------------------------------------------------------------------------- CLI


@pytest.fixture(scope="module")
def shared_model(tmp_path_factory) -> Path:
    """A tiny PPO trained by ``swarm-train``'s code on the vector env without status
    flags in its observations."""
    from train.config import train_config_from_mapping
    from train.train import train

    tc = train_config_from_mapping(
        {
            "env": {"n_agents": 3, "max_steps": 10, "n_neighbors": 2},
            "n_swarms": 1,
            "total_timesteps": 1,
            "hyperparams": {"n_steps": 8, "batch_size": 8, "n_epochs": 1},
            "checkpoint_seconds": 0,
        }
    )
    out = tmp_path_factory.mktemp("runs") / "learned"  # the label: the run's folder
    train(tc, out, progress_bar=False, tensorboard=False, verbose=0, handle_signals=False)
    return out / "model.zip"


def test_cli_sweeps_write_table_csv_plot(shared_model: Path, tmp_path, capsys):
    out = tmp_path / "robust"
    argv = ["--policies", str(shared_model), "analytic", "zero", "random"]
    argv += ["--failed-fraction", "0.5", "0", "--failure-mode", "removed"]
    argv += ["--obs-noise", "0", "1", "--episodes", "2", "--max-steps", "8"]
    argv += ["--set", "n_neighbors=2", "--set", "n_agents=4", "--no-progress"]
    assert main([*argv, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "| policy | perturbation | value | backend | success |" in printed
    assert "robustness.csv" in printed and "robustness.png" in printed
    res = _no_nan((out / "results.json").read_text())
    assert res["sweeps"] == {"failed_fraction": [0.0, 0.5], "obs_noise": [0.0, 1.0]}
    assert res["on_unstable"] == "truncate" and res["config"]["observe_status"] is False
    assert res["perturbations"]["failure_mode"] == "removed"
    names = ["learned", "potential", "zero", "random"]
    for row in res["rows"]:
        assert list(row["policies"]) == names
        if row["option"] == "failed_fraction" and row["value"] > 0:
            # removed agents need a core that takes statuses
            assert all(b in STATUS_BACKENDS for b in row["backend"].split(", "))
        for m in row["policies"].values():
            assert m["per_episode"]["steps"] == [8, 8]  # nobody arrives in 8 steps
            assert m["final_fraction_arrived"] is not None
    # the model, trained without status flags, keeps its observations under failures
    assert res["rows"][1]["policies"]["learned"]["mode"] == "shared"
    assert res["rows"][1]["perturbations"]["failed_fraction"] == 0.5
    rows = list(csv.DictReader((out / "robustness.csv").open()))
    assert [(r["policy"], r["perturbation"], r["value"]) for r in rows] == [
        (p, o, v)
        for o, values in (("failed_fraction", ("0.0", "0.5")), ("obs_noise", ("0.0", "1.0")))
        for p in names
        for v in values
    ]
    assert {r["failure_mode"] for r in rows} == {"removed"}
    assert all(r["mean_time_to_goal"] == "" and r["final_fraction_arrived"] for r in rows)
    assert (out / "robustness.png").read_bytes()[:8] == PNG
    summary = (out / "summary.md").read_text()
    assert "| learned | failed_fraction | 0.5 |" in summary and "failure_mode = removed" in summary
    assert not list(out.glob("*.gif")) and not (out / "curves.png").exists()
    # --overwrite clears a robustness run's files
    assert main([*argv, "--out", str(out), "--overwrite", "--no-plots"]) == 0
    assert not (out / "robustness.png").exists() and (out / "robustness.csv").exists()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--obs-noise", "0", "-1"], "--obs-noise: Perturbations.obs_noise must be in [0, inf)"),
        (["--failed-fraction", "1"], "--failed-fraction: Perturbations.failed_fraction must be"),
        (["--neighbor-dropout", "0.2", "0.2"], "--neighbor-dropout: neighbor_dropout lists"),
        (["--failure-mode", "frozen"], "need --failed-fraction"),
        (["--failed-fraction", "0.5", "--failure-time", "1", "2", "3"], "T or LOW HIGH"),
        (["--failed-fraction", "0.5", "--failure-time", "-1"], "--failure-time: Perturbations"),
        (["--failed-fraction", "0.5", "--failure-mode", "gone"], "invalid choice: 'gone'"),
        (["--n-agents", "3", "4", "--obs-noise", "0", "1"], "do not combine"),
        (
            ["--failed-fraction", "0", "0.5", "--set", "perturbations.absent_fraction=0.5"],
            "robustness sweep: the config is not valid at failed_fraction=0.5",
        ),
    ],
)
def test_cli_robustness_errors(tmp_path, capsys, argv, message):
    assert _exit_status([*argv, "--out", str(tmp_path / "o"), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("swarm-eval: error:")
    assert message in err
    assert not (tmp_path / "o").exists()


@pytest.fixture(scope="module")
def flagged_model(tmp_path_factory) -> Path:
    """A tiny PPO whose observations carry the neighbours' status flags."""
    from train.config import train_config_from_mapping
    from train.train import train

    tc = train_config_from_mapping(
        {
            "env": {"n_agents": 3, "max_steps": 10, "n_neighbors": 2, "observe_status": True},
            "n_swarms": 1,
            "total_timesteps": 1,
            "hyperparams": {"n_steps": 8, "batch_size": 8, "n_epochs": 1},
            "checkpoint_seconds": 0,
        }
    )
    out = tmp_path_factory.mktemp("flagged")
    train(tc, out, progress_bar=False, tensorboard=False, verbose=0, handle_signals=False)
    return out / "model.zip"


def test_models_with_and_without_status_flags_run_side_by_side(
    shared_model: Path, flagged_model: Path, tmp_path
):
    out = tmp_path / "both"
    argv = ["--policies", str(shared_model), str(flagged_model), "analytic"]
    argv += ["--failed-fraction", "0", "0.5", "--failure-mode", "frozen", "--episodes", "2"]
    argv += ["--max-steps", "8", "--set", "n_neighbors=2", "--set", "n_agents=4"]
    assert main([*argv, "--no-progress", "--out", str(out)]) == 0
    res = _no_nan((out / "results.json").read_text())
    for row in res["rows"]:
        assert len(row["policies"]) == 3
        assert all(m["mode"] == "shared" for m in row["policies"].values())
