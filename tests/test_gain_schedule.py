"""Gain schedules (train/gain_schedule.py): zero weights are the baseline exactly, the
per-agent gains act as controllers with those gains would, the gains stay in their
documented range, ES trains and resumes a schedule that loads back as the policy it
trained, and configs that cannot train one are refused."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import count_kept

from agents import make_controller
from agents.follow import SCHEDULED_GAINS, InformedFollowerController
from swarm_envs.tasks import task_config
from train.config import train_config_from_mapping
from train.gain_schedule import (
    LENGTH_SHIFT,
    SCHEDULES,
    GainScheduledPolicy,
    check_schedule_record,
    schedule_record,
    scheduled_actions,
    scheduled_gains,
)

SMALL_ENV = {"n_agents": 5, "max_steps": 30, "n_neighbors": 3, "informed_fraction": 0.4}
SCHEDULE = SCHEDULES["follow"]


def informed_cfg(**kw):
    return task_config("informed", **{**SMALL_ENV, **kw})


def observations(cfg, swarms=8, steps=12, seed=0):
    """Per-agent observations of `follow` driving `swarms` swarms for `steps` steps."""
    from swarm_envs.envs.backends import make_core

    core = make_core(cfg, batch=swarms)
    core.reset(np.random.default_rng(seed))
    ctrl = make_controller("follow", cfg)
    seen = []
    for _ in range(steps):
        obs = np.asarray(core.observe()).reshape(swarms * cfg.n_agents, -1)
        seen.append(obs)
        action, _ = ctrl.predict(obs)
        core.step(action.reshape(swarms, cfg.n_agents, -1))
    return np.concatenate(seen).astype(np.float64)


def test_zero_weights_are_the_baseline_exactly():
    cfg = informed_cfg()
    obs = observations(cfg)
    ctrl = make_controller("follow", cfg)
    expected, _ = ctrl.predict(obs)
    zero = np.zeros(SCHEDULE.shape)
    np.testing.assert_array_equal(scheduled_actions(ctrl, SCHEDULE, zero, obs), expected)


def test_per_agent_gains_act_as_controllers_with_those_gains():
    cfg = informed_cfg()
    obs = observations(cfg)
    one = {"k_p": 1.0, "k_d": 0.5, "k_l": 3.0, "k_v": 1.0, "k_c": 2.0, "tether": 0.5}
    two = {"k_p": 2.0, "k_d": 1.0, "k_l": 10.0, "k_v": 3.0, "k_c": 4.0, "tether": 2.0}
    extra = {"lead": 1.0, "flock_lead": 0.2, "goal_pull": "saturated", "saturation": "box"}
    a = InformedFollowerController(cfg, **one, **extra)
    b = InformedFollowerController(cfg, **two, **extra)
    first = np.arange(len(obs)) % 2 == 0  # alternate agents take either set
    columns = {
        name: np.where(first[:, None], a.gains()[name], b.gains()[name]) for name in SCHEDULED_GAINS
    }
    mixed = a.actions_with_gains(obs, columns)
    np.testing.assert_allclose(mixed[first], a.predict(obs[first])[0], atol=1e-12)
    np.testing.assert_allclose(mixed[~first], b.predict(obs[~first])[0], atol=1e-12)
    with pytest.raises(ValueError, match="unknown gains"):
        a.actions_with_gains(obs, {"k_q": 1.0})


def test_scheduled_gains_stay_within_a_factor_e_and_half_a_length():
    cfg = informed_cfg()
    obs = observations(cfg)
    ctrl = make_controller("follow", cfg)
    own = ctrl.gains()
    rng = np.random.default_rng(3)
    for scale in (0.1, 100.0):  # inside the clip, and far beyond it
        w = rng.normal(0, scale, SCHEDULE.shape)
        gains = scheduled_gains(ctrl, SCHEDULE, w, obs)
        assert set(gains) == set(SCHEDULE.gain_names)
        for name in SCHEDULE.scaled:
            assert np.all(gains[name] >= own[name] / np.e * (1 - 1e-12))
            assert np.all(gains[name] <= own[name] * np.e * (1 + 1e-12))
        for name in SCHEDULE.shifted:
            assert np.all(gains[name] >= 0)
            assert np.all(np.abs(gains[name] - own[name]) <= LENGTH_SHIFT + 1e-12)
    # The bias row alone scales every agent's gain alike.
    bias = np.zeros_like(w)
    bias[0, SCHEDULE.gain_names.index("k_v")] = 0.5
    k_v = scheduled_gains(ctrl, SCHEDULE, bias, obs)["k_v"]
    np.testing.assert_allclose(k_v, own["k_v"] * np.exp(0.5))


def test_features_are_finite_and_one_row_per_agent():
    cfg = informed_cfg()
    obs = observations(cfg)
    f = SCHEDULE.features(make_controller("follow", cfg), obs)
    assert f.shape == (len(obs), len(SCHEDULE.feature_names))
    assert np.all(np.isfinite(f)) and np.all(f[:, 0] == 1.0)
    informed = obs[:, 2 * cfg.dim] > 0.5
    assert np.all(f[~informed, -1] == 0)  # an uninformed agent reads no goal distance
    assert np.any(f[informed, -1] > 0)


def test_a_record_from_another_schedule_is_refused():
    w = np.zeros(SCHEDULE.shape)
    record = schedule_record("follow", w)
    np.testing.assert_array_equal(check_schedule_record(record, "follow"), w)
    with pytest.raises(ValueError, match="retrain"):
        check_schedule_record({**record, "features": ["one"]}, "follow")
    with pytest.raises(ValueError, match="shaped"):
        check_schedule_record({**record, "weights": [[0.0]]}, "follow")
    with pytest.raises(ValueError, match="gain schedule"):
        check_schedule_record(record, "pd")


def schedule_config(**kw):
    base = {
        "algo": "ES",
        "mode": "shared",
        "env_id": "swarm_envs/SwarmInformed-v0",
        "env": {"task": "informed", **SMALL_ENV},
        "residual": "follow",
        "residual_corrects": "gains",
        "n_swarms": 2,
        "total_timesteps": 1,
        "net_arch": [8],
        "checkpoint_seconds": 0,
        "hyperparams": {"population": 4, "noise_std": 0.1, "learning_rate": 0.05},
    }
    base.update(kw)
    return train_config_from_mapping(base)


def test_configs_that_cannot_train_a_schedule_are_refused():
    schedule_config()  # the valid one
    with pytest.raises(ValueError, match="residual_corrects must be one of action, gains"):
        schedule_config(residual_corrects="weights")
    with pytest.raises(ValueError, match="name the baseline in residual"):
        schedule_config(residual=None)
    with pytest.raises(ValueError, match="evolution strategies"):
        schedule_config(algo="PPO", hyperparams={})
    with pytest.raises(ValueError, match="leave residual_scale at 1"):
        schedule_config(residual_scale=0.5)
    with pytest.raises(ValueError, match=r"baseline with a gain schedule \(follow\)"):
        schedule_config(residual="pd")


def test_es_trains_a_schedule_that_loads_as_the_policy_it_trained(tmp_path):
    from train.evaluate import load_sb3_model
    from train.evaluate.episodes import run_episodes
    from train.train import train

    def run(out, total, resume=False):
        tc = schedule_config(total_timesteps=total)
        return train(tc, out, progress_bar=False, tensorboard=False, verbose=0, resume=resume)

    one = run(tmp_path / "a", 1)
    per_generation = json.loads((tmp_path / "a" / "meta.json").read_text())["timesteps"]
    policy = load_sb3_model(one)
    assert isinstance(policy, GainScheduledPolicy)
    assert np.any(policy.weights != 0)  # one generation moved the schedule
    run(tmp_path / "a", 2 * per_generation + 1, resume=True)
    run(tmp_path / "b", 2 * per_generation + 1)
    a = load_sb3_model(tmp_path / "a" / "model.zip")
    b = load_sb3_model(tmp_path / "b" / "model.zip")
    np.testing.assert_array_equal(a.weights, b.weights)  # resumed = uninterrupted
    # The loaded policy acts as the schedule it records.
    cfg = informed_cfg()
    obs = observations(cfg)
    expected = scheduled_actions(make_controller("follow", cfg), SCHEDULE, b.weights, obs)
    np.testing.assert_allclose(b.predict(obs.astype(np.float32))[0], expected, atol=1e-6)
    result = run_episodes(b, cfg, 3, 0, record_episode=False)
    assert np.all(np.isfinite(result.returns))
    with pytest.raises(ValueError, match="last axis"):
        b.predict(obs[:, :-1].astype(np.float32))  # not an observation of its env


def test_rollouts_skip_ended_episodes_without_changing_any_return(monkeypatch):
    """A row-wise actor (the schedule's) is no longer observed or run for swarms whose
    episodes ended, and the core shrinks to the live swarms once at most a quarter are
    live; the candidates' returns and agent-steps are bit for bit those of the full
    batch, generation after generation."""
    from train.es import Rollouts, policy_model
    from train.gain_schedule import ScheduleActor

    kept = count_kept(monkeypatch)
    tc = schedule_config(env={"task": "informed", **SMALL_ENV, "max_steps": 60})
    cfg = tc.swarm_config()
    actor = ScheduleActor(policy_model(tc), make_controller("follow", cfg), "follow")
    thetas = np.random.default_rng(5).normal(0, 0.5, (3, actor.size))
    shrinking = Rollouts(cfg, actor, None, candidates=3, episodes=6)
    skipping = [shrinking.returns(thetas, (4, g)) for g in range(2)]
    assert kept and max(kept) <= 18 // 4  # it shrank (and again in the next generation)
    actor.rowwise = False  # every swarm observed and acted for until the last one ends
    full = Rollouts(cfg, actor, None, candidates=3, episodes=6)
    for g, (returns, steps) in enumerate(skipping):
        full_returns, full_steps = full.returns(thetas, (4, g))
        assert steps == full_steps
        assert returns.tobytes() == full_returns.tobytes()
