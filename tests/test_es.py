"""Evolution strategies (``algo: ES``, train/es.py): the update climbs, the candidates
meet the same episodes, the saved model acts as the trained parameters, resuming gives
the uninterrupted result, and bad configs are refused."""

from __future__ import annotations

import json

import numpy as np
import pytest

from train.config import train_config_from_mapping
from train.es import (
    ActorParameters,
    EvolutionStrategy,
    Rollouts,
    centred_ranks,
    check_es_hyperparams,
)

SMALL_ENV = {"n_agents": 3, "max_steps": 20, "n_neighbors": 2}


def es_config(**kw):
    base = {
        "algo": "ES",
        "mode": "shared",
        "env": SMALL_ENV,
        "n_swarms": 2,
        "total_timesteps": 1,
        "net_arch": [8, 8],
        "checkpoint_seconds": 0,
        "hyperparams": {"population": 4, "noise_std": 0.1, "learning_rate": 0.05},
    }
    base.update(kw)
    return train_config_from_mapping(base)


def test_hyperparameters_have_defaults_and_are_checked():
    assert check_es_hyperparams({})["population"] == 32
    assert check_es_hyperparams({"noise_std": "0.1"})["noise_std"] == 0.1
    for bad, word in (
        ({"population": 3}, "even"),
        ({"population": 0}, "even"),
        ({"noise_std": 0}, "noise_std"),
        ({"learning_rate": -1}, "learning_rate"),
        ({"weight_decay": -0.1}, "weight_decay"),
        ({"n_steps": 64}, "not an ES argument"),
        ({"population": True}, "population"),
    ):
        with pytest.raises(ValueError, match=word):
            check_es_hyperparams(bad)


def test_es_configs_refuse_what_es_has_not():
    with pytest.raises(ValueError, match="mode must be 'shared'"):
        es_config(mode="central")
    with pytest.raises(ValueError, match="eval_freq must be 0"):
        es_config(eval_freq=1000)
    with pytest.raises(ValueError, match="residual_warmup must be 0"):
        es_config(residual="pd", residual_warmup=100)
    with pytest.raises(ValueError, match="residual must be null or one of"):
        es_config(residual="nope")
    with pytest.raises(ValueError, match="not an ES argument"):
        es_config(hyperparams={"n_epochs": 3})


def test_centred_ranks_span_minus_half_to_half():
    r = centred_ranks(np.array([5.0, 1.0, 3.0, 9.0]))
    assert r.tolist() == pytest.approx([1 / 6, -0.5, -1 / 6, 0.5])


def test_the_update_climbs_a_smooth_objective():
    """On ``f(θ) = −|θ − t|²`` the rank-shaped antithetic estimate points uphill: the
    distance to ``t`` shrinks (and an update with the ranks reversed would grow it)."""
    target = np.linspace(-1.0, 1.0, 20)
    es = EvolutionStrategy(
        np.zeros(20),
        check_es_hyperparams(
            {"population": 16, "noise_std": 0.1, "learning_rate": 0.05, "weight_decay": 0.0}
        ),
        seed=3,
    )
    start = np.linalg.norm(es.theta - target)
    for _ in range(150):
        eps, thetas = es.candidates()
        f = -np.sum((thetas[:-1] - target) ** 2, axis=1)
        np.testing.assert_array_equal(thetas[-1], es.theta)  # the centre rides along
        es.update(eps, f)
    assert np.linalg.norm(es.theta - target) < 0.2 * start


def _policy(tc):
    from train.es import policy_model

    return policy_model(tc)


def test_actor_vector_round_trips_and_acts_as_sb3_predicts():
    tc = es_config()
    model = _policy(tc)
    actor = ActorParameters(model.policy)
    theta = np.random.default_rng(0).normal(0, 0.5, actor.size)
    actor.load(theta)
    np.testing.assert_allclose(actor.flat(), theta, rtol=0, atol=1e-7)  # float32 inside
    obs = np.random.default_rng(1).normal(0, 1, (7, model.observation_space.shape[0]))
    ours = actor.actions(theta[None], obs[None])[0]
    theirs, _ = model.predict(obs.astype(np.float32), deterministic=True)
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-5)
    assert np.abs(theirs).max() <= 1.0


def test_candidates_meet_the_same_episodes_and_zero_correction_is_the_baseline():
    from train.evaluate.episodes import run_episodes
    from train.residual import make_baseline

    tc = es_config(residual="pd", env={**SMALL_ENV, "max_steps": 40})
    cfg = tc.swarm_config()
    actor = ActorParameters(_policy(tc).policy)
    baseline = make_baseline("pd", cfg)
    rollouts = Rollouts(cfg, actor, baseline, candidates=3, episodes=4)
    thetas = np.zeros((3, actor.size))  # the zero vector: no correction
    thetas[1] = np.random.default_rng(2).normal(0, 0.3, actor.size)
    returns, steps = rollouts.returns(thetas, (7, 0, 0))
    assert returns[0] == returns[2]  # the same starts for every candidate
    assert returns[1] != returns[0]
    assert steps > 0
    ref = run_episodes(baseline, cfg, 4, np.random.SeedSequence((7, 0, 0)), record_episode=False)
    assert returns[0] == pytest.approx(ref.returns.mean(), abs=1e-9)


def test_training_writes_a_loadable_model_and_resumes_to_the_same_parameters(tmp_path):
    from train.evaluate import load_sb3_model
    from train.residual import ResidualPolicy
    from train.train import train

    def run(out, total, resume=False):
        tc = es_config(residual="pd", total_timesteps=total)
        return train(tc, out, progress_bar=False, tensorboard=False, verbose=0, resume=resume)

    one = run(tmp_path / "a", 1)  # one generation
    meta = json.loads((tmp_path / "a" / "meta.json").read_text())
    assert meta["status"] == "completed" and meta["algo"] == "ES"
    assert meta["es"]["generations"] == 1
    per_generation = meta["timesteps"]
    policy = load_sb3_model(one)
    assert isinstance(policy, ResidualPolicy)
    run(tmp_path / "a", 2 * per_generation + 1, resume=True)  # two more generations
    run(tmp_path / "b", 2 * per_generation + 1)  # three generations at once
    a = load_sb3_model(tmp_path / "a" / "model.zip").model.policy
    b = load_sb3_model(tmp_path / "b" / "model.zip").model.policy
    np.testing.assert_array_equal(ActorParameters(a).flat(), ActorParameters(b).flat())
    assert json.loads((tmp_path / "a" / "meta.json").read_text())["es"]["generations"] == 3
    from train.train import TrainSetupError

    with pytest.raises(TrainSetupError, match="give a larger total_timesteps"):
        run(tmp_path / "a", 2 * per_generation + 1, resume=True)  # nothing left to do


def test_a_stop_request_saves_and_says_how_to_continue(tmp_path):
    from train.interrupt import StopRequest, TrainingInterrupted
    from train.train import train

    stop = StopRequest()
    stop.request()
    with pytest.raises(TrainingInterrupted, match="--resume"):
        train(
            es_config(total_timesteps=10**9),
            tmp_path / "run",
            progress_bar=False,
            tensorboard=False,
            verbose=0,
            stop=stop,
            handle_signals=False,
        )
    meta = json.loads((tmp_path / "run" / "meta.json").read_text())
    assert meta["status"] == "interrupted"
    assert (tmp_path / "run" / "model.zip").is_file()


def test_candidates_meet_the_same_failures_on_a_perturbed_config():
    from train.residual import make_baseline

    perturbed = {
        **SMALL_ENV,
        "n_agents": 6,
        "perturbations": {"failed_fraction": [0.0, 0.5], "obs_noise": [0.0, 0.05]},
    }
    tc = es_config(residual="pd", env=perturbed)
    cfg = tc.swarm_config()
    actor = ActorParameters(_policy(tc).policy)
    rollouts = Rollouts(cfg, actor, make_baseline("pd", cfg), candidates=3, episodes=4)
    returns, _ = rollouts.returns(np.zeros((3, actor.size)), (5, 0, 0))
    assert np.isfinite(returns).all()
    rollouts.core.reset(np.random.default_rng(0))  # statuses of a new start, then blocks
    for k in range(3):
        block = np.zeros(12, bool)
        block[4 * k : 4 * (k + 1)] = True
        rollouts.core.reset(np.random.default_rng(np.random.SeedSequence((5, 0, 0))), which=block)
    status = rollouts.core.status.reshape(3, 4, -1)
    assert (status != status[0, 0, 0]).any()  # some agents failed
    np.testing.assert_array_equal(status[1], status[0])
    np.testing.assert_array_equal(status[2], status[0])


def test_rollouts_scale_the_correction_as_the_evaluated_policy_does():
    from train.evaluate.episodes import run_episodes
    from train.residual import ResidualPolicy, make_baseline

    tc = es_config(residual="pd", residual_scale=0.5, env={**SMALL_ENV, "max_steps": 40})
    cfg = tc.swarm_config()
    model = _policy(tc)
    actor = ActorParameters(model.policy)
    baseline = make_baseline("pd", cfg)
    theta = np.random.default_rng(3).normal(0, 0.3, actor.size)
    rollouts = Rollouts(cfg, actor, baseline, candidates=1, episodes=4, scale=0.5)
    returns, _ = rollouts.returns(theta[None], (7, 0, 0))
    actor.load(theta)
    policy = ResidualPolicy(model, baseline, 0.5)
    ref = run_episodes(policy, cfg, 4, np.random.SeedSequence((7, 0, 0)), record_episode=False)
    assert returns[0] == pytest.approx(ref.returns.mean(), abs=1e-4)
    full = Rollouts(cfg, actor, baseline, candidates=1, episodes=4)
    assert full.returns(theta[None], (7, 0, 0))[0][0] != pytest.approx(returns[0], abs=1e-4)
