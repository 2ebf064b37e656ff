"""The policies of ``agents``: actions on hand-built observations, the SB3 ``predict``
protocol on every observation layout, construction from every env, and the goal-sink
controller's equivalence with the paper's navigating swarm (Mabrouk & McInnes eq. 21)."""

from __future__ import annotations

import gymnasium
import numpy as np
import pytest

import swarm_envs
from agents import (
    CONTROLLERS,
    Controller,
    PotentialFieldController,
    RandomController,
    ZeroController,
    make_controller,
    swarm_config_of,
)
from swarm_envs import swarm_nav_v0
from swarm_envs.config import SwarmConfig, load_swarm_config
from swarm_envs.envs import SwarmNavEnv, observation_size
from swarm_envs.physics import SocialPotentialParams, goal_force, simulate

NAV = "configs/env/paper_navigation.yaml"


def goal_obs(cfg: SwarmConfig, offsets: np.ndarray) -> np.ndarray:
    """Per-agent observations (n, obs_dim) whose goal part encodes world offsets (n, d)."""
    offsets = np.atleast_2d(offsets)
    obs = np.zeros((offsets.shape[0], observation_size(cfg)), np.float32)
    obs[:, : cfg.dim] = offsets / cfg.obs_goal_scale
    obs[:, cfg.dim : 2 * cfg.dim] = 0.7  # velocity and neighbours must not matter
    obs[:, 2 * cfg.dim :] = -0.3
    return obs


# --------------------------------------------------------------------------- actions


def test_potential_action_is_the_goal_sink_force_in_action_units():
    cfg = SwarmConfig()  # C_g = 15, l_g = 5, u_max = 3
    ctrl = PotentialFieldController(cfg)
    offsets = np.array([[3.0, 4.0], [-5.0, 0.0], [0.0, 0.5], [20.0, -20.0]])
    action, state = ctrl.predict(goal_obs(cfg, offsets))
    assert state is None
    dist = np.linalg.norm(offsets, axis=1, keepdims=True)
    expected = (15.0 / 5.0) * np.exp(-dist / 5.0) * offsets / dist / 3.0
    np.testing.assert_allclose(action, expected, rtol=1e-6)
    # (3, 4) at distance 5: e^{-1} (0.6, 0.8)
    np.testing.assert_allclose(action[0], np.exp(-1.0) * np.array([0.6, 0.8]), rtol=1e-6)
    assert action.dtype == np.float32 and action.shape == (4, 2)


def test_potential_action_on_the_goal_is_zero_and_finite():
    cfg = SwarmConfig()
    action, _ = PotentialFieldController(cfg).predict(goal_obs(cfg, np.zeros((1, 2))))
    assert np.array_equal(action, np.zeros((1, 2), np.float32))


def test_potential_ignores_everything_but_the_goal_offset():
    cfg = SwarmConfig()
    ctrl = PotentialFieldController(cfg)
    obs = goal_obs(cfg, np.array([[2.0, -1.0]]))
    other = obs.copy()
    other[:, cfg.dim :] = np.random.default_rng(0).uniform(-10, 10, other[:, cfg.dim :].shape)
    assert np.array_equal(ctrl.predict(obs)[0], ctrl.predict(other)[0])


def test_potential_matches_physics_goal_force_in_3d():
    cfg = SwarmConfig(dim=3, n_agents=4)
    ctrl = PotentialFieldController(cfg)
    rng = np.random.default_rng(1)
    offsets = rng.uniform(-8, 8, (50, 3))
    force = goal_force(-offsets, cfg.physics, np.zeros(3))
    np.testing.assert_allclose(ctrl.action_from_offset(offsets), force / cfg.u_max, rtol=1e-12)


def test_paper_navigation_set_never_saturates():
    cfg = load_swarm_config(NAV)
    ctrl = PotentialFieldController(cfg)
    assert cfg.physics.C_g / cfg.physics.l_g == cfg.u_max == 3.0
    assert ctrl.peak_action == 1.0 and not ctrl.saturates
    a = ctrl.action_from_offset(np.array([[1e-9, 0.0], [0.0, -1e-6]]))
    assert np.all(np.abs(a) <= 1.0)
    np.testing.assert_allclose(np.linalg.norm(a, axis=1), 1.0, rtol=1e-6)


def test_saturation_caps_the_norm_and_keeps_the_direction():
    cfg = SwarmConfig(u_max=1.0)  # C_g / l_g = 3 > u_max
    ctrl = PotentialFieldController(cfg)
    assert ctrl.saturates and ctrl.peak_action == pytest.approx(3.0)
    offsets = np.array([[0.3, 0.4], [1.0, 1.0], [30.0, 0.0]])
    a = ctrl.action_from_offset(offsets)
    norms = np.linalg.norm(a, axis=1)
    assert norms[0] == pytest.approx(1.0) and norms[1] == pytest.approx(1.0)
    unit = offsets[:2] / np.linalg.norm(offsets[:2], axis=1, keepdims=True)
    np.testing.assert_allclose(a[:2] / norms[:2, None], unit)
    np.testing.assert_allclose(a[2, 0], 3.0 * np.exp(-6.0))  # far away: not capped


def test_potential_with_no_sink_is_zero():
    cfg = load_swarm_config("configs/env/paper_default.yaml")  # C_g = 0
    a, _ = PotentialFieldController(cfg).predict(goal_obs(cfg, np.array([[1.0, 2.0]])))
    assert np.array_equal(a, np.zeros_like(a))


def test_zero_controller():
    cfg = SwarmConfig(n_agents=3)
    ctrl = ZeroController(cfg)
    a, _ = ctrl.predict(np.ones(3 * ctrl.obs_dim, np.float32))
    assert a.shape == (6,) and a.dtype == np.float32 and not a.any()


def test_random_controller_is_uniform_seeded_and_reproducible():
    cfg = SwarmConfig(n_agents=5)
    obs = np.zeros((4000, observation_size(cfg)), np.float32)
    a1, _ = RandomController(cfg, seed=3).predict(obs)
    a2, _ = RandomController(cfg, seed=3).predict(obs)
    a3, _ = RandomController(cfg, seed=4).predict(obs)
    assert np.array_equal(a1, a2) and not np.array_equal(a1, a3)
    assert a1.min() >= -1.0 and a1.max() <= 1.0
    assert abs(a1.mean()) < 0.05 and a1.std() == pytest.approx(1 / np.sqrt(3), abs=0.02)
    # deterministic=True still samples (a uniform policy has no mode)
    a4, _ = RandomController(cfg, seed=3).predict(obs, deterministic=True)
    assert np.array_equal(a1, a4)
    # a Generator is used as given
    rng = np.random.default_rng(3)
    assert np.array_equal(RandomController(cfg, seed=rng).predict(obs)[0], a1)


def test_random_controller_leaves_global_rng_alone():
    state = np.random.get_state()[1].copy()  # noqa: NPY002 (checks the global state)
    RandomController(SwarmConfig(), seed=0).predict(np.zeros((10, 34), np.float32))
    assert np.array_equal(np.random.get_state()[1], state)  # noqa: NPY002


# --------------------------------------------------------------------------- protocol


@pytest.mark.parametrize("cls", [PotentialFieldController, ZeroController, RandomController])
def test_predict_shapes_for_every_layout(cls):
    cfg = SwarmConfig(n_agents=4, n_neighbors=2)
    ctrl = cls(cfg)
    k, n, d = ctrl.obs_dim, cfg.n_agents, cfg.dim
    rng = np.random.default_rng(0)
    cases = {
        (k,): (d,),  # one agent
        (7, k): (7, d),  # a batch of agents (shared policy)
        (n * k,): (n * d,),  # the Gymnasium env's flat observation
        (3, n * k): (3, n * d),  # a batch of flat observations
        (2, n, k): (2, n, d),  # (episodes, agents, obs_dim)
    }
    for shape, out in cases.items():
        obs = rng.uniform(-1, 1, shape).astype(np.float32)
        state = object()
        a, s = ctrl.predict(obs, state=state, episode_start=np.ones(1, bool))
        assert a.shape == out and s is state
        assert np.all(np.abs(a) <= 1.0)


def test_predict_is_consistent_across_layouts():
    cfg = SwarmConfig(n_agents=4)
    ctrl = PotentialFieldController(cfg)
    obs = np.random.default_rng(2).uniform(-1, 1, (4, ctrl.obs_dim)).astype(np.float32)
    per_agent = ctrl.predict(obs)[0]
    flat = ctrl.predict(obs.reshape(-1))[0]
    single = np.stack([ctrl.predict(o)[0] for o in obs])
    assert np.array_equal(flat.reshape(4, 2), per_agent)
    assert np.array_equal(single, per_agent)


def test_predict_keeps_float64():
    cfg = SwarmConfig()
    ctrl = PotentialFieldController(cfg)
    obs = goal_obs(cfg, np.array([[1.0, 1.0]])).astype(np.float64)
    assert ctrl.predict(obs)[0].dtype == np.float64


@pytest.mark.parametrize("cls", [PotentialFieldController, ZeroController, RandomController])
@pytest.mark.parametrize("shape", [(33,), (5, 35), (339,), (2, 3)])
def test_wrong_observation_size_raises(cls, shape):
    ctrl = cls(SwarmConfig())  # obs_dim = 34, N = 10
    with pytest.raises(ValueError, match="34"):
        ctrl.predict(np.zeros(shape, np.float32))


def test_non_numeric_observation_raises():
    ctrl = ZeroController(SwarmConfig())
    with pytest.raises(ValueError, match="numeric"):
        ctrl.predict(np.array(["a"] * 34))
    with pytest.raises(ValueError):
        ctrl.predict(np.float32(1.0))


def test_predict_on_pettingzoo_dicts():
    par = swarm_nav_v0.parallel_env(n_agents=5)
    obs, _ = par.reset(seed=0)
    ctrl = PotentialFieldController(par)
    actions, _ = ctrl.predict(obs)
    assert set(actions) == set(obs)
    for agent, a in actions.items():
        assert np.array_equal(a, ctrl.predict(obs[agent])[0])
    par.step(actions)


# --------------------------------------------------------------------------- construction


def test_built_from_every_env_and_from_a_config():
    kwargs = {"n_agents": 6, "u_max": 2.5}
    envs = [
        gymnasium.make(swarm_envs.ENV_ID, **kwargs),  # TimeLimit + checker wrappers
        SwarmNavEnv(**kwargs),
        swarm_nav_v0.parallel_env(**kwargs),
        swarm_nav_v0.env(**kwargs),  # AEC with wrappers
        swarm_nav_v0.vec_env(2, **kwargs),
    ]
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    envs.append(VecNormalize(VecMonitor(swarm_nav_v0.vec_env(2, **kwargs))))
    for env in envs:
        ctrl = PotentialFieldController(env)
        assert (ctrl.n_agents, ctrl.u_max, ctrl.dim) == (6, 2.5, 2), type(env)
        assert ctrl.obs_dim == observation_size(ctrl.cfg)
        assert ctrl.observation_space.shape == (ctrl.obs_dim,)
        assert ctrl.action_space.shape == (2,)
    cfg = load_swarm_config(NAV)
    ctrl = PotentialFieldController.from_config(cfg)
    assert (ctrl.C_g, ctrl.l_g, ctrl.n_agents) == (15.0, 5.0, 31)
    assert swarm_config_of(cfg) is cfg
    with pytest.raises(ValueError, match="SwarmConfig"):
        PotentialFieldController.from_config({"n_agents": 3})


def test_not_a_swarm_env_raises():
    with pytest.raises(ValueError, match="swarm_envs environment"):
        ZeroController(gymnasium.make("CartPole-v1"))


def test_make_controller_by_name():
    cfg = SwarmConfig()
    assert set(CONTROLLERS) == {
        "potential",
        "informed",
        "goal_force",
        "lyapunov",
        "mill",
        "pd",
        "follow",
        "zero",
        "random",
    }
    assert isinstance(make_controller("potential", cfg), PotentialFieldController)
    assert isinstance(make_controller("analytic", cfg), PotentialFieldController)
    r1, r2 = make_controller("random", cfg, seed=1), make_controller("random", cfg, seed=1)
    obs = np.zeros((3, 34), np.float32)
    assert np.array_equal(r1.predict(obs)[0], r2.predict(obs)[0])
    with pytest.raises(ValueError, match="unknown policy 'magic'"):
        make_controller("magic", cfg)


def test_docstrings_name_the_paper():
    assert "Mabrouk & McInnes" in PotentialFieldController.__doc__
    assert "eqs. 19–21" in PotentialFieldController.__doc__
    assert "u_max" in PotentialFieldController.__doc__  # clipping is documented
    assert issubclass(PotentialFieldController, Controller)


# --------------------------------------------------------------------------- the paper's model


def _paper_reference(env: SwarmNavEnv, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """``physics.simulate`` with the sink on (eq. 21) from the env's start."""
    core = env.core
    params: SocialPotentialParams = env.cfg.physics
    assert params.C_g > 0 and not env.cfg.goal_in_physics
    return simulate(
        params, core.x[0].copy(), core.v[0].copy(), dt=env.cfg.dt, steps=steps, goal=core.goal[0]
    )


# The comparison stops during the transit, before the swarm packs into the goal: there
# close encounters amplify any difference exponentially (measured: round-off of 1e-14
# grows to 1e-7 within 40 steps after arrival), which is chaos, not a discrepancy.
# The env's step is one integration step when the step-size rule asks for one: at
# dt = 0.03 it does for this swarm throughout (checked on every step below).
STEPS = 330
DT = 0.03


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_env_plus_controller_is_the_papers_navigating_swarm_exactly(seed):
    """Exact state: the controller is computed from the env's float64 state.

    ``env (goal_in_physics=False) + controller actions`` must equal ``simulate`` with the
    sink in the physics; the two differ only in summation order and in
    ``u_max · (F / u_max)`` round-off, ~1e-16 per step.
    """
    env = SwarmNavEnv(config=NAV, max_steps=10 * STEPS, dt=DT)
    env.reset(seed=seed)
    ctrl = PotentialFieldController(env)
    xs_ref, vs_ref = _paper_reference(env, STEPS)
    core = env.core
    for t in range(STEPS):
        action = ctrl.action_from_offset(core.goal[0] - core.x[0])  # float64, exact state
        assert np.all(np.linalg.norm(action, axis=-1) <= 1.0)  # never clipped
        _, _, _, _, info = env.step(action.reshape(-1))
        assert info["substeps"] == 1
        np.testing.assert_allclose(core.x[0], xs_ref[t + 1], rtol=0, atol=1e-9)
        np.testing.assert_allclose(core.v[0], vs_ref[t + 1], rtol=0, atol=1e-9)
    # the swarm really travelled (this is not a trivial comparison)
    assert np.linalg.norm(xs_ref[-1].mean(0) - xs_ref[0].mean(0)) > 3.0


def test_env_plus_controller_through_float32_observations():
    """Public API: actions from the env's float32 observations.

    The observed offset carries float32 round-off (relative 2^-24 ≈ 6e-8), and so do the
    float32 actions: the control force is off by at most ~2 · 6e-8 · C_g/l_g ≈ 4e-7 per
    step. With dissipation β = 1 a constant force error δF shifts the velocity by at most
    δF/β and the position by at most δF/β · t ≈ 4e-7 · 10 s = 4e-6 over the STEPS · DT
    ≈ 10 s compared (if all errors added coherently; measured ~1e-8, as they are random).
    Tolerance 1e-5.
    """
    env = SwarmNavEnv(config=NAV, max_steps=10 * STEPS, dt=DT)
    obs, _ = env.reset(seed=0)
    ctrl = PotentialFieldController(env)
    xs_ref, _ = _paper_reference(env, STEPS)
    for t in range(STEPS):
        action, _ = ctrl.predict(obs)
        assert action.dtype == np.float32 and action.shape == env.action_space.shape
        obs, *_ = env.step(action)
        np.testing.assert_allclose(env.core.x[0], xs_ref[t + 1], rtol=0, atol=1e-5)


def test_controller_reaches_the_goal_in_the_gym_env():
    env = gymnasium.make(swarm_envs.ENV_ID, n_agents=6)
    ctrl = PotentialFieldController(env)
    obs, _ = env.reset(seed=5)
    for _ in range(400):
        obs, _, terminated, truncated, info = env.step(ctrl.predict(obs)[0])
        if terminated or truncated:
            break
    assert terminated and info["success"] == 1.0


def test_vec_env_slots_use_the_shared_layout():
    venv = swarm_nav_v0.vec_env(3, n_agents=4)
    ctrl = PotentialFieldController(venv)
    obs = venv.reset()
    actions, _ = ctrl.predict(obs)
    assert actions.shape == (12, 2)
    venv.step(actions)
