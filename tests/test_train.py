"""Training: strict configs, smoke runs of both modes and both algorithms, reload + evaluate,
the CLIs, and (slow) the full demo."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from agents import PotentialFieldController
from swarm_envs.config import CONFIG_ROOT
from swarm_envs.envs.adapters.vec_env import SwarmNavVecEnv
from train import cli_train, demo
from train.config import (
    TrainConfig,
    load_train_config,
    parse_overrides,
    train_config_from_mapping,
)
from train.evaluate import evaluate_policies, load_sb3_model
from train.train import build_model, make_training_env, train

# SB3 runs; the RLlib ones (``*_rllib.yaml``) are checked in tests/test_rllib.py.
TRAIN_CONFIGS = sorted(
    p for p in (CONFIG_ROOT / "train").glob("*.yaml") if not p.stem.endswith("_rllib")
)

# A few thousand timesteps on a small swarm: seconds, not minutes.
SMOKE_ENV = {"n_agents": 3, "max_steps": 30, "n_neighbors": 2}


def smoke_config(**kw) -> TrainConfig:
    base = {
        "algo": "PPO",
        "mode": "shared",
        "env": SMOKE_ENV,
        "n_swarms": 2,
        "total_timesteps": 1024,
        "net_arch": [16, 16],
        "hyperparams": {"n_steps": 64, "batch_size": 64, "n_epochs": 1},
    }
    base.update(kw)
    return train_config_from_mapping(base)


# --------------------------------------------------------------------------- configs


def test_shipped_configs_load_by_name_from_any_folder(tmp_path: Path, monkeypatch):
    from train.sweep import load_sweep_config

    monkeypatch.chdir(tmp_path)  # no configs/ here: the package's are found
    by_path = load_train_config("configs/train/demo.yaml")
    assert load_train_config("demo") == by_path == load_train_config("train/demo.yaml")
    assert load_sweep_config("quick") == load_sweep_config("configs/sweeps/quick.yaml")
    (tmp_path / "demo.yaml").write_text("n_swarms: 5\n")  # a file here comes first
    assert load_train_config("demo.yaml").n_swarms == 5
    with pytest.raises(ValueError, match="train config not found: nope"):
        load_train_config("nope")


def test_shipped_train_configs_exist():
    names = {p.stem for p in TRAIN_CONFIGS}
    assert {"demo", "paper_navigation", "central", "sac_shared"} <= names


@pytest.mark.parametrize("path", TRAIN_CONFIGS, ids=lambda p: p.stem)
def test_every_shipped_train_config_validates(path: Path):
    tc = load_train_config(path)
    assert tc.swarm_config().n_agents >= 1
    assert set(yaml.safe_load(path.read_text())) <= set(tc.to_dict())


def _ppo_recipes() -> list[Any]:
    """Every shipped PPO recipe, and each benchmark entry's training config (seed 0)."""
    from train.benchmark.matrix import load_matrix

    recipes = [(p.stem, load_train_config(p)) for p in TRAIN_CONFIGS]
    recipes += [(e.name, e.train_config(0)) for e in load_matrix().entries]
    return [pytest.param(name, tc, id=name) for name, tc in recipes if tc.algo == "PPO"]


@pytest.mark.parametrize(("name", "tc"), _ppo_recipes())
def test_every_ppo_recipe_splits_its_rollout_into_whole_minibatches(name, tc: TrainConfig):
    """A rollout of ``n_steps`` × slots samples is cut into minibatches of ``batch_size``:
    a remainder would be a small, noisy last minibatch of every epoch (SB3 warns)."""
    n_steps = tc.hyperparams.get("n_steps", 2048)
    batch = tc.hyperparams.get("batch_size", 64)
    assert (n_steps * tc.n_slots) % batch == 0, (name, n_steps, tc.n_slots, batch)


def test_paper_navigation_train_config_uses_the_paper_scenario():
    tc = load_train_config(CONFIG_ROOT / "train" / "paper_navigation.yaml")
    assert tc.swarm_config().n_agents == 31
    assert tc.swarm_config().physics.C_g == 15.0


@pytest.mark.parametrize(
    ("data", "fragment"),
    [
        ({"algoo": "PPO"}, "unknown config key 'algoo'"),
        ({"algo": "DQN"}, "algo must be one of ('PPO', 'SAC', 'ES')"),
        ({"mode": "solo"}, "mode must be one of ('shared', 'central')"),
        ({"n_swarms": 0}, "n_swarms must be an integer >= 1"),
        ({"total_timesteps": 1.5}, "total_timesteps must be an integer"),
        ({"net_arch": []}, "net_arch must be a non-empty list"),
        ({"net_arch": [64, -1]}, "net_arch must be a non-empty list"),
        ({"hyperparams": {"learning_rat": 1e-3}}, "hyperparams.learning_rat is not a PPO"),
        ({"algo": "SAC", "hyperparams": {"n_epochs": 3}}, "hyperparams.n_epochs is not a SAC"),
        ({"hyperparams": {"seed": 3}}, "hyperparams.seed is not a PPO"),
        ({"env": {"n_agent": 3}}, "unknown config key 'n_agent'"),
        ({"env": {"dt": -1.0}}, "dt must be in (0, inf)"),
        ({"env_config": "no/such.yaml"}, "config file not found"),
        ({"torch_threads": 0}, "torch_threads must be null or an integer >= 1"),
        ({"encoder": "transformer"}, "encoder must be null or one of deepsets"),
        ({"encoder": "deepsets", "mode": "central"}, "it needs mode 'shared'"),
        ({"encoder": "deepsets", "algo": "ES", "hyperparams": {}}, "algo ES trains the flat"),
        ({"encoder_width": 0}, "encoder_width must be an integer >= 1"),
    ],
)
def test_bad_train_configs_name_the_key(data, fragment):
    with pytest.raises(ValueError) as info:
        train_config_from_mapping(data)
    assert fragment in str(info.value)


@pytest.mark.parametrize("text", ["2e6", "2.0e6", "2_000_000", "2000000.0", "2000000", "2E+6"])
def test_integer_keys_accept_integral_numbers_in_any_spelling(text):
    tc = load_train_config(
        CONFIG_ROOT / "train" / "demo.yaml",
        parse_overrides(
            [
                f"total_timesteps={text}",
                f"eval_freq={text}",
                f"checkpoint_freq={text}",
                f"hyperparams.batch_size={text}",
                "env.n_agents=6e0",
                "env.max_steps=1e3",
                "net_arch=[6.4e1, 64.0]",
                "torch_threads=1.0",
            ]
        ),
    )
    for key in ("total_timesteps", "eval_freq", "checkpoint_freq"):
        value = getattr(tc, key)
        assert value == 2_000_000 and type(value) is int, key
    assert tc.hyperparams["batch_size"] == 2_000_000 and type(tc.hyperparams["batch_size"]) is int
    assert tc.env == {"n_agents": 6, "max_steps": 1000}
    assert all(type(v) is int for v in tc.env.values())
    assert tc.swarm_config().n_agents == 6 and tc.swarm_config().max_steps == 1000
    assert tc.net_arch == (64, 64) and tc.torch_threads == 1
    # The saved config holds plain integers, and loads back to the same config.
    assert yaml.safe_load(yaml.safe_dump(tc.to_dict()))["total_timesteps"] == 2_000_000
    assert train_config_from_mapping(tc.to_dict()) == tc


@pytest.mark.parametrize(
    ("override", "key"),
    [
        ("total_timesteps=2.5", "total_timesteps"),
        ("total_timesteps=2.5e0", "total_timesteps"),
        ("eval_freq=1e-3", "eval_freq"),
        ("n_swarms=inf", "n_swarms"),
        ("seed=.nan", "seed"),
        ("checkpoint_keep=true", "checkpoint_keep"),
        ("torch_threads=1.5", "torch_threads"),
        ("net_arch=[64.5, 64]", "net_arch"),
        ("hyperparams.n_steps=2.5", "hyperparams.n_steps"),
        ("env.max_steps=2.5", "max_steps"),
        ("env.n_agents=six", "n_agents"),
    ],
)
def test_integer_keys_refuse_fractions_naming_the_key(override, key):
    with pytest.raises(ValueError, match=rf"{key} must be"):
        load_train_config(CONFIG_ROOT / "train" / "demo.yaml", parse_overrides([override]))


def test_overrides_parse_dotted_keys_and_yaml_values():
    got = parse_overrides(["total_timesteps=5000", "env.n_agents=4", "hyperparams.gamma=0.9"])
    assert got == {"total_timesteps": 5000, "env": {"n_agents": 4}, "hyperparams": {"gamma": 0.9}}
    with pytest.raises(ValueError, match="key=value"):
        parse_overrides(["total_timesteps"])


def test_overrides_merge_into_file_sections(tmp_path: Path):
    path = tmp_path / "t.yaml"
    path.write_text(yaml.safe_dump({"env": {"n_agents": 5, "dt": 0.05}, "seed": 1}))
    tc = load_train_config(path, {"env": {"n_agents": 3}})
    assert tc.env == {"n_agents": 3, "dt": 0.05}
    assert tc.seed == 1


# --------------------------------------------------------------------------- training


@pytest.mark.parametrize(
    ("algo", "mode", "hyper"),
    [
        ("PPO", "shared", {"n_steps": 64, "batch_size": 64, "n_epochs": 1}),
        ("PPO", "central", {"n_steps": 64, "batch_size": 64, "n_epochs": 1}),
        ("SAC", "shared", {"learning_starts": 100, "batch_size": 32, "buffer_size": 2000}),
        ("SAC", "central", {"learning_starts": 100, "batch_size": 32, "buffer_size": 2000}),
    ],
)
def test_smoke_training_writes_a_reloadable_model(tmp_path: Path, algo, mode, hyper):
    tc = smoke_config(algo=algo, mode=mode, hyperparams=hyper, total_timesteps=400)
    model_path = train(tc, tmp_path, progress_bar=False, tensorboard=False, verbose=0)
    assert model_path.is_file()
    for name in ("train_config.yaml", "env_config.yaml", "meta.json"):
        assert (tmp_path / name).is_file()
    meta = json.loads((tmp_path / "meta.json").read_text())
    assert meta["algo"] == algo and meta["mode"] == mode and meta["swarm_envs"]
    assert meta["status"] == "completed" and meta["timesteps"] >= 400
    assert (tmp_path / meta["checkpoint"] / "model.zip").is_file()  # the final state
    # The saved config reloads into the same run description.
    assert load_train_config(tmp_path / "train_config.yaml") == tc

    model = load_sb3_model(model_path)
    cfg = tc.swarm_config()
    results = evaluate_policies(
        {"learned": model, "potential": PotentialFieldController.from_config(cfg)},
        cfg,
        episodes=3,
        seed=5,
        progress=False,
    )
    learned = results["policies"]["learned"]
    assert np.isfinite(learned["mean_return"])
    assert learned["mode"] == mode


@pytest.mark.parametrize(
    ("algo", "hyper"),
    [
        ("PPO", {"n_steps": 64, "batch_size": 64, "n_epochs": 1}),
        ("SAC", {"learning_starts": 100, "batch_size": 32, "buffer_size": 2000}),
    ],
)
def test_a_policy_with_the_neighbour_set_encoder_trains_and_reloads(tmp_path: Path, algo, hyper):
    from train.encoders import NeighborSetEncoder

    tc = smoke_config(
        algo=algo, hyperparams=hyper, total_timesteps=400, encoder="deepsets", encoder_width=8
    )
    train(tc, tmp_path, progress_bar=False, tensorboard=False, verbose=0)
    assert load_train_config(tmp_path / "train_config.yaml") == tc
    model = load_sb3_model(tmp_path / "model.zip")
    extractor = (
        model.policy.actor.features_extractor
        if algo == "SAC"
        else (model.policy.features_extractor)
    )
    assert isinstance(extractor, NeighborSetEncoder)
    cfg = tc.swarm_config()
    obs = np.random.default_rng(0).normal(size=(5, model.observation_space.shape[0]))
    obs = obs.astype(np.float32)
    own, slots = obs[:, : extractor.own], obs[:, extractor.own :].reshape(5, -1, extractor.block)
    slots[..., extractor.mask] = 1.0  # every slot a real neighbour
    order = np.random.default_rng(1).permutation(cfg.n_neighbors)
    a = model.predict(np.concatenate([own, slots.reshape(5, -1)], axis=1), deterministic=True)
    shuffled = slots[:, order].reshape(5, -1)
    b = model.predict(np.concatenate([own, shuffled], axis=1), deterministic=True)
    np.testing.assert_allclose(a[0], b[0], atol=1e-5)  # the neighbours' order is not an input


def test_the_neighbour_set_encoder_ignores_padding_slots():
    import gymnasium as gym
    import torch

    from train.encoders import NeighborSetEncoder

    space = gym.spaces.Box(-10.0, 10.0, (2 + 3 * 3,), np.float32)
    enc = NeighborSetEncoder(space, own=2, k=3, block=3, mask=2, width=4)
    obs = torch.zeros(2, 11)
    obs[:, 2:5] = torch.tensor([0.4, -0.2, 1.0])  # one real neighbour
    obs[1, 5:8] = torch.tensor([5.0, 5.0, 0.0])  # padding with garbage: ignored
    out = enc(obs)
    torch.testing.assert_close(out[0], out[1])
    none = enc(torch.zeros(1, 11))  # no neighbour at all: zero codes
    assert torch.count_nonzero(none) == 0
    with pytest.raises(ValueError, match="is not 2 own entries and 3 slots of 4"):
        NeighborSetEncoder(space, own=2, k=3, block=4, mask=2)


def test_training_is_deterministic_for_a_seed(tmp_path: Path):
    tc = smoke_config(total_timesteps=256, torch_threads=1)
    params = []
    for run in ("a", "b"):
        train(tc, tmp_path / run, progress_bar=False, tensorboard=False, verbose=0)
        model = load_sb3_model(tmp_path / run / "model.zip")
        params.append([p.detach().numpy().copy() for p in model.policy.parameters()])
    for p, q in zip(params[0], params[1], strict=True):
        np.testing.assert_array_equal(p, q)


@pytest.mark.parametrize(("threads", "expected"), [("default", 1), (2, 2)])
def test_training_runs_on_the_configs_torch_threads(tmp_path: Path, threads, expected):
    import torch

    before = torch.get_num_threads()
    seen = []
    kw = {} if threads == "default" else {"torch_threads": threads}
    tc = smoke_config(total_timesteps=64, **kw)
    assert tc.torch_threads == expected
    callback = pytest.importorskip("stable_baselines3.common.callbacks")

    class Probe(callback.BaseCallback):
        def _on_step(self) -> bool:
            seen.append(torch.get_num_threads())
            return True

    import train.train as trainer

    real = trainer.SwarmStatsCallback

    def with_probe(cfg):
        return callback.CallbackList([real(cfg), Probe()])

    try:
        trainer.SwarmStatsCallback = with_probe
        train(tc, tmp_path, progress_bar=False, tensorboard=False, verbose=0)
    finally:
        trainer.SwarmStatsCallback = real
        torch.set_num_threads(before)
    assert seen and set(seen) == {expected}
    assert json.loads((tmp_path / "meta.json").read_text())["torch_threads"] == expected


def test_shared_mode_uses_one_slot_per_agent():
    tc = smoke_config(n_swarms=3)
    venv = make_training_env(tc)
    assert venv.num_envs == 3 * SMOKE_ENV["n_agents"]
    model = build_model(tc, venv)
    assert model.observation_space.shape == venv.observation_space.shape
    venv.close()


def test_stats_callback_reads_the_batched_envs_arrays_as_the_infos_hold_them(monkeypatch):
    # Shared mode: the means come from SwarmNavVecEnv.last_stats; they must equal the
    # loop over the infos (the path every other env takes).
    from stable_baselines3.common.logger import configure

    from train.callbacks import SwarmStatsCallback

    tc = smoke_config(n_swarms=3)
    venv = make_training_env(tc)
    venv.seed(0)
    venv.reset()
    rng = np.random.default_rng(0)
    for batched in (True, False):
        model = build_model(tc, venv)
        model.set_logger(configure(None, []))
        callback = SwarmStatsCallback(tc.swarm_config())
        callback.init_callback(model)
        assert callback._batched_env() is venv
        if not batched:
            monkeypatch.setattr(callback, "_batched_env", lambda: None)
        _, _, dones, infos = venv.step(rng.uniform(-1, 1, (venv.num_envs, 2)))
        callback.update_locals({"infos": infos, "dones": dones})
        callback.on_step()
        values = dict(model.logger.name_to_value)
        assert {f"swarm/{k}" for k in venv.last_stats} <= set(values)
        expected = {k: float(np.mean(v)) for k, v in venv.last_stats.items()}
        for key, value in expected.items():
            assert values[f"swarm/{key}"] == pytest.approx(value, rel=1e-6, abs=1e-9)
    venv.close()


def test_training_env_reports_episodes_without_a_monitor():
    from stable_baselines3.common.vec_env import VecMonitor

    shared = make_training_env(smoke_config(n_swarms=2))
    assert isinstance(shared, SwarmNavVecEnv)  # reports "episode" itself
    central = make_training_env(smoke_config(mode="central", n_swarms=2))
    assert isinstance(central, VecMonitor)
    shared.close()
    central.close()


@pytest.mark.parametrize("algo", ["PPO", "SAC"])
def test_done_slots_only_keeps_what_sb3_buffers(algo):
    # The override visits the ended slots only; on infos as monitors write them
    # ("episode" where an episode ended, "is_success" anywhere) the buffers must hold
    # exactly what SB3's own loop over every slot puts there.
    from train.config import algorithm_class
    from train.train import done_slots_only

    hyperparams = {"buffer_size": 1000} if algo == "SAC" else {"n_steps": 64, "batch_size": 64}
    tc = smoke_config(n_swarms=2, algo=algo, hyperparams=hyperparams)
    venv = make_training_env(tc)
    base = algorithm_class(algo)
    fast = done_slots_only(base)
    assert issubclass(fast, base) and fast.__name__ == base.__name__
    assert done_slots_only(base) is fast  # made once
    rng = np.random.default_rng(0)
    models = [build_model(tc, venv) for _ in range(2)]
    models[0].__class__ = base
    models[1].__class__ = fast
    for model in models:
        model._setup_learn(10, None)
    for _ in range(20):
        dones = rng.random(venv.num_envs) < 0.3
        infos = [
            {"episode": {"r": float(rng.normal()), "l": int(rng.integers(1, 9)), "t": 0.0}}
            if done
            else {}
            for done in dones
        ]
        for info in infos:
            if rng.random() < 0.5:
                info["is_success"] = bool(rng.random() < 0.5)
        for model in models:
            model._update_info_buffer(infos, dones)
    assert list(models[0].ep_info_buffer) == list(models[1].ep_info_buffer)
    assert list(models[0].ep_success_buffer) == list(models[1].ep_success_buffer)
    assert len(models[1].ep_success_buffer) > 0
    no_dones = [{"episode": {"r": 1.0, "l": 1, "t": 0.0}}] * 3
    models[1]._update_info_buffer(no_dones)  # without dones: SB3's own loop
    assert list(models[1].ep_info_buffer)[-3:] == [info["episode"] for info in no_dones]
    venv.close()


def test_periodic_evaluation_logs_and_keeps_the_best_model(tmp_path: Path):
    tc = smoke_config(total_timesteps=512, eval_freq=256, eval_episodes=2)
    train(tc, tmp_path, progress_bar=False, tensorboard=True, verbose=0)
    meta = json.loads((tmp_path / "meta.json").read_text())
    # SB3 finishes its last rollout past total_timesteps: at least one eval per 256 steps.
    steps = [e["timesteps"] for e in meta["evaluations"]]
    assert len(steps) >= 2 and steps == sorted(steps)
    assert (tmp_path / "best_model.zip").is_file()
    assert any((tmp_path / "tensorboard").rglob("events.out.tfevents*"))


# --------------------------------------------------------------------------- CLIs


def test_cli_train_rejects_bad_config_with_exit_2(tmp_path: Path, capsys):
    path = tmp_path / "t.yaml"
    path.write_text(yaml.safe_dump({"algo": "PPO", "n_swarm": 2}))
    assert cli_train.main(["--config", str(path)]) == 2
    assert "unknown config key 'n_swarm'" in capsys.readouterr().err


def test_cli_train_runs_with_overrides(tmp_path: Path):
    path = tmp_path / "t.yaml"
    path.write_text(yaml.safe_dump(smoke_config().to_dict()))
    out = tmp_path / "run"
    code = cli_train.main(
        ["--config", str(path), "--out", str(out), "--no-progress", "total_timesteps=128"]
    )
    assert code == 0
    assert load_train_config(out / "train_config.yaml").total_timesteps == 128


def test_demo_compare_criteria():
    base = {
        "mean_return": 8.0,
        "success_rate": 1.0,
        "mean_time_to_goal": 12.0,
        "collisions_per_episode": 0.1,
    }
    better = {**base, "mean_return": 12.0, "mean_time_to_goal": 4.0}
    assert all(ok for _, ok, _ in demo.compare(better, base))
    worse = {**better, "success_rate": 0.9}
    assert [ok for _, ok, _ in demo.compare(worse, base)] == [True, False, True, True]
    never = {**better, "mean_time_to_goal": None}
    assert not demo.compare(never, base)[2][1]


def test_demo_pipeline_smoke(tmp_path: Path):
    path = tmp_path / "t.yaml"
    path.write_text(yaml.safe_dump(smoke_config(total_timesteps=256).to_dict()))
    code = demo.main(
        ["--config", str(path), "--out", str(tmp_path / "demo"), "--episodes", "3", "--no-progress"]
    )
    assert code in (0, 1)  # an untrained policy may lose; the files must be there
    for name in ("results.json", "summary.md", "report.md", "curves.png", "model.zip"):
        assert (tmp_path / "demo" / name).is_file()
    results = json.loads((tmp_path / "demo" / "results.json").read_text())
    assert set(results["policies"]) == {"potential", "pd", "zero", "random", "learned"}
    assert results["baselines"] == ["potential", "pd"]
    report = (tmp_path / "demo" / "report.md").read_text()
    best = results["best_baseline"]
    assert best in ("potential", "pd") and f"the best baseline, `{best}`" in report
    assert "Lower bound on the time to goal" in report


@pytest.mark.slow
def test_full_demo_learned_policy_beats_the_best_baseline(tmp_path: Path):
    """The main job, as `make demo` runs it: the verdict on 100 held-out episodes."""
    code = demo.main(["--out", str(tmp_path / "demo"), "--no-progress"])
    report = (tmp_path / "demo" / "report.md").read_text()
    assert code == 0, report
    meta = json.loads((tmp_path / "demo" / "meta.json").read_text())
    assert meta["torch_threads"] == 1 and meta["status"] == "completed"


@pytest.mark.parametrize("dynamics", ["zone", "piecewise", "lagrangian"])
def test_smoke_training_on_every_dynamics_with_its_baseline_logged(tmp_path: Path, dynamics):
    tc = smoke_config(
        env={**SMOKE_ENV, "dynamics": dynamics},
        total_timesteps=256,
        eval_freq=256,
        eval_episodes=1,
    )
    train(tc, tmp_path, progress_bar=False, tensorboard=False, verbose=0)
    meta = json.loads((tmp_path / "meta.json").read_text())
    assert meta["evaluations"] and np.isfinite(meta["evaluations"][-1]["learned"]["mean_return"])
    assert load_train_config(tmp_path / "train_config.yaml").swarm_config().dynamics == dynamics


def test_progress_is_a_line_per_interval_without_a_terminal(tmp_path: Path, monkeypatch, capsys):
    import train.train as trainer

    monkeypatch.setattr(trainer, "PROGRESS_LINE_SECONDS", 0.0)  # every step
    hyper = {"n_steps": 32, "batch_size": 64, "n_epochs": 1}
    tc = smoke_config(hyperparams=hyper, total_timesteps=256)
    train(tc, tmp_path, progress_bar=True, tensorboard=False, verbose=0)
    lines = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("progress: ")]
    assert len(lines) >= 3
    done = [
        int(re.match(r"progress: ([\d,]+) / 256 timesteps", ln)[1].replace(",", "")) for ln in lines
    ]
    assert done == sorted(done) and done[-1] >= 256  # the last line: the run's end
    assert all("timesteps/s" in ln for ln in lines)


def test_no_progress_prints_no_progress_lines(tmp_path: Path, monkeypatch, capsys):
    import train.train as trainer

    monkeypatch.setattr(trainer, "PROGRESS_LINE_SECONDS", 0.0)
    tc = smoke_config(hyperparams={"n_steps": 32, "batch_size": 64}, total_timesteps=64)
    train(tc, tmp_path, progress_bar=False, tensorboard=False, verbose=0)
    assert "progress: " not in capsys.readouterr().out
