"""A user's model defined outside the package (``examples/cucker_smale_model.py``): it
registers itself and then runs under every API on the numpy core, as the shipped models do.

The model is loaded from its file, as a user's script imports it; the other cores refuse
it up front with a reason, and the environments fall back to numpy."""

from __future__ import annotations

import functools
import importlib.util
import sys
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from helpers import strict_warnings
from pettingzoo.test import parallel_api_test, parallel_seed_test
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from agents import PotentialFieldController, baseline_names, make_controller
from swarm_envs import ENV_ID, models, swarm_nav_v0
from swarm_envs.config import SwarmConfig, as_dict, config_from_mapping, load_swarm_config
from swarm_envs.envs import backends
from swarm_envs.envs.cores.numpy import SwarmNavCore
from swarm_envs.envs.step_control import check_step_control, start_substeps
from swarm_envs.models import SHIPPED, model_names, model_spec
from swarm_envs.physics import simulate

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "cucker_smale_model.py"
NAME = "cucker_smale"


def load_example() -> ModuleType:
    """Import the example from its file, as a user's script does (registering it)."""
    spec = importlib.util.spec_from_file_location("cucker_smale_model", EXAMPLE)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module", autouse=True)
def cs() -> Iterator[ModuleType]:
    """The example, registered for this module's tests; the registry is restored after."""
    saved = dict(models._REGISTRY)
    yield load_example()
    models._REGISTRY.clear()
    models._REGISTRY.update(saved)
    sys.modules.pop("cucker_smale_model", None)


def cfg_of(**kw) -> SwarmConfig:
    return config_from_mapping(SwarmConfig, {"dynamics": NAME, **kw})


# --------------------------------------------------------------------------- the APIs


@pytest.mark.parametrize("dim", [2, 3])
def test_gymnasium_and_sb3_checkers_pass(dim: int):
    with strict_warnings():
        gym_check_env(gym.make(ENV_ID, dynamics=NAME, dim=dim, n_agents=4).unwrapped)
        sb3_check_env(gym.make(ENV_ID, dynamics=NAME, dim=dim, n_agents=4), warn=True)


def test_pettingzoo_api_and_seed_tests_pass():
    with strict_warnings():
        parallel_api_test(swarm_nav_v0.parallel_env(dynamics=NAME, n_agents=5), num_cycles=100)
        parallel_seed_test(functools.partial(swarm_nav_v0.parallel_env, dynamics=NAME))


def test_the_sb3_vec_env_repeats_a_seeded_rollout_and_trains():
    from stable_baselines3 import PPO

    def rollout() -> np.ndarray:
        venv = swarm_nav_v0.vec_env(3, dynamics=NAME, n_agents=4, dtype=np.float64)
        venv.seed(7)
        obs = [venv.reset()]
        rng = np.random.default_rng(1)
        for _ in range(30):
            obs.append(venv.step(rng.uniform(-1, 1, (12, 2)))[0])
        return np.stack(obs)

    a, b = rollout(), rollout()
    np.testing.assert_array_equal(a, b)
    assert np.isfinite(a).all()
    venv = swarm_nav_v0.vec_env(2, dynamics=NAME, n_agents=3, max_steps=20)
    PPO("MlpPolicy", venv, n_steps=16, batch_size=48, n_epochs=1, seed=0).learn(96)


def test_a_seed_fixes_the_rollout_and_another_seed_changes_it():
    def rollout(seed: int) -> np.ndarray:
        env = gym.make(ENV_ID, dynamics=NAME, n_agents=5)
        env.reset(seed=seed)
        env.action_space.seed(seed)
        return np.stack([env.step(env.action_space.sample())[0] for _ in range(20)])

    np.testing.assert_array_equal(rollout(3), rollout(3))
    assert not np.allclose(rollout(3), rollout(4))


# --------------------------------------------------------------------------- the physics


@pytest.mark.parametrize("K", [1.0, 15.0])  # 15: more than one substep per step
def test_zero_action_is_the_passive_model_in_the_rules_substeps(K: float):
    cfg = cfg_of(n_agents=7, model_params={NAME: {"K": K}})
    n = start_substeps(cfg)
    assert (n > 1) == (K > 1.0)
    core = SwarmNavCore(cfg)
    core.reset(np.random.default_rng(0))
    x0, v0 = core.x[0].copy(), core.v[0].copy()
    xs, substeps = [x0], []
    for _ in range(25):
        *_, stats = core.step(np.zeros_like(core.x))
        xs.append(core.x[0].copy())
        substeps.append(stats["substeps"][0])
    assert substeps == [n] * 25
    ref, _ = simulate(cfg.dynamics_params, x0, v0, dt=cfg.dt / n, steps=25 * n)
    np.testing.assert_allclose(np.stack(xs), ref[::n], rtol=0, atol=1e-12)


def test_the_velocity_disagreement_never_rises_without_action():
    cfg = cfg_of(n_agents=12, init_speed=2.0, model_params={NAME: {"K": 4.0, "beta": 0.6}})
    core = SwarmNavCore(cfg, batch=4)
    core.reset(np.random.default_rng(5))
    energy = [core.stats()["energy"]]
    for _ in range(40):
        energy.append(core.step(np.zeros_like(core.x))[3]["energy"])
    energy = np.stack(energy)
    assert (np.diff(energy, axis=0) <= 1e-12 * energy[:-1]).all()
    assert (energy[-1] < 0.5 * energy[0]).all()  # and the flock aligns


def test_simulate_dispatches_to_the_registered_simulator(cs):
    assert model_spec(NAME).simulate is cs.simulate_cucker_smale
    rng = np.random.default_rng(0)
    x0, v0 = rng.normal(size=(2, 6, 2)), rng.normal(size=(2, 6, 2))
    params = cs.CuckerSmaleParams(K=2.0)
    got = simulate(params, x0, v0, dt=0.05, steps=8)
    want = cs.simulate_cucker_smale(params, x0, v0, dt=0.05, steps=8)
    for a, b in zip(got, want, strict=True):
        assert a.shape == (9, 2, 6, 2)
        np.testing.assert_array_equal(a, b)
    with pytest.raises(ValueError, match="apply to SocialPotentialParams only"):
        simulate(params, x0, v0, dt=0.05, steps=1, control=np.zeros_like(x0))


# --------------------------------------------------------------------------- the config


def test_an_unknown_model_name_lists_the_registered_ones():
    for make in (
        lambda: gym.make(ENV_ID, dynamics="boids"),
        lambda: SwarmConfig(dynamics="boids"),
        lambda: model_spec("boids"),
    ):
        with pytest.raises(ValueError, match="dynamics must be one of") as err:
            make()
        for name in (*SHIPPED, NAME):
            assert repr(name) in str(err.value)
    assert NAME in model_names()


def test_its_section_is_built_validated_and_round_trips(cs):
    cfg = cfg_of(model_params={NAME: {"K": 2.0}})
    assert cfg.dynamics_params == cs.CuckerSmaleParams(K=2.0)  # the rest: class defaults
    assert cfg_of().dynamics_params == cs.CuckerSmaleParams()  # filled where absent
    assert config_from_mapping(SwarmConfig, as_dict(cfg)) == cfg
    assert hash(cfg) == hash(config_from_mapping(SwarmConfig, as_dict(cfg)))
    with pytest.raises(ValueError, match=r"unknown config key 'model_params\.cucker_smale\.k'"):
        cfg_of(model_params={NAME: {"k": 2.0}})
    with pytest.raises(ValueError, match=r"CuckerSmaleParams\.K must be in \(0, inf\)"):
        cfg_of(model_params={NAME: {"K": -1.0}})
    with pytest.raises(ValueError, match=r"model_params: unknown section 'zone'.*cucker_smale"):
        cfg_of(model_params={"zone": {}})
    with pytest.raises(ValueError, match="integrator='velocity_verlet' is not available"):
        cfg_of(integrator="velocity_verlet")  # ModelSpec.integrators: the default only
    with pytest.raises(ValueError, match="need dynamics='social_potential'"):
        cfg_of(perturbations={"failed_fraction": 0.2, "failure_mode": "frozen"})


def test_a_partial_section_given_as_an_override_merges_into_the_files(cs, tmp_path):
    path = tmp_path / "cs.yaml"
    path.write_text(f"dynamics: {NAME}\nmodel_params:\n  {NAME}: {{K: 3.0, sigma: 2.0}}\n")
    cfg = load_swarm_config(path, {"model_params": {NAME: {"beta": 0.1}}})
    assert cfg.dynamics_params == cs.CuckerSmaleParams(K=3.0, sigma=2.0, beta=0.1)


def test_its_step_size_rule_refuses_a_config_that_needs_more_than_the_cap():
    cfg = cfg_of(model_params={NAME: {"K": 200.0}}, max_substeps=4)
    with pytest.raises(ValueError, match=r"every step of dynamics='cucker_smale'.*max_substeps=4"):
        check_step_control(cfg)


# --------------------------------------------------------------------------- backends, agents


@pytest.mark.parametrize("backend", ["cutoff", "torch", "native"])
def test_the_other_cores_refuse_it_and_the_env_falls_back_to_numpy(monkeypatch, backend):
    cfg = cfg_of()
    reason = backends.unsupported(cfg, backend)
    assert reason == "supports dynamics='social_potential' only, got 'cucker_smale'"
    assert backends.unsupported(cfg, "numpy") is None
    monkeypatch.setattr(backends, "_WARNED", set())
    with pytest.warns(UserWarning, match=rf"backend '{backend}' cannot run .*; using 'numpy'"):
        env = swarm_nav_v0.parallel_env(dynamics=NAME, backend=backend)
    assert env.core.backend == "numpy"


def test_its_analytic_baseline_is_the_one_its_entry_names():
    env = gym.make(ENV_ID, dynamics=NAME, n_agents=4)
    assert isinstance(make_controller("analytic", env), PotentialFieldController)
    assert baseline_names(env)[0] == model_spec(NAME).baseline
