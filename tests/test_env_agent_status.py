"""Agents that fail, leave and join, through every API: PettingZoo's official tests with
agents leaving and joining, the central env's status flags, the SB3 VecEnv's inactive
slots (done handling for PPO and SAC) and seeded determinism."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from helpers import strict_warnings
from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test
from stable_baselines3 import PPO, SAC
from stable_baselines3.common.vec_env import VecCheckNan

from swarm_envs import ENV_ID, swarm_nav_v0
from swarm_envs.envs.task.agent_status import ABSENT, ACTIVE, FAILED, FROZEN

LEAVING = {"failed_fraction": 0.3, "failure_time": [1, 20]}
COMING_AND_GOING = {
    "failed_fraction": 0.3,
    "failure_mode": "removed",
    "failure_time": [1, 20],
    "join_fraction": 0.2,
    "join_time": [2, 10],
    "obs_noise": 0.2,
    "neighbor_dropout": 0.1,
}


@pytest.mark.parametrize("perturbations", [LEAVING, COMING_AND_GOING])
def test_official_pettingzoo_tests_pass_with_agents_leaving(perturbations: dict[str, Any]):
    kwargs = dict(perturbations=perturbations, observe_status=True, max_steps=60)
    with strict_warnings():
        parallel_api_test(swarm_nav_v0.parallel_env(**kwargs), num_cycles=200)
        api_test(swarm_nav_v0.env(**kwargs), num_cycles=200)
        parallel_seed_test(lambda: swarm_nav_v0.parallel_env(**kwargs))


def test_failed_agents_are_terminated_and_leave_and_joiners_enter():
    env = swarm_nav_v0.parallel_env(perturbations=COMING_AND_GOING, max_steps=60)
    obs, _ = env.reset(seed=3)
    n = env.cfg.n_agents
    assert len(env.agents) == n - 2  # two joiners held back
    assert set(obs) == set(env.agents)
    seen_leave = seen_join = False
    for _ in range(40):
        before = list(env.agents)
        actions = {a: np.zeros(2, np.float32) for a in before}
        obs, rew, term, _, _ = env.step(actions)
        if not env.agents:
            break
        left = [a for a in before if a not in env.agents]
        joined = [a for a in env.agents if a not in before]
        for a in left:
            assert term[a] and env.status[env.possible_agents.index(a)] == ABSENT
            seen_leave = True
        for a in joined:
            assert a in obs and rew[a] == 0.0 and not term[a]
            seen_join = True
        assert np.array_equal(env.active, env.status == ACTIVE)
        assert set(env.agents) == {
            a for a, on in zip(env.possible_agents, env.active, strict=True) if on
        }
    assert seen_leave and seen_join


def test_the_same_seed_gives_the_same_perturbed_rollout():
    def run(seed: int) -> list[Any]:
        env = swarm_nav_v0.parallel_env(perturbations=COMING_AND_GOING, observe_status=True)
        obs, _ = env.reset(seed=seed)
        rng = np.random.default_rng(0)
        out = [sorted(obs), np.stack([obs[a] for a in sorted(obs)])]
        for _ in range(30):
            actions = {a: rng.uniform(-1, 1, 2).astype(np.float32) for a in env.agents}
            obs, rew, *_ = env.step(actions)
            out += [env.status, np.stack([obs[a] for a in sorted(obs)]), sorted(rew.items())]
        return out

    first, again, other = run(5), run(5), run(6)
    for a, b in zip(first, again, strict=True):
        np.testing.assert_array_equal(np.asarray(a, dtype=object), np.asarray(b, dtype=object))
    assert any(
        not np.array_equal(np.asarray(a, dtype=object), np.asarray(b, dtype=object))
        for a, b in zip(first, other, strict=False)
    )


def test_the_central_env_appends_every_agents_flag():
    kwargs = dict(perturbations={"failed_fraction": 0.3, "failure_mode": "frozen"})
    plain = gym.make(ENV_ID, **kwargs)
    flagged = gym.make(ENV_ID, observe_status=True, **kwargs)
    n = plain.unwrapped.cfg.n_agents
    # each neighbour block gains its flag, and the central observation one per agent
    assert flagged.observation_space.shape[0] == plain.observation_space.shape[0] + 6 * n + n
    obs, _ = flagged.reset(seed=1)
    status = flagged.unwrapped.status
    assert (status == FROZEN).sum() == 3
    np.testing.assert_array_equal(obs[-n:], (status == ACTIVE).astype(np.float32))
    obs, *_ = flagged.step(flagged.action_space.sample())
    assert flagged.observation_space.contains(obs)


def test_passive_failures_keep_their_physics_but_not_their_actions():
    env = gym.make(ENV_ID, perturbations={"failed_fraction": 0.5})
    env.reset(seed=2)
    status = env.unwrapped.status
    assert (status == FAILED).sum() == 5
    a = np.zeros(env.action_space.shape, np.float32)
    a.reshape(-1, 2)[status == FAILED] = 1.0  # pushes on failed agents only
    env2 = gym.make(ENV_ID, perturbations={"failed_fraction": 0.5})
    env2.reset(seed=2)
    for _ in range(5):
        o1, *_ = env.step(a)
        o2, *_ = env2.step(np.zeros_like(a))
    np.testing.assert_array_equal(o1, o2)
    assert np.abs(env.unwrapped.velocities[status == FAILED]).sum() > 0  # they still move


# --------------------------------------------------------------------------- vec_env


def _vec(**kwargs: Any):
    return swarm_nav_v0.vec_env(4, n_agents=6, max_steps=40, **kwargs)


def test_vec_env_inactive_slots_are_zero_reward_absorbing_episodes():
    venv = _vec(perturbations={"failed_fraction": 0.5, "failure_time": [1, 10]})
    venv.seed(0)
    obs = venv.reset()
    was_active = venv._statuses().reshape(-1)
    assert was_active.all()  # every failure comes later
    stopped_seen = False
    for _ in range(60):
        obs, rewards, dones, infos = venv.step(np.zeros((venv.num_envs, 2), np.float32))
        active = venv._statuses().reshape(-1)
        swarm_done = np.repeat(dones.reshape(4, 6).all(axis=1), 6)
        stopped = was_active & ~active & ~swarm_done
        idle = ~was_active & ~swarm_done
        for slot in np.flatnonzero(stopped | idle):
            assert dones[slot]
            assert infos[slot]["TimeLimit.truncated"] is False
            assert "episode" not in infos[slot]
            terminal = infos[slot]["terminal_observation"]
            assert (np.abs(terminal).sum() > 0) == bool(stopped[slot])
        stopped_seen |= stopped.any()
        assert np.all(rewards[idle] == 0.0)
        assert np.all(obs[~active] == 0.0) and np.all(np.abs(obs[active]).sum(axis=1) > 0)
        was_active = active
    assert stopped_seen


@pytest.mark.parametrize("algo", [PPO, SAC])
def test_ppo_and_sac_train_with_agents_failing_and_joining(algo: type):
    perturbations = {
        "failed_fraction": [0.0, 0.5],
        "failure_time": [0, 20],
        "failure_mode": "removed",
        "join_fraction": 0.2,
        "join_time": [1, 20],
    }
    venv = VecCheckNan(_vec(perturbations=perturbations, observe_status=True), raise_exception=True)
    extra = (
        dict(n_steps=32, batch_size=64, n_epochs=1)
        if algo is PPO
        else dict(learning_starts=64, batch_size=64, buffer_size=5000)
    )
    model = algo("MlpPolicy", venv, policy_kwargs={"net_arch": [16]}, seed=0, device="cpu", **extra)
    model.learn(total_timesteps=1536)
    assert model.num_timesteps >= 1536
    if algo is SAC:  # the absorbing slots' transitions: zero observation, reward 0, done
        buf = model.replay_buffer
        n = buf.size() if not buf.full else buf.buffer_size
        obs, rew, done = buf.observations[:n], buf.rewards[:n], buf.dones[:n]
        zero = np.abs(obs).sum(axis=-1) == 0
        assert zero.any()
        assert np.all(rew[zero] == 0.0) and np.all(done[zero] == 1.0)
