"""The informed and mill tasks: their configs and defaults, the informed agents'
observation, the mill's statistics, reward and episode end, the official API checkers on
every registered id, and their analytic baselines."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from helpers import strict_warnings
from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import VecCheckNan

from agents import MillController, analytic_name, make_controller
from swarm_envs import metrics, swarm_informed_v0, swarm_mill_v0, swarm_nav_v0
from swarm_envs.config import SwarmConfig, load_swarm_config
from swarm_envs.envs.backends import make_core, unsupported
from swarm_envs.envs.cores.numpy import SwarmNavCore
from swarm_envs.envs.task.episode import episode_end
from swarm_envs.envs.task.informed import draw_informed
from swarm_envs.envs.task.observation import block_size, observation_size, own_size
from swarm_envs.tasks import MILL_SUCCESS_SPEED, TASK_IDS, TASKS, informed_count, task_config

# ---------------------------------------------------------------------------- configs


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"task": "flock"}, "task must be one of"),
        ({"informed_fraction": 0.5}, "informed_fraction applies to task='informed'"),
        ({"task": "informed", "informed_fraction": 0.0}, "informed_fraction"),
        ({"task": "informed", "informed_fraction": 1.5}, "informed_fraction"),
        ({"task": "informed", "informed_fraction": [0.4, 0.2]}, "low <= high"),
        ({"task": "mill", "physics": {"alpha": 0.0}}, "physics.alpha > 0"),
        ({"task": "mill", "dynamics": "zone"}, "dynamics='social_potential'"),
        ({"reward": {"mill": 0.1}}, "reward.mill"),
    ],
)
def test_bad_task_settings_are_refused_naming_the_key(overrides: dict, message: str):
    with pytest.raises(ValueError, match=message):
        load_swarm_config(None, overrides)


def test_each_task_brings_its_defaults_under_the_given_values():
    mill = task_config("mill", physics={"alpha": 2.0}, max_steps=50)
    assert mill.physics.alpha == 2.0 and mill.physics.beta == 0.5  # only alpha changed
    assert mill.goal_in_physics and mill.max_steps == 50 and mill.reward.mill > 0
    assert task_config("informed").informed_fraction == 0.3
    assert task_config("informed", informed_fraction=[0.1, 0.3]).informed_fraction == (0.1, 0.3)
    assert task_config("navigation") == SwarmConfig()
    # a SwarmConfig built directly takes the dataclass defaults
    assert SwarmConfig(task="informed").informed_fraction == 1.0


def test_registered_ids_and_modules_run_their_task():
    assert set(TASK_IDS) == set(TASKS)
    for task, env_id in TASK_IDS.items():
        assert gym.make(env_id).unwrapped.cfg.task == task
    assert swarm_informed_v0.parallel_env().cfg.informed_fraction == 0.3
    assert swarm_mill_v0.parallel_env().cfg.physics.cruise_speed == 1.0
    with pytest.raises(ValueError, match="runs task='mill'"):
        swarm_mill_v0.parallel_env(task="navigation")
    yaml_cfg = load_swarm_config("configs/env/mill.yaml")
    assert yaml_cfg == task_config("mill")


# ---------------------------------------------------------------------------- informed


def test_informed_counts_and_draws_are_seeded_and_in_range():
    assert [informed_count(f, 10) for f in (0.01, 0.1, 0.149, 0.15, 0.3, 1.0)] == [
        1,
        1,
        1,
        2,
        3,
        10,
    ]
    cfg = task_config("informed", informed_fraction=[0.1, 0.5])
    a = draw_informed(cfg, np.random.default_rng(3), 200)
    b = draw_informed(cfg, np.random.default_rng(3), 200)
    np.testing.assert_array_equal(a, b)
    counts = a.sum(axis=1)
    assert counts.min() >= 1 and counts.max() <= 5 and len(set(counts)) > 2
    assert a.any(axis=0).all()  # every agent is informed in some swarm


@pytest.mark.parametrize("observe_status", [False, True])
@pytest.mark.parametrize("dynamics", ["social_potential", "zone"])
def test_the_observation_hides_the_goal_and_shows_who_is_informed(
    dynamics: str, observe_status: bool
):
    cfg = task_config(
        "informed", dynamics=dynamics, n_agents=7, n_neighbors=4, observe_status=observe_status
    )
    core = SwarmNavCore(cfg, batch=3)
    core.reset(np.random.default_rng(0))
    core.step(np.zeros((3, 7, 2)))
    obs, told, d = core.observe(), core.informed, cfg.dim
    assert obs.shape == (3, 7, observation_size(cfg))
    assert own_size(cfg) == 2 * d + 1 and block_size(cfg) == 2 * d + 2 + observe_status
    np.testing.assert_array_equal(obs[..., 2 * d], told)  # the agent's own flag
    offset = (core.goal[:, None, :] - core.x) / cfg.obs_goal_scale
    np.testing.assert_allclose(obs[..., :d], np.where(told[..., None], offset, 0.0), atol=1e-6)
    slots = obs[..., own_size(cfg) :].reshape(3, 7, cfg.n_neighbors, block_size(cfg))
    ranked = core._near[..., : cfg.n_neighbors]
    neighbour_told = np.take_along_axis(told[:, None, :].repeat(7, 1), ranked, axis=-1)
    np.testing.assert_array_equal(slots[..., -1], neighbour_told)
    # the navigation layout stays as it was
    assert observation_size(task_config("navigation", n_agents=7, n_neighbors=4)) == 4 + 4 * 5


def test_informed_runs_on_the_backends_that_write_its_observation():
    cfg = task_config("informed")
    assert "informed" in unsupported(cfg, "torch")
    assert make_core(cfg, batch=2).backend == "numpy"
    big = task_config("informed", n_agents=12, backend="cutoff")
    cut, dense = make_core(big, batch=2), SwarmNavCore(big, batch=2)
    for core in (cut, dense):
        core.reset(np.random.default_rng(5))
        for _ in range(3):
            core.step(np.full((2, 12, 2), 0.3))
    np.testing.assert_array_equal(cut.informed, dense.informed)
    np.testing.assert_allclose(cut.observe(), dense.observe(), atol=1e-5)


@pytest.mark.parametrize("dynamics", ["social_potential", "zone"])
def test_the_informed_baseline_moves_only_the_informed_agents(dynamics: str):
    cfg = task_config("informed", informed_fraction=0.3, dynamics=dynamics)
    core = SwarmNavCore(cfg, batch=4)
    core.reset(np.random.default_rng(1))
    obs = core.observe()
    for name in (analytic_name(cfg), "analytic"):
        action, _ = make_controller(name, cfg).predict(obs.reshape(-1, obs.shape[-1]))
        moving = np.abs(action.reshape(4, 10, 2)).sum(-1) > 0
        np.testing.assert_array_equal(moving, core.informed)
    random_action, _ = make_controller("random", cfg, seed=0).predict(obs.reshape(40, -1))
    assert (np.abs(random_action).sum(-1) > 0).all()


def test_the_same_seed_gives_the_same_informed_rollout():
    def rollout() -> np.ndarray:
        env = gym.make(TASK_IDS["informed"], informed_fraction=[0.1, 0.5])
        obs, _ = env.reset(seed=11)
        out = [obs]
        for _ in range(5):
            obs, *_ = env.step(env.action_space.sample() * 0 + 0.2)
            out.append(obs)
        return np.stack(out)

    np.testing.assert_array_equal(rollout(), rollout())


# ---------------------------------------------------------------------------- mill


def _ring(n: int, radius: float, speed: float) -> tuple[np.ndarray, np.ndarray]:
    theta = np.linspace(0, 2 * np.pi, n, endpoint=False)
    x = radius * np.stack([np.cos(theta), np.sin(theta)], axis=-1)
    v = speed * np.stack([-np.sin(theta), np.cos(theta)], axis=-1)
    return x, v


def test_mill_statistics_read_a_ring_circling_the_goal():
    cfg = task_config("mill")
    core = SwarmNavCore(cfg, batch=1)
    core.reset(np.random.default_rng(0))
    x, v = _ring(10, 0.5, 0.8)
    goal = np.array([3.0, -2.0])
    core.x[0], core.v[0], core.goal[0] = x + goal, v, goal
    core._after_reset(np.arange(1), np.random.default_rng(0))
    core._measure()
    stats = core.stats()
    assert stats["goal_angular_momentum"][0] == pytest.approx(0.5 * 0.8)
    assert stats["mill_speed"][0] == pytest.approx(0.8)
    assert stats["mill_order"][0] == pytest.approx(0.8 / cfg.physics.cruise_speed)
    assert stats["success"][0] == 1.0
    core.v[0] = 0.3 * v  # too slow: arrived, but not milling
    core._measure()
    assert 0.3 * 0.8 < MILL_SUCCESS_SPEED and core.stats()["success"][0] == 0.0
    core.v[0] = x / 0.5 * 0.8  # moving radially: no mill
    core._measure()
    assert core.stats()["mill_speed"][0] == pytest.approx(0.0, abs=1e-12)


def test_tangential_speed_counts_only_agents_within_the_radius():
    x, v = _ring(8, 2.0, 1.0)
    assert metrics.tangential_speed(x, v, [0.0, 0.0]) == pytest.approx(1.0)
    assert metrics.tangential_speed(x, v, [0.0, 0.0], radius=1.5) == 0.0
    inner = np.concatenate([x, x * 0.25])
    both = np.concatenate([v, v])
    assert metrics.tangential_speed(inner, both, [0.0, 0.0], radius=1.0) == pytest.approx(0.5)
    assert metrics.goal_angular_momentum(x, v, [0.0, 0.0]) == pytest.approx(2.0)


def test_the_mill_never_terminates_and_pays_its_order():
    cfg = task_config("mill", max_steps=20)
    core = SwarmNavCore(cfg, batch=3)
    core.reset(np.random.default_rng(2))
    ctrl = MillController(cfg)
    prev = core.stats()
    for t in range(20):
        obs = core.observe()
        action, _ = ctrl.predict(obs.reshape(-1, obs.shape[-1]))
        r, terminated, truncated, stats = core.step(action.reshape(3, 10, 2))
        assert not terminated.any() and truncated.all() == (t == 19)
        w = cfg.reward
        start = core.task.records.start["mean_goal_distance"]
        progress = (prev["mean_goal_distance"] - stats["mean_goal_distance"]) / start
        arrival = stats["fraction_arrived"] - prev["fraction_arrived"]
        effort = (np.clip(action, -1, 1) ** 2).reshape(3, -1).sum(-1) / 10
        expected = (
            w.progress * progress
            + w.arrival * arrival
            - w.collision * stats["collisions"] / 10
            - w.effort * effort
            + w.mill * stats["mill_order"]
        )
        np.testing.assert_allclose(r, expected, rtol=1e-6, atol=1e-9)
        prev = stats
    terminated, truncated = episode_end(cfg, np.ones(3), np.full(3, 20))
    assert not terminated.any() and truncated.all()


def test_the_mill_controller_spins_the_swarm_up_faster_than_the_passive_swarm():
    cfg = task_config("mill")
    order = {}
    for name in ("mill", "zero"):
        core = SwarmNavCore(cfg, batch=8)
        core.reset(np.random.default_rng(4))
        ctrl = make_controller(name, cfg)
        for _ in range(100):
            obs = core.observe()
            action, _ = ctrl.predict(obs.reshape(-1, obs.shape[-1]))
            core.step(action.reshape(8, 10, 2))
        order[name] = core.stats()["mill_order"].mean()
    assert analytic_name(cfg) == "mill"
    assert order["mill"] > 0.9 and order["zero"] < 0.5


def test_the_mill_controller_refuses_3d_and_bad_gains():
    with pytest.raises(ValueError, match="dim must be 2"):
        MillController(SwarmConfig(dim=3))
    with pytest.raises(ValueError, match="spin"):
        MillController(task_config("mill"), spin=2.0)


# ---------------------------------------------------------------------------- APIs


@pytest.mark.parametrize("task", ["informed", "mill"])
def test_official_checkers_pass_on_every_api(task: str):
    module = {"informed": swarm_informed_v0, "mill": swarm_mill_v0}[task]
    with strict_warnings():
        gym_check_env(gym.make(TASK_IDS[task], max_steps=30).unwrapped)
        parallel_api_test(module.parallel_env(max_steps=30), num_cycles=60)
        api_test(module.env(max_steps=30), num_cycles=60)
        parallel_seed_test(lambda: module.parallel_env(max_steps=30))


@pytest.mark.parametrize("task", ["informed", "mill"])
def test_ppo_trains_a_shared_policy_on_the_vec_env(task: str):
    module = {"informed": swarm_informed_v0, "mill": swarm_mill_v0}[task]
    venv = VecCheckNan(module.vec_env(2, max_steps=30), raise_exception=True)
    assert venv.observation_space.shape == (observation_size(venv.venv.cfg),)
    model = PPO("MlpPolicy", venv, n_steps=32, batch_size=64, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=640)
    assert model.num_timesteps >= 640
    assert math.isfinite(float(np.sum(model.rollout_buffer.rewards)))


def test_navigation_modules_refuse_nothing_they_used_to_take():
    env = swarm_nav_v0.parallel_env(task="navigation")
    assert env.cfg == SwarmConfig()


def test_the_evaluation_judges_the_mill_at_its_last_step():
    from train.evaluate.episodes import run_episodes
    from train.evaluate.measures import summarize

    cfg = task_config("mill", max_steps=120)
    held = summarize(run_episodes(MillController(cfg), cfg, 4, seed=3, record_episode=False))
    assert held["success_rate"] == 1.0 and held["mean_episode_length"] == 120
    assert 0 < held["mean_time_to_goal"] < 120 * cfg.dt  # the first step of the held mill
    assert held["final_mill_order"] >= MILL_SUCCESS_SPEED
    idle = summarize(run_episodes(make_controller("zero", cfg), cfg, 4, seed=3))
    assert idle["final_mill_order"] < held["final_mill_order"]
