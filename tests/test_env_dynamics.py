"""SwarmNav with every ``dynamics``: the official checkers, zero action = passive model,
each model's invariants seen through the environment, and the matching baselines."""

from __future__ import annotations

import functools
import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from helpers import strict_warnings
from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test, seed_test
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from agents import (
    ANALYTIC,
    GoalForceController,
    InformedIndividualController,
    LyapunovTargetController,
    make_controller,
)
from agents.vanualailai_sharma import target_potential
from swarm_envs import ENV_ID, swarm_nav_v0
from swarm_envs.config import DYNAMICS, SwarmConfig, config_from_mapping
from swarm_envs.envs.cores.numpy import SwarmNavCore
from swarm_envs.physics import (
    LagrangianParams,
    PiecewiseParams,
    ZoneParams,
    simulate_lagrangian,
    simulate_piecewise,
    simulate_zone,
)
from swarm_envs.physics.lagrangian import START_GAP, lagrangian_value, min_pair_clearance
from train.evaluate import evaluate_policies

NEW = ("zone", "piecewise", "lagrangian")


def cfg_of(dynamics: str, **kw) -> SwarmConfig:
    return config_from_mapping(SwarmConfig, {"dynamics": dynamics, **kw})


# --------------------------------------------------------------------------- checkers


@pytest.mark.parametrize("dynamics", DYNAMICS)
@pytest.mark.parametrize("dim", [2, 3])
def test_gymnasium_and_sb3_checkers_pass(dynamics: str, dim: int):
    with strict_warnings():
        gym_check_env(gym.make(ENV_ID, dynamics=dynamics, dim=dim, n_agents=4).unwrapped)
        sb3_check_env(gym.make(ENV_ID, dynamics=dynamics, dim=dim, n_agents=4), warn=True)


@pytest.mark.parametrize("dynamics", NEW)
def test_pettingzoo_api_and_seed_tests_pass(dynamics: str):
    with strict_warnings():
        parallel_api_test(swarm_nav_v0.parallel_env(dynamics=dynamics, n_agents=5), num_cycles=200)
        api_test(swarm_nav_v0.env(dynamics=dynamics, n_agents=4), num_cycles=50)
        parallel_seed_test(functools.partial(swarm_nav_v0.parallel_env, dynamics=dynamics))
        seed_test(functools.partial(swarm_nav_v0.env, dynamics=dynamics), num_cycles=50)


@pytest.mark.parametrize("dynamics", NEW)
def test_vec_env_rollouts_repeat_for_a_seed_and_match_the_parallel_env(dynamics: str):
    def rollout() -> np.ndarray:
        venv = swarm_nav_v0.vec_env(3, dynamics=dynamics, n_agents=4, dtype=np.float64)
        venv.seed(7)
        obs = [venv.reset()]
        rng = np.random.default_rng(1)
        for _ in range(60):
            obs.append(venv.step(rng.uniform(-1, 1, (12, 2)))[0])
        return np.stack(obs)

    a, b = rollout(), rollout()
    np.testing.assert_array_equal(a, b)
    assert np.isfinite(a).all()


def test_unknown_dynamics_is_a_value_error_naming_the_choices():
    with pytest.raises(ValueError, match="dynamics must be one of"):
        gym.make(ENV_ID, dynamics="boids")
    with pytest.raises(ValueError, match=r"unknown config key 'zone\.r_x'"):
        swarm_nav_v0.parallel_env(dynamics="zone", zone={"r_x": 1.0})


def test_a_partial_model_section_keeps_the_task_defaults():
    cfg = cfg_of("zone", zone={"r_o": 2.0})
    assert cfg.zone == ZoneParams.navigation(r_o=2.0)
    assert cfg_of("piecewise").piecewise == PiecewiseParams.navigation()


def test_lagrangian_per_agent_parameters_must_match_n_agents():
    with pytest.raises(ValueError, match=r"lagrangian.*gamma has shape"):
        cfg_of("lagrangian", n_agents=4, lagrangian={"gamma": [1.0, 2.0]})
    cfg = cfg_of("lagrangian", n_agents=2, lagrangian={"gamma": [1.0, 2.0]})
    assert cfg.lagrangian.gamma == (1.0, 2.0)


def test_lagrangian_start_that_cannot_fit_is_a_clear_error():
    # Below the radius at which the bins can never fit, the config itself refuses it.
    with pytest.raises(ValueError, match=r"init_radius must be in"):
        cfg_of("lagrangian", n_agents=20, init_radius=0.1)
    # Above it but too tight for random starts: the core (no env-level trial) says why.
    cfg = cfg_of("lagrangian", n_agents=20, init_radius=0.2)
    core = SwarmNavCore(cfg)
    with pytest.raises(ValueError, match=r"could not place 20 agents with their bins"):
        core.reset(np.random.default_rng(0))


def test_lagrangian_starts_keep_a_gap_between_every_pair_of_bins():
    # Nearly touching bins (R_ij near 0) would hold the swarm where it starts: the step
    # rules find no substep. Of 4,000 random starts about 30 would come that close.
    cfg = cfg_of("lagrangian")
    core = SwarmNavCore(cfg, batch=4000)
    core.reset(np.random.default_rng(2026))
    x = np.asarray(core.x)
    dist = np.linalg.norm(x[:, :, None] - x[:, None], axis=-1) + np.eye(cfg.n_agents) * 1e9
    r_sum = cfg.lagrangian.arrays(cfg.n_agents, cfg.dim)["r_sum"]
    assert (dist >= (1 + START_GAP) * r_sum - 1e-12).all()
    # ... and every swarm moves in its first step (none is held in place).
    x0 = x.copy()
    core.step(np.zeros_like(x))
    assert (np.abs(np.asarray(core.x) - x0).max(axis=(1, 2)) > 0).all()


# --------------------------------------------------------------------------- zero action


def zero_rollout(cfg: SwarmConfig, steps: int, seed: int = 0) -> tuple[np.ndarray, ...]:
    core = SwarmNavCore(cfg)
    core.reset(np.random.default_rng(seed))
    x0, v0 = core.x[0].copy(), core.v[0].copy()
    xs = [x0]
    for _ in range(steps):
        core.step(np.zeros_like(core.x))
        xs.append(core.x[0].copy())
    return x0, v0, np.stack(xs)


def test_zero_action_is_the_passive_zone_model():
    cfg = cfg_of("zone", zone={"param_spread": 0.0})
    x0, v0, xs = zero_rollout(cfg, 40)
    ref, _ = simulate_zone(cfg.zone, x0, v0, dt=cfg.dt, steps=40)
    np.testing.assert_allclose(xs, ref, rtol=0, atol=1e-12)


def test_zero_action_is_the_passive_piecewise_model():
    cfg = cfg_of("piecewise", piecewise={"noise": 0.0})
    x0, v0, xs = zero_rollout(cfg, 40)
    ref, _ = simulate_piecewise(cfg.piecewise, x0, v0, dt=cfg.dt, steps=40)
    np.testing.assert_allclose(xs, ref, rtol=0, atol=1e-12)


def test_zero_action_is_the_passive_lagrangian_model():
    cfg = cfg_of("lagrangian")
    x0, v0, xs = zero_rollout(cfg, 40)
    ref, vref = simulate_lagrangian(cfg.lagrangian, x0, v0, dt=cfg.dt, steps=40)
    np.testing.assert_allclose(xs, ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(v0, vref[0], rtol=0, atol=1e-12)


@pytest.mark.parametrize("dynamics", NEW)
def test_goal_in_physics_changes_the_passive_model(dynamics: str):
    _, _, free = zero_rollout(cfg_of(dynamics), 30)
    _, _, driven = zero_rollout(cfg_of(dynamics, goal_in_physics=True), 30)
    assert not np.allclose(free[-1], driven[-1])


# --------------------------------------------------------------------------- invariants


def test_zone_speed_is_constant_and_turns_never_exceed_the_maximum_under_any_action():
    cfg = cfg_of("zone", n_agents=12)
    core = SwarmNavCore(cfg, batch=4)
    core.reset(np.random.default_rng(3))
    speed0 = np.linalg.norm(core.v, axis=-1)
    rng = np.random.default_rng(4)
    max_turn = np.asarray(core.dynamics.agent_params.max_turn)
    for _ in range(100):
        h0 = core.v / np.linalg.norm(core.v, axis=-1, keepdims=True)
        core.step(rng.uniform(-1, 1, core.x.shape))
        h1 = core.v / np.linalg.norm(core.v, axis=-1, keepdims=True)
        np.testing.assert_allclose(np.linalg.norm(core.v, axis=-1), speed0, rtol=1e-12)
        turn = np.arccos(np.clip(np.einsum("bik,bik->bi", h0, h1), -1.0, 1.0))
        assert np.all(turn <= max_turn + 1e-9)


def test_zone_per_agent_parameters_are_drawn_per_swarm_at_reset():
    core = SwarmNavCore(cfg_of("zone"), batch=3)
    core.reset(np.random.default_rng(0))
    speed = np.linalg.norm(core.v, axis=-1)
    assert speed.std() > 0  # σ = 0.05 spread
    np.testing.assert_allclose(speed, core.dynamics.agent_params.speed)


def test_piecewise_noise_is_seeded_and_differs_between_seeds():
    def final(seed: int) -> np.ndarray:
        core = SwarmNavCore(cfg_of("piecewise"))
        core.reset(np.random.default_rng(seed))
        start = core.x.copy()
        for _ in range(20):
            core.step(np.zeros_like(core.x))
        return core.x - start

    np.testing.assert_array_equal(final(5), final(5))
    assert not np.allclose(final(5), final(6))


def test_lagrangian_bins_never_overlap_even_under_adversarial_actions():
    cfg = cfg_of("lagrangian", n_agents=8, init_radius=1.0)
    core = SwarmNavCore(cfg, batch=2)
    core.reset(np.random.default_rng(0))
    for _ in range(40):  # every agent pushed at full force toward the centroid
        centre = core.x.mean(axis=1, keepdims=True)
        push = centre - core.x
        core.step(push / np.maximum(np.abs(push).max(axis=-1, keepdims=True), 1e-9))
        assert np.all(min_pair_clearance(core.x, cfg.lagrangian) > 0)
        assert np.all(core.stats()["collisions"] == 0)


def test_lagrangian_energy_statistic_is_l_and_never_increases_without_action():
    cfg = cfg_of("lagrangian", n_agents=8)
    core = SwarmNavCore(cfg, batch=2)
    core.reset(np.random.default_rng(2))
    values = [core.stats()["energy"]]
    for _ in range(60):
        _, _, _, stats = core.step(np.zeros_like(core.x))
        values.append(stats["energy"])
    values = np.array(values)
    np.testing.assert_allclose(values[-1], lagrangian_value(core.x, cfg.lagrangian))
    assert np.all(np.diff(values, axis=0) <= 0)
    assert values[-1].max() < values[0].min()


# --------------------------------------------------------------------------- controllers


def test_analytic_names_match_every_dynamics():
    assert set(ANALYTIC) == set(DYNAMICS)
    kinds = {
        "zone": InformedIndividualController,
        "piecewise": GoalForceController,
        "lagrangian": LyapunovTargetController,
    }
    for dynamics, cls in kinds.items():
        assert type(make_controller("analytic", cfg_of(dynamics))) is cls


def obs_with_offset(ctrl, offsets: np.ndarray) -> np.ndarray:
    obs = np.zeros((len(offsets), ctrl.obs_dim), np.float64)
    obs[:, : ctrl.dim] = offsets / ctrl.cfg.obs_goal_scale
    return obs


def test_informed_individual_action_is_omega_times_the_unit_goal_direction():
    ctrl = InformedIndividualController(cfg_of("zone"), omega=0.9)
    offsets = np.array([[3.0, 4.0], [-0.01, 0.0], [0.0, 0.0]])
    actions, _ = ctrl.predict(obs_with_offset(ctrl, offsets))
    np.testing.assert_allclose(actions[0], 0.3 * np.array([0.6, 0.8]))
    np.testing.assert_allclose(actions[1], [-0.3, 0.0])
    np.testing.assert_array_equal(actions[2], [0.0, 0.0])
    big = InformedIndividualController(cfg_of("zone"), omega=10.0)
    assert np.linalg.norm(big.predict(obs_with_offset(big, offsets[:1]))[0]) == pytest.approx(1)
    with pytest.raises(ValueError, match="omega"):
        InformedIndividualController(cfg_of("zone"), omega=-1.0)


def test_goal_force_controller_applies_the_sink_force():
    ctrl = GoalForceController(cfg_of("piecewise"))
    offset = np.array([[6.0, 8.0]])  # distance 10 = 2 l_g: force (C_g/l_g) e^{-2}
    action, _ = ctrl.predict(obs_with_offset(ctrl, offset))
    expected = 3.0 * math.exp(-2.0) * np.array([0.6, 0.8]) / ctrl.u_max
    np.testing.assert_allclose(action[0], expected, rtol=1e-12)


def test_lyapunov_action_is_minus_the_gradient_of_the_target_potential():
    ctrl = LyapunovTargetController(cfg_of("lagrangian", dim=3), gain=0.8)
    rng = np.random.default_rng(0)
    offsets = rng.normal(scale=4.0, size=(20, 3))  # r_g − r, both sides of the knee
    u = ctrl.u_max * ctrl.predict(obs_with_offset(ctrl, offsets))[0]
    h = 1e-6
    for k in range(3):  # V_t as a function of r − r_g = −offset
        e = np.zeros(3)
        e[k] = h
        plus = target_potential(-offsets + e, ctrl.gain, ctrl.u_max)
        minus = target_potential(-offsets - e, ctrl.gain, ctrl.u_max)
        np.testing.assert_allclose(-(plus - minus) / (2 * h), u[:, k], atol=1e-6)
    assert np.all(np.linalg.norm(u, axis=-1) <= ctrl.u_max * (1 + 1e-12))


def test_lyapunov_closed_loop_decreases_l_plus_target_potential():
    cfg = cfg_of("lagrangian", n_agents=6, lagrangian={"step_tol": 0.01})
    core = SwarmNavCore(cfg, batch=2)
    core.reset(np.random.default_rng(1))
    ctrl = LyapunovTargetController(cfg)

    def total() -> np.ndarray:
        offset = core.x - core.goal[:, None, :]
        return core.stats()["energy"] + target_potential(offset, ctrl.gain, ctrl.u_max).sum(-1)

    values = [total()]
    for _ in range(80):
        core.step(ctrl.action_from_offset(core.goal[:, None, :] - core.x))
        values.append(total())
    values = np.array(values)
    assert np.all(np.diff(values, axis=0) <= 1e-9 * np.abs(values[:-1]).max())
    assert values[-1].max() < 0.1 * values[0].min()


@pytest.mark.parametrize("dynamics", NEW)
def test_each_baseline_reaches_the_goal_where_zero_action_does_not(dynamics: str):
    cfg = cfg_of(dynamics)
    policies = {name: make_controller(name, cfg) for name in ("analytic", "zero")}
    res = evaluate_policies(policies, cfg, episodes=4, seed=0, progress=False)["policies"]
    assert res["analytic"]["success_rate"] == 1.0
    assert res["zero"]["success_rate"] < 0.5
    assert res["analytic"]["mean_return"] > res["zero"]["mean_return"] + 10


def test_params_defaults_for_the_task_are_valid_and_documented():
    for params in (ZoneParams.navigation(), PiecewiseParams.navigation()):
        assert params.__doc__
    assert LagrangianParams.navigation().gradient == "exact"
