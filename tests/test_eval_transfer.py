"""Size transfer (``train.evaluate.transfer``, ``swarm-eval --n-agents``), unstable
episodes under step-size control, and results without NaN."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import gymnasium
import numpy as np
import pytest

from agents import PotentialFieldController, RandomController, ZeroController
from swarm_envs.config import SwarmConfig, load_swarm_config
from swarm_envs.envs import observation_size
from swarm_envs.envs.common import SwarmUnstableError
from train.cli_eval import main
from train.evaluate import (
    CentralPolicyError,
    SpaceMismatchError,
    evaluate_policies,
    evaluate_transfer,
    format_transfer_table,
    json_safe,
    load_sb3_model,
)
from train.evaluate.transfer import central_size, size_configs

# A short task the goal-sink controller solves in ~40 steps.
QUICK = {"n_agents": 4, "max_steps": 80, "goal_distance_min": 3.0, "goal_distance_max": 4.0}
# Steps of dt = 1 need more than 2 substeps: every episode ends unstable.
UNSTABLE = {
    "dt": 1.0,
    "max_substeps": 2,
    "max_steps": 20,
    "on_unstable": "truncate",
    "init_radius": 3.0,  # an average start fits max_substeps; the swarm then contracts
}


def _no_nan(text: str) -> dict:
    def refuse(name: str) -> None:
        raise AssertionError(f"results.json holds {name}")

    return json.loads(text, parse_constant=refuse)


class CentralPotential:
    """The goal-sink controller with whole-swarm spaces, like an SB3 model trained on
    the Gymnasium env with ``cfg.n_agents`` agents."""

    def __init__(self, cfg: SwarmConfig) -> None:
        self.inner = PotentialFieldController(cfg)
        n, k, d = cfg.n_agents, observation_size(cfg), cfg.dim
        self.observation_space = gymnasium.spaces.Box(-10, 10, (n * k,), np.float32)
        self.action_space = gymnasium.spaces.Box(-1, 1, (n * d,), np.float32)

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        raise AssertionError("a central policy must not run")


# --------------------------------------------------------------------------- Python API


def test_every_policy_runs_unchanged_at_every_size():
    cfg = SwarmConfig(**QUICK)
    policies = {
        "potential": PotentialFieldController(cfg),
        "zero": ZeroController(cfg),
        "random": RandomController(cfg, seed=0),
    }
    res = evaluate_transfer(policies, cfg, [5, 3], episodes=2, seed=1, progress=False)
    json.dumps(res, allow_nan=False)
    assert res["n_agents"] == [3, 5] and [s["n_agents"] for s in res["sizes"]] == [3, 5]
    assert res["config"]["n_agents"] == 4 and res["on_unstable"] == "raise"
    for size in res["sizes"]:
        assert size["backend"] in ("native", "numpy")  # auto's pick at these sizes
        assert list(size["policies"]) == ["potential", "zero", "random"]
        pot, zero = size["policies"]["potential"], size["policies"]["zero"]
        assert pot["success_rate"] == 1.0 and pot["mean_time_to_goal"] > 0
        assert pot["std_time_to_goal"] is not None and pot["unstable_episodes"] == 0
        assert zero["success_rate"] == 0.0 and zero["mean_time_to_goal"] is None
        assert zero["std_time_to_goal"] is None
        assert pot["mean_substeps"] >= 1.0
        low, high = zero["success_ci95"]
        assert low == 0.0 and 0.5 < high < 1.0  # Wilson, 0 of 2
    # The same episodes as a plain evaluation at that size: the harness is reused.
    at3 = evaluate_policies(
        {"potential": PotentialFieldController(cfg)},
        SwarmConfig(**{**QUICK, "n_agents": 3}),
        2,
        1,
        progress=False,
    )["policies"]["potential"]
    assert res["sizes"][0]["policies"]["potential"]["per_episode"] == at3["per_episode"]
    table = format_transfer_table(res)
    assert table.count("\n| ") == 6  # 3 policies × 2 sizes
    assert "| zero | 5 | native | 0% |" in table and "| — |" in table


def test_a_central_policy_is_refused_with_why():
    cfg = SwarmConfig(**QUICK)
    central = CentralPotential(cfg)
    assert central_size(central, cfg) == 4
    assert central_size(PotentialFieldController(cfg), cfg) is None
    with pytest.raises(CentralPolicyError, match=r"'c' is a central policy: .* fits N = 4 only"):
        evaluate_transfer({"c": central}, cfg, [3, 4], episodes=1, progress=False)
    assert issubclass(CentralPolicyError, SpaceMismatchError)

    class Wrong:
        observation_space = gymnasium.spaces.Box(-1, 1, (3,), np.float32)
        action_space = gymnasium.spaces.Box(-1, 1, (2,), np.float32)

        def predict(self, obs, state=None, episode_start=None, deterministic=True):
            raise AssertionError("must not run")

    with pytest.raises(SpaceMismatchError, match=r"policy 'w': observation space"):
        evaluate_transfer({"w": Wrong()}, cfg, [3], episodes=1, progress=False)


@pytest.mark.parametrize(
    ("sizes", "message"),
    [
        ([], "at least one"),
        ([3, 0], "integers >= 1, got 0"),
        ([3, True], "integers >= 1"),
        ([3, 2.5], "integers >= 1"),
        ([5, 3, 5], "lists 5 more than once"),
    ],
)
def test_bad_sizes_are_refused(sizes, message):
    with pytest.raises(ValueError, match=message):
        size_configs(SwarmConfig(), sizes)


def test_a_config_invalid_at_a_size_names_it():
    cfg = load_swarm_config(
        None, {"n_agents": 3, "dynamics": "lagrangian", "lagrangian": {"gamma": [0.1] * 3}}
    )
    with pytest.raises(ValueError, match="not valid at n_agents=5"):
        size_configs(cfg, [3, 5])


def test_unstable_episodes_are_counted_and_results_hold_no_nan(tmp_path):
    cfg = SwarmConfig(n_agents=4, **UNSTABLE)
    policies = {"potential": PotentialFieldController(cfg), "zero": ZeroController(cfg)}
    res = evaluate_transfer(policies, cfg, [3, 5], 2, 0, out_dir=tmp_path, progress=False)
    for size in res["sizes"]:
        for m in size["policies"].values():
            assert m["unstable_episodes"] == 2 and m["per_episode"]["unstable"] == [True] * 2
            assert m["success_rate"] == 0.0 and m["mean_time_to_goal"] is None
    # N = 5 goes unstable within its first two steps; N = 3 runs a while at up to the cap.
    at5 = res["sizes"][1]["policies"]["zero"]
    assert max(at5["per_episode"]["steps"]) <= 2
    assert at5["mean_substeps"] is None or 1.0 <= at5["mean_substeps"] <= 2.0
    at3 = res["sizes"][0]["policies"]["zero"]
    assert 1.0 <= at3["mean_substeps"] <= 2.0 and min(at3["per_episode"]["steps"]) > 2
    written = _no_nan((tmp_path / "results.json").read_text())
    assert written["sizes"][0]["policies"]["zero"]["mean_time_to_goal"] is None
    summary = (tmp_path / "summary.md").read_text()
    assert "| zero | 5 | native | 0% |" in summary and "| — | 0.0 ± 0.0 | 2 |" in summary
    rows = list(csv.DictReader((tmp_path / "transfer.csv").open()))
    assert len(rows) == 4 and rows[-1]["policy"] == "zero" and rows[-1]["n_agents"] == "5"
    assert rows[-1]["mean_time_to_goal"] == "" and rows[-1]["unstable_episodes"] == "2"
    assert (tmp_path / "transfer.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(SwarmUnstableError, match="max_substeps=2"):
        evaluate_transfer(policies, SwarmConfig(**{**UNSTABLE, "on_unstable": "raise"}), [3], 1)


def test_json_safe_writes_undefined_values_as_null():
    data = {"a": float("nan"), "b": [np.float64(np.inf), np.int64(3), np.bool_(True)]}
    data["c"] = {"d": np.array([1.5, -np.inf]), "e": None, "f": "text"}
    safe = json_safe(data)
    assert safe == {
        "a": None,
        "b": [None, 3, True],
        "c": {"d": [1.5, None], "e": None, "f": "text"},
    }
    json.dumps(safe, allow_nan=False)


# --------------------------------------------------------------------------- CLI


@pytest.fixture(scope="module")
def shared_model(tmp_path_factory) -> Path:
    """A tiny PPO trained by ``swarm-train``'s code on the vector env (shared policy)."""
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


def test_cli_size_transfer_writes_table_csv_plot(shared_model: Path, tmp_path, capsys):
    out = tmp_path / "sizes"
    argv = ["--policies", str(shared_model), "analytic", "zero", "--n-agents", "5", "3"]
    argv += ["--episodes", "2", "--max-steps", "8", "--set", "n_neighbors=2"]
    assert main([*argv, "--out", str(out), "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "| policy | N | backend | success |" in printed and "transfer.png" in printed
    res = _no_nan((out / "results.json").read_text())
    assert res["n_agents"] == [3, 5] and res["on_unstable"] == "truncate"
    assert res["config"]["on_unstable"] == "truncate" and res["overrides"] == {"n_neighbors": 2}
    for size in res["sizes"]:
        assert list(size["policies"]) == ["learned", "potential", "zero"]
        assert size["policies"]["learned"]["mode"] == "shared"
        assert size["policies"]["learned"]["per_episode"]["steps"] == [8, 8]
    rows = list(csv.DictReader((out / "transfer.csv").open()))
    assert [(r["policy"], r["n_agents"]) for r in rows] == [
        (p, n) for p in ("learned", "potential", "zero") for n in ("3", "5")
    ]
    assert (out / "transfer.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "| learned | 5 |" in (out / "summary.md").read_text()
    assert not list(out.glob("*.gif")) and not (out / "curves.png").exists()
    # --overwrite clears a size-transfer run's files
    assert main([*argv, "--out", str(out), "--no-progress", "--overwrite", "--no-plots"]) == 0
    assert not (out / "transfer.png").exists()


def test_cli_refuses_a_central_model(tmp_path, capsys):
    from stable_baselines3 import PPO

    central = tmp_path / "central_ppo.zip"
    env = gymnasium.make("swarm_envs/SwarmNav-v0", n_agents=3, n_neighbors=2)
    PPO("MlpPolicy", env, n_steps=16, batch_size=16, seed=0).save(central)
    argv = ["--policies", "zero", str(central), "--n-agents", "3", "5", "--set", "n_neighbors=2"]
    assert main([*argv, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "central_ppo.zip: policy 'central_ppo' is a central policy" in err
    assert "fits N = 3 only" in err and "shared per-agent policy" in err
    assert not (tmp_path / "o").exists()
    assert load_sb3_model(central).observation_space.shape == (3 * 14,)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--n-agents", "3", "--set", "n_agents=4"], "both set the swarm size"),
        (["--n-agents", "3", "0"], "--n-agents: n_agents must be integers >= 1, got 0"),
        (["--n-agents", "3", "3"], "lists 3 more than once"),
        (["--n-agents", "3", "--set", "device=cuda:99", "--set", "backend=numpy"], "device"),
    ],
)
def test_cli_size_errors(tmp_path, capsys, argv, message):
    assert main([*argv, "--out", str(tmp_path / "o"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("swarm-eval: error:") and message in err
    assert not (tmp_path / "o").exists()


def test_cli_keeps_on_unstable_where_the_user_sets_it(tmp_path, capsys):
    argv = ["--policies", "zero", "--n-agents", "3", "--episodes", "1", "--max-steps", "20"]
    argv += ["--set", "dt=1.0", "--set", "max_substeps=2", "--set", "init_radius=3.0"]
    argv += ["--no-progress"]
    # default: truncate, the episode counted as unstable
    assert main([*argv, "--out", str(tmp_path / "a")]) == 0
    res = _no_nan((tmp_path / "a" / "results.json").read_text())
    assert res["sizes"][0]["policies"]["zero"]["unstable_episodes"] == 1
    # --set on_unstable=raise: the unstable step stops the evaluation
    capsys.readouterr()
    assert main([*argv, "--set", "on_unstable=raise", "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "unstable step" in err and "max_substeps=2" in err
    # ... and so does a config file that names it
    config = tmp_path / "env.yaml"
    config.write_text("on_unstable: raise\n")
    assert main([*argv, "--config", str(config), "--out", str(tmp_path / "c")]) == 2
    assert "unstable step" in capsys.readouterr().err
    config.write_text("n_neighbors: 2\n")  # a file without it: truncate
    assert main([*argv, "--config", str(config), "--out", str(tmp_path / "d")]) == 0
    assert _no_nan((tmp_path / "d" / "results.json").read_text())["on_unstable"] == "truncate"
