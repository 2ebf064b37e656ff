"""Training never loses work: checkpoints between updates, SIGINT/SIGTERM save and exit
130/143, ``--resume`` continues to the same model as an uninterrupted run."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from train import cli_train
from train.checkpoints import checkpoint_timesteps, latest_checkpoint, list_checkpoints
from train.config import train_config_from_mapping
from train.evaluate import load_sb3_model
from train.interrupt import (
    StopRequest,
    TrainingAborted,
    TrainingInterrupted,
    stop_on_signals,
)
from train.train import train

ROOT = Path(__file__).resolve().parents[1]
SMOKE_ENV = {"n_agents": 3, "max_steps": 30, "n_neighbors": 2}
PPO_HYPER = {"n_steps": 64, "batch_size": 64, "n_epochs": 1}
SAC_HYPER = {"learning_starts": 100, "batch_size": 32, "buffer_size": 2000}


def tiny(**kw) -> dict:
    base = {
        "algo": "PPO",
        "mode": "shared",
        "env": SMOKE_ENV,
        "n_swarms": 2,
        "total_timesteps": 1500,
        "net_arch": [16, 16],
        "torch_threads": 1,
        "hyperparams": PPO_HYPER,
    }
    base.update(kw)
    return base


class StopAfter(StopRequest):
    """A stop request that turns true at its ``n``-th reading (a signal, deterministically)."""

    def __init__(self, n: int, signum: int = signal.SIGINT) -> None:
        super().__init__()
        self.n = n
        self.wanted = signum

    @property
    def requested(self) -> bool:
        self.n -= 1
        if self.n < 0:
            self.request(self.wanted)
        return self.signum is not None


def params(path: Path) -> list[np.ndarray]:
    model = load_sb3_model(path)
    return [p.detach().numpy().copy() for p in model.policy.parameters()]


def assert_same_model(a: Path, b: Path) -> None:
    for p, q in zip(params(a), params(b), strict=True):
        np.testing.assert_array_equal(p, q)


def run(tc, out: Path, **kw) -> Path:
    return train(tc, out, progress_bar=False, tensorboard=False, verbose=0, **kw)


# --------------------------------------------------------------------------- in process


@pytest.mark.parametrize(
    ("algo", "mode", "hyper", "polls"),
    [
        ("PPO", "shared", PPO_HYPER, 3),
        ("PPO", "central", PPO_HYPER, 3),
        ("SAC", "shared", SAC_HYPER, 40),
    ],
)
def test_stopped_and_resumed_run_equals_an_uninterrupted_one(tmp_path, algo, mode, hyper, polls):
    tc = train_config_from_mapping(tiny(algo=algo, mode=mode, hyperparams=hyper))
    run(tc, tmp_path / "whole")

    with pytest.raises(TrainingInterrupted) as info:
        run(tc, tmp_path / "cut", stop=StopAfter(polls))
    stopped_at = info.value.timesteps
    assert 0 < stopped_at < tc.total_timesteps and info.value.signum == signal.SIGINT
    meta = json.loads((tmp_path / "cut" / "meta.json").read_text())
    assert meta["status"] == "interrupted" and meta["timesteps"] == stopped_at
    assert load_sb3_model(tmp_path / "cut" / "model.zip").num_timesteps == stopped_at
    ckpt = latest_checkpoint(tmp_path / "cut")
    assert ckpt is not None and checkpoint_timesteps(ckpt) == stopped_at
    expected = {"model.zip", "env.pkl", "rng.pkl", "state.json"}
    if algo == "SAC":
        expected.add("replay_buffer.pkl")
    assert expected <= {p.name for p in ckpt.iterdir()}

    run(tc, tmp_path / "cut", resume=True)
    meta = json.loads((tmp_path / "cut" / "meta.json").read_text())
    assert meta["status"] == "completed" and meta["timesteps"] >= tc.total_timesteps
    resumed = load_sb3_model(tmp_path / "cut" / "model.zip")
    assert resumed.num_timesteps == load_sb3_model(tmp_path / "whole" / "model.zip").num_timesteps
    assert_same_model(tmp_path / "cut" / "model.zip", tmp_path / "whole" / "model.zip")


def test_resume_continues_the_periodic_evaluation(tmp_path):
    tc = train_config_from_mapping(tiny(eval_freq=384, eval_episodes=1))
    with pytest.raises(TrainingInterrupted):
        run(tc, tmp_path, stop=StopAfter(3))  # after two evaluations
    first = json.loads((tmp_path / "meta.json").read_text())["evaluations"]
    run(tc, tmp_path, resume=True)
    evaluations = json.loads((tmp_path / "meta.json").read_text())["evaluations"]
    steps = [e["timesteps"] for e in evaluations]
    assert evaluations[: len(first)] == first and len(first) >= 1
    assert steps == sorted(set(steps)) and steps[-1] >= 1152  # none repeated, none skipped
    assert len(steps) == len(range(384, steps[-1] + 1, 384))


def test_periodic_checkpoints_by_time_keep_the_latest_few(tmp_path):
    # A cadence shorter than a rollout: a checkpoint at every rollout start.
    tc = train_config_from_mapping(tiny(checkpoint_seconds=1e-6, checkpoint_keep=2))
    run(tc, tmp_path)
    kept = list_checkpoints(tmp_path)
    assert len(kept) == 2
    assert checkpoint_timesteps(kept[-1]) == load_sb3_model(tmp_path / "model.zip").num_timesteps
    assert checkpoint_timesteps(kept[0]) == checkpoint_timesteps(kept[1]) - 6 * 64


def test_checkpoints_by_timesteps_and_defaults(tmp_path):
    tc = train_config_from_mapping(tiny(checkpoint_freq=700, checkpoint_keep=10))
    assert tc.checkpoint_seconds == 120.0  # on by default
    run(tc, tmp_path)
    steps = [checkpoint_timesteps(p) for p in list_checkpoints(tmp_path)]
    assert steps == [768, 1536]  # 700 → the next rollout start (384 per rollout); final


def test_a_partial_checkpoint_is_ignored_and_cleared(tmp_path):
    tc = train_config_from_mapping(tiny(total_timesteps=400))
    run(tc, tmp_path)
    good = latest_checkpoint(tmp_path)
    partial = tmp_path / "checkpoints" / "step_000000999999"
    partial.mkdir()  # a save killed half-way: no state.json
    (partial / "model.zip").write_bytes(b"truncated")
    assert latest_checkpoint(tmp_path) == good


def test_resume_refuses_a_finished_run_and_extends_on_request(tmp_path, capsys):
    config = tmp_path / "tiny.yaml"
    config.write_text(yaml.safe_dump(tiny(total_timesteps=400)))
    out = tmp_path / "run"
    assert cli_train.main(["--config", str(config), "--out", str(out), "--no-progress"]) == 0
    capsys.readouterr()
    assert cli_train.main(["--resume", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "the run has 768 timesteps" in err and "total_timesteps" in err
    assert err.count("\n") == 1
    assert cli_train.main(["--resume", str(out), "seed=3"]) == 2
    assert "cannot change seed (0 -> 3)" in capsys.readouterr().err
    assert cli_train.main(["--resume", str(out), "--config", str(config)]) == 2
    assert "drop --config" in capsys.readouterr().err
    code = cli_train.main(["--resume", str(out), "--no-progress", "total_timesteps=1000"])
    assert code == 0
    assert json.loads((out / "meta.json").read_text())["timesteps"] == 1152
    assert yaml.safe_load((out / "train_config.yaml").read_text())["total_timesteps"] == 1000


def test_resume_without_checkpoint_is_an_error(tmp_path, capsys):
    (tmp_path / "train_config.yaml").write_text(yaml.safe_dump(tiny()))
    assert cli_train.main(["--resume", str(tmp_path)]) == 2
    assert "no checkpoint in" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["train_config.yaml"]


def test_resume_names_a_damaged_checkpoint(tmp_path, capsys):
    run(train_config_from_mapping(tiny(total_timesteps=400)), tmp_path)
    ckpt = latest_checkpoint(tmp_path)
    (ckpt / "model.zip").write_text("garbage")
    assert cli_train.main(["--resume", str(tmp_path), "total_timesteps=2000"]) == 2
    err = capsys.readouterr().err
    assert f"cannot load checkpoint {ckpt}" in err and err.count("\n") == 1


def test_first_signal_requests_a_stop_and_a_second_aborts():
    before = signal.getsignal(signal.SIGINT)
    with stop_on_signals() as stop:
        assert not stop.requested
        signal.raise_signal(signal.SIGTERM)
        assert stop.requested and stop.signum == signal.SIGTERM
        with pytest.raises(TrainingAborted):
            signal.raise_signal(signal.SIGINT)
    assert signal.getsignal(signal.SIGINT) is before


# --------------------------------------------------------------------------- real signals


def _wait_for(predicate, proc: subprocess.Popen, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if proc.poll() is not None:
            raise AssertionError(f"swarm-train ended early: {proc.communicate()}")
        if time.monotonic() > deadline:
            proc.kill()
            raise AssertionError("no checkpoint appeared")
        time.sleep(0.05)


@pytest.mark.parametrize(("signum", "status"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_signal_saves_the_run_and_resume_continues_it(tmp_path, signum, status):
    config = tmp_path / "tiny.yaml"
    config.write_text(yaml.safe_dump(tiny(total_timesteps=10_000_000, checkpoint_freq=384)))
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "train.cli_train", "--no-progress"]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(
        [*cmd, "--config", str(config), "--out", str(out)],
        cwd=tmp_path,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    _wait_for(lambda: bool(list_checkpoints(out)), proc)  # after the first update
    proc.send_signal(signum)
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == status, stderr
    name = signal.Signals(signum).name
    assert stderr.count("\n") == 1 and f"stopped by {name}" in stderr
    assert f"swarm-train --resume {out}" in stderr
    meta = json.loads((out / "meta.json").read_text())
    ckpt = latest_checkpoint(out)
    assert meta["status"] == "interrupted" and ckpt is not None
    assert meta["timesteps"] == checkpoint_timesteps(ckpt) >= 384
    assert load_sb3_model(out / "model.zip").num_timesteps == meta["timesteps"]

    total = meta["timesteps"] + 1000
    resumed = subprocess.run(
        [*cmd, "--resume", str(out), f"total_timesteps={total}"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert resumed.returncode == 0, resumed.stderr
    meta = json.loads((out / "meta.json").read_text())
    assert meta["status"] == "completed" and meta["timesteps"] >= total
    # The same model as one run straight to that total.
    whole = tmp_path / "whole"
    run(train_config_from_mapping(tiny(total_timesteps=total, checkpoint_freq=384)), whole)
    assert_same_model(out / "model.zip", whole / "model.zip")
