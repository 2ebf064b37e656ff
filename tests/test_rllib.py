"""Ray RLlib training (train.rllib, ``swarm-train --engine rllib``): strict configs without Ray,
and (with the ``distributed`` extra) a two-iteration PPO run on a local 2-CPU Ray whose
checkpoint ``swarm-eval`` loads beside the analytic controller."""

from __future__ import annotations

import csv
import inspect
import json
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from swarm_envs.config import CONFIG_ROOT
from train import cli_eval, cli_train
from train.rllib.config import (
    PPO_TRAINING_ARGS,
    RLlibTrainConfig,
    load_rllib_config,
    rllib_config_from_mapping,
)
from train.rllib.policy import is_rllib_checkpoint, rllib_policy_name

RLLIB_CONFIGS = sorted((CONFIG_ROOT / "train").glob("*_rllib.yaml"))
NO_RAY = "Ray is not installed (pip install -e '.[distributed]')"

#: A tiny swarm and batch: each iteration is a few episodes of 20 steps.
SMOKE_ENV = {"n_agents": 3, "max_steps": 20, "n_neighbors": 2}
SMOKE = {
    "env": SMOKE_ENV,
    "seed": 0,
    "iterations": 2,
    "num_env_runners": 1,
    "num_envs_per_env_runner": 1,
    "num_learners": 0,
    "num_cpus": 2,
    "net_arch": [16, 16],
    "checkpoint_freq": 1,
    "hyperparams": {
        "train_batch_size_per_learner": 120,
        "minibatch_size": 120,
        "num_epochs": 1,
        "lr": 0.001,
    },
}


# --------------------------------------------------------------------------- configs (no Ray)


def test_shipped_rllib_configs_validate():
    assert {p.stem for p in RLLIB_CONFIGS} >= {"demo_rllib"}
    for path in RLLIB_CONFIGS:
        rc = load_rllib_config(path)
        assert rc.swarm_config().n_agents >= 1
        assert set(yaml.safe_load(path.read_text())) <= set(rc.to_dict())


@pytest.mark.parametrize(
    ("data", "fragment"),
    [
        ({"iteration": 3}, "unknown config key 'iteration'"),
        ({"algo": "SAC"}, "algo must be one of ('PPO',)"),
        ({"iterations": 0}, "iterations must be an integer >= 1"),
        ({"num_env_runners": -1}, "num_env_runners must be an integer >= 0"),
        ({"num_envs_per_env_runner": 1.5}, "num_envs_per_env_runner must be an integer"),
        ({"num_learners": True}, "num_learners must be an integer >= 0"),
        ({"num_gpus_per_learner": -1}, "num_gpus_per_learner must be a number >= 0"),
        ({"num_cpus": 0}, "num_cpus must be an integer >= 1"),
        ({"net_arch": []}, "net_arch must be a non-empty list"),
        ({"rollout_fragment_length": "long"}, "rollout_fragment_length must be 'auto'"),
        ({"vf_share_layers": "yes"}, "vf_share_layers must be true or false"),
        ({"hyperparams": {"learning_rate": 1e-3}}, "hyperparams.learning_rate is not a PPO"),
        ({"hyperparams": {"model": {}}}, "hyperparams.model is not a PPO"),
        ({"env": {"n_agent": 3}}, "unknown config key 'n_agent'"),
        ({"env": {"dt": -1.0}}, "dt must be in (0, inf)"),
    ],
)
def test_bad_rllib_configs_name_the_key(data, fragment):
    with pytest.raises(ValueError) as err:
        rllib_config_from_mapping(data)
    assert fragment in str(err.value)


def test_rllib_config_overrides_merge_sections(tmp_path: Path):
    rc = load_rllib_config(
        CONFIG_ROOT / "train" / "demo_rllib.yaml", {"hyperparams": {"lr": 0.01}, "seed": 4}
    )
    assert rc.hyperparams["lr"] == 0.01 and rc.hyperparams["num_epochs"] == 5 and rc.seed == 4
    with pytest.raises(ValueError, match="train config not found"):
        load_rllib_config(tmp_path / "missing.yaml")
    assert isinstance(rllib_config_from_mapping({}), RLlibTrainConfig)


def test_engine_is_inferred_from_the_config_name():
    assert cli_train._engine(None, "configs/train/demo_rllib.yaml") == "rllib"
    assert cli_train._engine(None, "configs/train/demo.yaml") == "sb3"
    assert cli_train._engine("sb3", "configs/train/demo_rllib.yaml") == "sb3"


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["--config", "configs/train/demo.yaml", "--address", "auto"], "only to --engine rllib"),
        (
            ["--engine", "rllib", "--config", "configs/train/demo_rllib.yaml", "iteration=2"],
            "unknown config key 'iteration'",
        ),
        (["--config", "configs/train/demo_rllib.yaml", "--num-cpus", "0"], "num_cpus must be"),
    ],
)
def test_cli_train_rejects_bad_input_with_exit_2(capsys, monkeypatch, args, fragment):
    monkeypatch.chdir(CONFIG_ROOT.parent)
    assert cli_train.main(args) == 2
    assert fragment in capsys.readouterr().err


def test_cli_train_rllib_without_ray_says_how_to_install(capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    config = str(CONFIG_ROOT / "train" / "demo_rllib.yaml")
    assert cli_train.main(["--engine", "rllib", "--config", config]) == 2
    assert 'pip install -e ".[distributed]"' in capsys.readouterr().err


def test_checkpoint_detection_and_names(tmp_path: Path):
    assert not is_rllib_checkpoint(tmp_path)
    assert not is_rllib_checkpoint(tmp_path / "missing")
    assert rllib_policy_name(tmp_path / "run" / "checkpoint") == "run"
    assert rllib_policy_name("ckpt") == "ckpt"


def test_swarm_eval_rejects_a_folder_that_is_no_checkpoint(tmp_path: Path, capsys):
    code = cli_eval.main(["--policies", str(tmp_path), "--out", str(tmp_path / "eval")])
    assert code == 2
    assert "not an RLlib checkpoint" in capsys.readouterr().err


# --------------------------------------------------------------------------- with Ray


@pytest.fixture(scope="module")
def ray_rllib():
    return pytest.importorskip("ray.rllib", reason=NO_RAY)


def test_ppo_training_args_exist_in_the_installed_rllib(ray_rllib):
    from ray.rllib.algorithms.algorithm_config import AlgorithmConfig
    from ray.rllib.algorithms.ppo import PPOConfig

    known = set(inspect.signature(PPOConfig.training).parameters)
    known |= set(inspect.signature(AlgorithmConfig.training).parameters)
    assert known >= PPO_TRAINING_ARGS


def test_multi_agent_adapter_passes_rllibs_checker(ray_rllib):
    from ray.rllib.utils.pre_checks.env import check_multiagent_environments

    from train.rllib.env import SwarmNavMultiAgentEnv, make_env

    env = make_env(SMOKE_ENV)
    assert isinstance(env, SwarmNavMultiAgentEnv)
    assert env.possible_agents == ["agent_0", "agent_1", "agent_2"]
    check_multiagent_environments(env)
    obs, _ = env.reset(seed=3)
    again, _ = make_env(SMOKE_ENV).reset(seed=3)
    assert list(obs) == env.agents and all(np.array_equal(obs[a], again[a]) for a in obs)
    zero = {a: np.zeros(2, np.float32) for a in env.agents}
    steps, done = 0, False
    while not done:
        _, rewards, terminated, truncated, _ = env.step(zero)
        assert len(set(rewards.values())) == 1  # cooperative reward
        steps, done = steps + 1, terminated["__all__"] or truncated["__all__"]
    assert steps == 20 and truncated["__all__"] and env.agents == []


@pytest.fixture(scope="module")
def trained_run(ray_rllib, tmp_path_factory):
    """Two PPO iterations through ``swarm-train --engine rllib`` on a local 2-CPU Ray."""
    root = tmp_path_factory.mktemp("rllib")
    config = root / "smoke_rllib.yaml"
    config.write_text(yaml.safe_dump(SMOKE, sort_keys=False))
    out = root / "smoke_rllib"
    assert cli_train.main(["--config", str(config), "--out", str(out), "--num-cpus", "2"]) == 0
    return out


def test_rllib_training_writes_checkpoints_and_metadata(trained_run: Path):
    out = trained_run
    assert is_rllib_checkpoint(out / "checkpoint")
    assert is_rllib_checkpoint(out / "checkpoints" / "iter_000001")
    assert (out / "checkpoint" / "learner_group" / "learner" / "rl_module" / "shared").is_dir()
    meta = json.loads((out / "meta.json").read_text())
    assert meta["engine"] == "rllib" and meta["policy_id"] == "shared"
    assert [h["iteration"] for h in meta["history"]] == [1, 2]
    rows = list(csv.DictReader((out / "progress.csv").open()))
    assert [int(r["env_steps"]) for r in rows] == [120, 240]
    assert [int(r["agent_steps"]) for r in rows] == [360, 720]
    assert yaml.safe_load((out / "env_config.yaml").read_text())["n_agents"] == 3


def test_swarm_eval_loads_the_rllib_checkpoint_beside_the_controller(trained_run: Path):
    out = trained_run / "eval"
    code = cli_eval.main(
        [
            "--config",
            str(trained_run / "env_config.yaml"),
            "--policies",
            "potential",
            str(trained_run / "checkpoint"),
            "--episodes",
            "3",
            "--out",
            str(out),
            "--no-gif",
            "--no-plots",
            "--no-progress",
        ]
    )
    assert code == 0
    results = json.loads((out / "results.json").read_text())
    policies = results["policies"]
    assert {"potential", "smoke_rllib"} <= set(policies)
    assert policies["smoke_rllib"]["mode"] == "shared"


def test_swarm_eval_loads_the_checkpoint_by_a_relative_path(
    trained_run: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
):
    # As docs/distributed.md writes it: runs/<name>/checkpoint, from the folder above runs/.
    monkeypatch.chdir(trained_run.parent)
    relative = f"{trained_run.name}/checkpoint"
    out = tmp_path / "eval"
    argv = ["--config", f"{trained_run.name}/env_config.yaml", "--policies", relative]
    argv += ["--episodes", "2", "--out", str(out), "--no-gif", "--no-plots", "--no-progress"]
    assert cli_eval.main(argv) == 0
    results = json.loads((out / "results.json").read_text())
    assert set(results["policies"]) == {"smoke_rllib"}


def test_rllib_policy_predicts_like_the_controllers(trained_run: Path):
    from train.rllib.policy import load_rllib_policy

    policy = load_rllib_policy(trained_run)  # the run folder finds checkpoint/
    obs_dim, d = policy.obs_dim, policy.act_dim
    obs = np.random.default_rng(0).uniform(-1, 1, (3, obs_dim)).astype(np.float32)
    action, state = policy.predict(obs)
    assert action.shape == (3, d) and action.dtype == np.float32 and state is None
    assert np.all(np.abs(action) <= 1.0)
    np.testing.assert_array_equal(action, policy.predict(obs)[0])  # deterministic mode
    batch, _ = policy.predict(np.stack([obs, obs]))  # leading batch axes are kept
    assert batch.shape == (2, 3, d)
    np.testing.assert_allclose(batch[1], action, rtol=1e-6, atol=1e-7)
    s1 = load_rllib_policy(trained_run / "checkpoint", seed=5).predict(obs, deterministic=False)
    s2 = load_rllib_policy(trained_run / "checkpoint", seed=5).predict(obs, deterministic=False)
    np.testing.assert_array_equal(s1[0], s2[0])  # seeded sampling
    as_dict, _ = policy.predict({f"agent_{i}": obs[i] for i in range(3)})
    np.testing.assert_array_equal(as_dict["agent_2"], action[2])
    with pytest.raises(ValueError, match="last axis must be"):
        policy.predict(np.zeros((3, obs_dim + 1), np.float32))
