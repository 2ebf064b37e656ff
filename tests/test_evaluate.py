"""The evaluation harness (``train.evaluate``) and the ``swarm-eval`` console script."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from helpers import count_kept

from agents import PotentialFieldController, RandomController, ZeroController
from swarm_envs import swarm_nav_v0
from swarm_envs.config import SwarmConfig
from swarm_envs.envs import observation_size
from swarm_envs.envs.common import SwarmUnstableError
from train.cli_eval import main
from train.evaluate import (
    CURVE_KEYS,
    SpaceMismatchError,
    evaluate_policies,
    format_table,
    load_sb3_model,
    policy_mode,
    run_episodes,
)
from train.evaluate.policies import _detect_sb3_algorithm

ROOT = Path(__file__).resolve().parent.parent
# A short task the goal-sink controller solves in ~40 steps.
QUICK = {"n_agents": 4, "max_steps": 80, "goal_distance_min": 3.0, "goal_distance_max": 4.0}
QUICK_ARGS = [f"--set={k}={v}" for k, v in QUICK.items()]


@pytest.fixture(scope="module")
def cfg() -> SwarmConfig:
    return SwarmConfig(**QUICK)


class CentralPotential:
    """The goal-sink controller seen as a whole-swarm ("central") policy, like an SB3
    model trained on the Gymnasium env."""

    def __init__(self, cfg: SwarmConfig) -> None:
        self.inner = PotentialFieldController(cfg)
        n, k, d = cfg.n_agents, observation_size(cfg), cfg.dim
        self.observation_space = gymnasium.spaces.Box(-10, 10, (n * k,), np.float32)
        self.action_space = gymnasium.spaces.Box(-1, 1, (n * d,), np.float32)
        self.shapes: list[tuple[int, ...]] = []

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        self.shapes.append(np.shape(obs))
        return self.inner.predict(obs, state, episode_start, deterministic)


# --------------------------------------------------------------------------- Python API


def test_evaluate_policies_measures(cfg):
    policies = {
        "potential": PotentialFieldController(cfg),
        "zero": ZeroController(cfg),
        "random": RandomController(cfg, seed=0),
    }
    res = evaluate_policies(policies, cfg, episodes=3, seed=0, progress=False)
    assert res["env"] == "swarm_envs/SwarmNav-v0"
    assert res["episodes"] == 3 and res["seed"] == 0
    assert res["config"]["n_agents"] == 4
    json.dumps(res, allow_nan=False)  # JSON-ready
    pot, zero, rnd = (res["policies"][k] for k in ("potential", "zero", "random"))
    for m in (pot, zero, rnd):
        for key in (
            "mean_return",
            "std_return",
            "success_rate",
            "mean_time_to_goal",
            "collisions_per_episode",
            "control_effort",
            "final_expanse",
            "final_polarization",
        ):
            assert key in m
    assert pot["success_rate"] == 1.0 and zero["success_rate"] == 0.0
    steps = np.array(pot["per_episode"]["steps"])
    assert pot["mean_time_to_goal"] == pytest.approx(steps.mean() * cfg.dt)
    assert zero["mean_time_to_goal"] is None
    assert zero["per_episode"]["steps"] == [cfg.max_steps] * 3
    assert zero["control_effort"] == 0.0 and pot["control_effort"] > 0
    assert rnd["control_effort_per_step"] == pytest.approx(2 / 3, rel=0.1)  # E|a|² = d/3
    assert pot["mean_return"] > rnd["mean_return"] and pot["mean_return"] > zero["mean_return"]
    assert pot["final_centroid_distance"] < zero["final_centroid_distance"]


def test_every_policy_sees_the_same_episodes(cfg):
    a = run_episodes(ZeroController(cfg), cfg, 4, seed=7)
    b = run_episodes(ZeroController(cfg), cfg, 4, seed=7)
    c = run_episodes(ZeroController(cfg), cfg, 4, seed=8)
    assert np.array_equal(a.returns, b.returns)
    assert np.array_equal(a.trajectory["x"], b.trajectory["x"])
    assert not np.array_equal(a.trajectory["x"][0], c.trajectory["x"][0])
    p = run_episodes(PotentialFieldController(cfg), cfg, 4, seed=7)
    assert np.array_equal(p.trajectory["x"][0], a.trajectory["x"][0])  # same start
    assert np.array_equal(p.curves["centroid_distance"][0], a.curves["centroid_distance"][0])


def test_curves_hold_the_last_value_after_an_episode_ends(cfg):
    b = run_episodes(PotentialFieldController(cfg), cfg, 3, seed=0)
    T = b.times.size
    assert b.times[1] == pytest.approx(cfg.dt)
    assert T == b.lengths.max() + 1  # stops when the last episode ends
    for key in CURVE_KEYS:
        assert b.curves[key].shape == (T, 3)
        for e, n in enumerate(b.lengths):
            assert np.all(b.curves[key][n:, e] == b.curves[key][n, e])
    # the final statistics are the curves' values at each episode's end
    ends = b.curves["centroid_distance"][b.lengths, np.arange(3)]
    np.testing.assert_allclose(b.final["centroid_distance"], ends)
    assert len(b.trajectory["x"]) == b.lengths[0] + 1


@pytest.mark.parametrize("central", [False, True])
def test_a_core_shrunk_to_the_live_episodes_gives_the_same_results(cfg, monkeypatch, central):
    """Once at most a quarter of the episodes are live the numpy core shrinks to them;
    every recorded number is the whole batch's, bit for bit."""
    import train.evaluate.episodes as episodes

    quick = replace(cfg, backend="numpy", goal_distance_min=2.0, goal_distance_max=6.0)
    kept = count_kept(monkeypatch)
    policy = CentralPotential(quick) if central else PotentialFieldController(quick)
    shrunk = run_episodes(policy, quick, 12, seed=3)
    assert kept and kept[-1] <= 12 // 4  # it shrank
    monkeypatch.setattr(episodes, "keeps_rows", lambda core: False)
    whole = run_episodes(policy, quick, 12, seed=3)
    assert len(set(whole.lengths.tolist())) > 3  # episodes of many lengths
    for field in ("returns", "success", "lengths", "collisions", "effort", "unstable"):
        assert getattr(shrunk, field).tobytes() == getattr(whole, field).tobytes(), field
    for field in ("substeps", "integrated", "first_success", "times"):
        assert getattr(shrunk, field).tobytes() == getattr(whole, field).tobytes(), field
    for group in ("final", "curves", "trajectory"):
        for key, value in getattr(whole, group).items():
            assert getattr(shrunk, group)[key].tobytes() == value.tobytes(), (group, key)


def test_central_policies_get_whole_swarm_observations(cfg):
    central = CentralPotential(cfg)
    assert policy_mode(central, cfg) == "central"
    assert policy_mode(PotentialFieldController(cfg), cfg) == "shared"
    res = evaluate_policies(
        {"central": central, "shared": PotentialFieldController(cfg)},
        cfg,
        episodes=3,
        seed=1,
        progress=False,
    )
    n, k = cfg.n_agents, observation_size(cfg)
    assert central.shapes[0] == (3, n * k)
    c, s = res["policies"]["central"], res["policies"]["shared"]
    assert c["mode"] == "central" and s["mode"] == "shared"
    assert c["per_episode"] == s["per_episode"]
    assert c["mean_return"] == s["mean_return"]


def test_space_mismatch_is_an_error(cfg):
    class Wrong:
        observation_space = gymnasium.spaces.Box(-1, 1, (3,), np.float32)
        action_space = gymnasium.spaces.Box(-2, 2, (1,), np.float32)

        def predict(self, obs, state=None, episode_start=None, deterministic=True):
            raise AssertionError("must not run")

    with pytest.raises(SpaceMismatchError, match=r"policy 'wrong': observation space .*\(34,\)"):
        evaluate_policies({"wrong": Wrong()}, cfg, episodes=1, seed=0, progress=False)

    class WrongBounds(Wrong):
        observation_space = gymnasium.spaces.Box(-10, 10, (observation_size(cfg),))
        action_space = gymnasium.spaces.Box(-2, 2, (2,))

    with pytest.raises(SpaceMismatchError, match=r"\[-1, 1\]"):
        policy_mode(WrongBounds(), cfg)
    with pytest.raises(ValueError, match="episodes"):
        run_episodes(ZeroController(cfg), cfg, 0, seed=0)


def test_evaluate_accepts_an_env_and_writes_outputs(tmp_path, cfg):
    env = gymnasium.make("swarm_envs/SwarmNav-v0", **QUICK)
    res = evaluate_policies(
        {"potential": PotentialFieldController(env)},
        env,
        episodes=2,
        seed=0,
        out_dir=tmp_path,
        progress=False,
        gif_size=120,
    )
    assert json.loads((tmp_path / "results.json").read_text())["policies"].keys() == {"potential"}
    assert (tmp_path / "curves.png").stat().st_size > 0
    assert (tmp_path / "episode0_potential.gif").stat().st_size > 0
    assert "| potential | 100% |" in format_table(res)


def test_undefined_measures_are_null_and_shown_as_a_dash(tmp_path):
    cfg = SwarmConfig(n_agents=3, max_steps=5)  # nothing reaches a goal 8-12 away in 5 steps
    res = evaluate_policies(
        {"zero": ZeroController(cfg)}, cfg, 2, 0, out_dir=tmp_path, progress=False, gif=False
    )
    zero = res["policies"]["zero"]
    assert zero["success_rate"] == 0.0 and zero["mean_time_to_goal"] is None
    assert zero["std_time_to_goal"] is None and zero["unstable_episodes"] == 0
    assert zero["mean_substeps"] == 1.0  # slow and sparse: one substep per step

    def refuse(name):
        raise AssertionError(f"results.json holds {name}")

    written = json.loads((tmp_path / "results.json").read_text(), parse_constant=refuse)
    assert written["policies"]["zero"]["mean_time_to_goal"] is None
    row = next(line for line in format_table(res).splitlines() if line.startswith("| zero"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[0] == "zero" and cells[1] == "0%" and cells[3] == "—"
    assert cells[-3:-1] == ["0", "1.0"]  # unstable episodes, substeps per step
    assert cells[-1] == "✓"  # zero is the only baseline, so the best
    assert "| — |" in (tmp_path / "summary.md").read_text()


def test_unstable_episodes_are_truncated_and_counted():
    # an average start fits the cap (3 substeps), but the passive swarm contracts
    cfg = SwarmConfig(n_agents=3, dt=1.0, max_substeps=3, max_steps=20, on_unstable="truncate")
    b = run_episodes(ZeroController(cfg), cfg, 2, seed=0)
    assert b.unstable.tolist() == [True, True] and not b.success.any()
    assert np.all(b.integrated == b.lengths - 1)  # the unstable step was undone
    assert np.all(b.integrated <= b.substeps) and np.all(b.substeps <= 3.0 * b.integrated)
    with pytest.raises(SwarmUnstableError, match="on_unstable='truncate'"):
        run_episodes(ZeroController(cfg), replace(cfg, on_unstable="raise"), 2, seed=0)


# --------------------------------------------------------------------------- CLI


def test_cli_writes_all_outputs(tmp_path, capsys):
    out = tmp_path / "eval"
    argv = ["--policies", "potential", "zero", "random", "--episodes", "2", "--seed", "3"]
    rc = main([*argv, *QUICK_ARGS, "--out", str(out), "--no-progress", "--gif-size", "160"])
    assert rc == 0
    printed = capsys.readouterr().out
    assert "| potential |" in printed and "results.json" in printed
    res = json.loads((out / "results.json").read_text())
    assert set(res) >= {"env", "config", "episodes", "seed", "policies"}
    assert res["episodes"] == 2 and res["seed"] == 3 and res["config"]["max_steps"] == 80
    assert list(res["policies"]) == ["potential", "zero", "random"]
    assert res["policies"]["potential"]["success_rate"] == 1.0
    summary = (out / "summary.md").read_text()
    assert summary.count("\n| ") >= 3 and "| zero |" in summary
    png = (out / "curves.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    for name in ("potential", "zero", "random"):
        gif = out / f"episode0_{name}.gif"
        assert gif.read_bytes()[:6] == b"GIF89a"
        assert gif.stat().st_size < 1_000_000


def test_cli_with_config_file_and_overrides(tmp_path):
    out = tmp_path / "nav"
    rc = main(
        [
            "--config",
            "configs/env/paper_navigation.yaml",
            "--set",
            "n_agents=5",
            "--set",
            "physics.C_o=0.5",
            "--max-steps",
            "10",
            "--policies",
            "zero",
            "--episodes",
            "1",
            "--out",
            str(out),
            "--no-progress",
            "--no-gif",
            "--no-plots",
        ]
    )
    assert rc == 0
    res = json.loads((out / "results.json").read_text())
    cfg = res["config"]
    assert (cfg["n_agents"], cfg["max_steps"], cfg["physics"]["C_o"]) == (5, 10, 0.5)
    assert cfg["physics"]["C_g"] == 15.0 and res["config_path"].endswith("paper_navigation.yaml")
    assert not (out / "curves.png").exists() and not list(out.glob("*.gif"))


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--policies", "potential", "magic"], "unknown policy 'magic'"),
        (["--policies", "missing/model.zip"], "model file not found: missing/model.zip"),
        (["--policies", "nothere.zip"], "model file not found"),
        (["--env", "swarm_envs/Nope-v0"], "cannot make env"),
        (["--set", "n_agent=3"], "n_agent"),
        (["--set", "novalue"], "KEY=VALUE"),
        (["--episodes", "0"], "--episodes"),
        (["--torch-threads", "-1"], "--torch-threads must be >= 0"),
        (["--set", "backend=numpy", "--set", "device=cuda:99"], "device"),
    ],
)
def test_cli_errors(tmp_path, capsys, argv, message):
    rc = main([*argv, "--out", str(tmp_path / "o"), "--no-progress"])
    assert rc != 0
    err = capsys.readouterr().err
    assert err.startswith("swarm-eval: error:") and message in err
    assert not (tmp_path / "o").exists()


def test_cli_rejects_a_file_that_is_not_a_model(tmp_path, capsys):
    bogus = tmp_path / "bogus.zip"
    bogus.write_text("not a zip")
    assert main(["--policies", str(bogus), "--out", str(tmp_path / "o")]) == 2
    assert "not a Stable-Baselines3 model zip" in capsys.readouterr().err


def test_cli_rejects_a_model_with_mismatched_spaces(tmp_path, capsys):
    from stable_baselines3 import PPO

    path = tmp_path / "pendulum_ppo.zip"
    PPO("MlpPolicy", gymnasium.make("Pendulum-v1"), n_steps=16, batch_size=16).save(path)
    rc = main(["--policies", "potential", str(path), "--out", str(tmp_path / "o")])
    assert rc == 2
    err = capsys.readouterr().err
    assert "does not fit the env" in err and "(3,)" in err and "(34,)" in err
    assert not (tmp_path / "o").exists()


def test_cli_evaluates_sb3_models_in_both_layouts(tmp_path):
    from stable_baselines3 import PPO, SAC

    shared = tmp_path / "shared_sac.zip"
    central = tmp_path / "central_ppo.zip"
    SAC("MlpPolicy", swarm_nav_v0.vec_env(1, **QUICK), buffer_size=64, seed=0).save(shared)
    PPO(
        "MlpPolicy",
        gymnasium.make("swarm_envs/SwarmNav-v0", **QUICK),
        n_steps=16,
        batch_size=16,
        seed=0,
    ).save(central)
    out = tmp_path / "o"
    argv = ["--policies", str(shared), str(central), str(central), "--episodes", "2"]
    rc = main([*argv, *QUICK_ARGS, "--max-steps", "5", "--out", str(out), "--no-progress"])
    assert rc == 0
    res = json.loads((out / "results.json").read_text())["policies"]
    assert list(res) == ["shared_sac", "central_ppo", "central_ppo_2"]
    assert res["shared_sac"]["mode"] == "shared" and res["central_ppo"]["mode"] == "central"
    assert (out / "episode0_central_ppo_2.gif").exists()


def test_sb3_algorithm_detection():
    common = {"policy_class": {"__module__": "stable_baselines3.common.policies"}}
    assert _detect_sb3_algorithm({**common, "clip_range": 0.2}) == "PPO"
    assert _detect_sb3_algorithm(common) == "A2C"
    sac = {"policy_class": {"__module__": "stable_baselines3.sac.policies"}}
    assert _detect_sb3_algorithm(sac) == "SAC"
    td3 = {"policy_class": {"__module__": "stable_baselines3.td3.policies"}}
    assert _detect_sb3_algorithm(td3) == "TD3"


def test_console_script_exits_nonzero_on_a_bad_policy(tmp_path):
    # An occupied default --out (runs/eval, as the README's evaluation leaves it): the
    # policy is reported first, and nothing in the folder is touched.
    (tmp_path / "runs" / "eval").mkdir(parents=True)
    (tmp_path / "runs" / "eval" / "results.json").write_text("{}")
    proc = subprocess.run(
        [sys.executable, "-m", "train.cli_eval", "--policies", "nope"],
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2
    assert "unknown policy 'nope'" in proc.stderr
    assert (tmp_path / "runs" / "eval" / "results.json").read_text() == "{}"


def test_policies_are_labelled_by_the_user_or_by_their_run_folder(tmp_path, capsys):
    from stable_baselines3 import PPO

    model = PPO("MlpPolicy", swarm_nav_v0.vec_env(1, **QUICK), n_steps=16, batch_size=16)
    for run in ("robust", "demo"):
        (tmp_path / "runs" / run).mkdir(parents=True)
        model.save(tmp_path / "runs" / run / "model.zip")
    robust, demo = (str(tmp_path / "runs" / r / "model.zip") for r in ("robust", "demo"))
    common = [*QUICK_ARGS, "--episodes", "1", "--no-progress", "--no-gif", "--no-plots"]

    def labels(policies: list[str], out: str) -> list[str]:
        assert main(["--policies", *policies, *common, "--out", str(tmp_path / out)]) == 0
        return list(json.loads((tmp_path / out / "results.json").read_text())["policies"])

    assert labels([robust, demo, "analytic"], "default") == ["robust", "demo", "potential"]
    named = labels([f"mine={robust}", f"theirs={demo}", "base=analytic"], "named")
    assert named == ["mine", "theirs", "base"]
    assert labels([robust, robust], "twice") == ["robust", "robust_2"]
    capsys.readouterr()
    for bad, message in (
        ([f"a={robust}", f"a={demo}"], "the label 'a' is given twice"),
        ([f"no label={robust}"], "LABEL=POLICY"),
        ([f"={robust}"], "LABEL=POLICY"),
    ):
        assert main(["--policies", *bad, *common, "--out", str(tmp_path / "bad")]) == 2
        assert message in capsys.readouterr().err
        assert not (tmp_path / "bad").exists()


def _native_available(cfg: SwarmConfig) -> bool:
    from swarm_envs.envs.backends import unsupported

    return unsupported(cfg, "native") is None


@pytest.mark.parametrize("backend", ["numpy", "native"])
def test_episodes_run_on_the_configs_backend(backend):
    cfg = SwarmConfig(n_agents=4, max_steps=20, backend=backend)
    if backend == "native" and not _native_available(cfg):
        pytest.skip("the C step cannot be built here")
    res = evaluate_policies({"potential": PotentialFieldController(cfg)}, cfg, 3, 0, progress=False)
    assert res["backend"] == backend
    reference = evaluate_policies(
        {"potential": PotentialFieldController(cfg)},
        SwarmConfig(n_agents=4, max_steps=20, backend="numpy"),
        3,
        0,
        progress=False,
    )
    got, want = res["policies"]["potential"], reference["policies"]["potential"]
    assert got["mean_return"] == pytest.approx(want["mean_return"], rel=1e-9)


def test_cli_records_and_refuses_the_env_device(tmp_path, capsys):
    import torch

    out = tmp_path / "o"
    argv = ["--policies", "zero", "--episodes", "1", "--max-steps", "3", "--no-gif"]
    before = torch.get_num_threads()
    try:
        assert (
            main([*argv, "--set", "backend=numpy", "--torch-threads", "1", "--out", str(out)]) == 0
        )
        assert torch.get_num_threads() == 1
    finally:
        torch.set_num_threads(before)
    assert json.loads((out / "results.json").read_text())["backend"] == "numpy"
    capsys.readouterr()
    bad = ["--set", "device=cuda:99", "--set", "backend=numpy", "--out", str(tmp_path / "b")]
    assert main([*argv, *bad]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "device" in err and err.startswith("swarm-eval: ")
    assert not (tmp_path / "b").exists()


@pytest.fixture(scope="module")
def trained_run(tmp_path_factory) -> Path:
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
    out = tmp_path_factory.mktemp("runs") / "learned"  # the policy's label: its folder
    train(tc, out, progress_bar=False, tensorboard=False, verbose=0, handle_signals=False)
    return out


def test_a_trained_model_records_its_env(trained_run: Path):
    from train.evaluate import TRAINED_ENV, trained_env_record

    cfg = SwarmConfig(n_agents=3, max_steps=10, n_neighbors=2)
    record = getattr(load_sb3_model(trained_run / "model.zip"), TRAINED_ENV)
    assert record == trained_env_record(cfg, "swarm_envs/SwarmNav-v0")
    assert record["observation_size"] == observation_size(cfg) == 14
    assert record["dynamics"] == "social_potential"
    meta = json.loads((trained_run / "meta.json").read_text())
    assert meta["env"]["observation_size"] == 14 and meta["env"]["n_neighbors"] == 2
    for ckpt in (trained_run / "checkpoints").iterdir():
        assert getattr(load_sb3_model(ckpt / "model.zip"), TRAINED_ENV) == record


def test_evaluating_on_other_dynamics_warns(trained_run: Path, capsys):
    from train.evaluate import TrainedEnvWarning

    model = load_sb3_model(trained_run / "model.zip")
    zone = SwarmConfig(n_agents=5, max_steps=3, n_neighbors=2, dynamics="zone")
    with pytest.warns(TrainedEnvWarning, match="dynamics: trained 'social_potential', here 'zone'"):
        evaluate_policies({"m": model}, zone, 1, 0, progress=False)
    # Another swarm size alone is what a shared policy is for: no warning.
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", TrainedEnvWarning)
        evaluate_policies({"m": model}, SwarmConfig(n_agents=5, max_steps=3, n_neighbors=2), 1, 0)
    argv = ["--policies", str(trained_run / "model.zip"), "--episodes", "1", "--no-gif"]
    argv += ["--set", "dynamics=zone", "--set", "n_neighbors=2", "--max-steps", "3"]
    assert main([*argv, "--out", str(trained_run / "eval_zone"), "--no-progress"]) == 0
    warning = [line for line in capsys.readouterr().err.splitlines() if "warning" in line]
    assert warning == [
        "swarm-eval: warning: policy 'learned' is evaluated on another env than it was "
        "trained on: dynamics: trained 'social_potential', here 'zone'"
    ]


def test_evaluating_on_other_spaces_is_refused_with_what_it_was_trained_on(
    trained_run: Path, capsys
):
    argv = ["--policies", str(trained_run / "model.zip"), "--set", "n_neighbors=3"]
    assert main([*argv, "--out", str(trained_run / "eval_k3")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "does not fit the env" in err
    assert "trained on dynamics='social_potential', N=3, d=2, k=2 (observation size 14" in err
    assert not (trained_run / "eval_k3").exists()
    model = load_sb3_model(trained_run / "model.zip")
    with pytest.raises(SpaceMismatchError, match="the model was trained on"):
        evaluate_policies({"m": model}, SwarmConfig(n_neighbors=3), 1, 0)
