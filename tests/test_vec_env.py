"""The batched SB3 VecEnv: bulk bounds, auto-reset infos, seeding, layout, PPO smoke test.

10⁴+ steps at the action bounds (``VecCheckNan``), seeding, pickling, auto reset with
``terminal_observation`` and ``TimeLimit.truncated``, ``seed()``, and bad input
(docs/testing.md).
"""

from __future__ import annotations

import math
import pickle
from typing import Any

import cloudpickle
import numpy as np
import pytest
from helpers import assert_same_rng_states, rng_states, strict_warnings
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import VecCheckNan, VecEnv, VecMonitor

from swarm_envs import swarm_nav_v0
from swarm_envs.envs import OBS_BOUND, STAT_KEYS
from swarm_envs.envs.adapters.vec_env import SwarmNavVecEnv

#: Config with which every swarm succeeds on its first step (goal at the start, big radius).
INSTANT_SUCCESS = {"goal_distance_min": 0.0, "goal_distance_max": 0.0, "goal_radius": 50.0}


def bound_actions(rng: np.random.Generator, venv: VecEnv) -> np.ndarray:
    """Every entry ±1 with a random sign, shaped ``(num_envs, d)``."""
    shape = (venv.num_envs, *venv.action_space.shape)
    return rng.choice(np.array([-1.0, 1.0], np.float32), size=shape)


def uniform_actions(rng: np.random.Generator, venv: VecEnv) -> np.ndarray:
    return rng.uniform(-1, 1, (venv.num_envs, *venv.action_space.shape)).astype(np.float32)


def assert_obs_in_box(obs: np.ndarray, venv: VecEnv) -> None:
    assert obs.dtype == np.float32
    assert obs.shape == (venv.num_envs, *venv.observation_space.shape)
    assert np.isfinite(obs).all()
    assert obs.min() >= -OBS_BOUND and obs.max() <= OBS_BOUND


def assert_stats_ok(info: dict[str, Any]) -> None:
    for key in STAT_KEYS:
        assert type(info[key]) is float and math.isfinite(info[key]), (key, info[key])


def test_is_an_sb3_vec_env_with_one_slot_per_agent():
    with strict_warnings():  # VecEnv.__init__ must find render_mode (no SB3 warning)
        venv = swarm_nav_v0.vec_env(3, n_agents=5)
    assert isinstance(venv, VecEnv) and isinstance(venv, SwarmNavVecEnv)
    assert venv.num_envs == 15 and venv.n_swarms == 3 and venv.n_agents == 5
    assert venv.observation_space.shape == (4 + 6 * 5,)
    assert venv.observation_space.dtype == np.float32
    assert venv.action_space.shape == (2,)
    assert venv.render_mode is None


# --------------------------------------------------------------------------- bulk stepping


@pytest.mark.parametrize(
    ("n_agents", "n_swarms", "steps", "dtype"),
    [(10, 16, 700, np.float32), (10, 16, 200, np.float64), (64, 16, 120, np.float32)],
    ids=["N10-f32", "N10-f64", "N64-f32"],
)
def test_random_steps_at_action_bounds_stay_in_box(
    n_agents: int, n_swarms: int, steps: int, dtype: type
):
    """16 swarms × 700 steps = 11 200 swarm steps (with resets) for the default config."""
    venv = VecCheckNan(
        swarm_nav_v0.vec_env(n_swarms, n_agents=n_agents, dtype=dtype, max_steps=300),
        raise_exception=True,
    )
    venv.seed(0)
    obs = venv.reset()
    assert_obs_in_box(obs, venv)
    rng = np.random.default_rng(0)
    ended = 0
    for _ in range(steps):
        obs, rewards, dones, infos = venv.step(bound_actions(rng, venv))
        assert_obs_in_box(obs, venv)
        assert rewards.shape == (venv.num_envs,) and np.isfinite(rewards).all()
        for i in np.flatnonzero(dones):
            term = infos[i]["terminal_observation"]
            assert term.dtype == np.float32 and np.isfinite(term).all()
            assert np.abs(term).max() <= OBS_BOUND
            ended += 1
    if steps > 300:
        assert ended >= venv.num_envs  # every swarm truncated at least once
    for b in range(n_swarms):
        assert_stats_ok(infos[b * n_agents])


@pytest.mark.parametrize(
    "kwargs",
    [
        {"init_radius": 0.0, "init_speed": 0.0},
        {"init_radius": 1e-12},
        {"init_radius": 1e6, "goal_distance_min": 1e6, "goal_distance_max": 1e6},
    ],
    ids=["coincident", "1e-12", "1e6"],
)
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_extreme_separations_stay_finite(kwargs: dict[str, Any], dtype: type):
    venv = VecCheckNan(
        swarm_nav_v0.vec_env(4, n_agents=8, dtype=dtype, **kwargs), raise_exception=True
    )
    venv.seed(1)
    obs = venv.reset()
    assert_obs_in_box(obs, venv)
    rng = np.random.default_rng(1)
    for _ in range(10):
        obs, rewards, _, infos = venv.step(bound_actions(rng, venv))
        assert_obs_in_box(obs, venv)
        assert np.isfinite(rewards).all()
    assert_stats_ok(infos[0])


# --------------------------------------------------------------------------- auto reset


def test_truncated_swarms_reset_with_terminal_observation_and_time_limit_flag():
    B, N, T = 3, 4, 5
    venv = swarm_nav_v0.vec_env(B, n_agents=N, max_steps=T)
    venv.seed(2)
    venv.reset()
    zero = np.zeros((venv.num_envs, 2), np.float32)
    for t in range(1, 2 * T + 1):
        obs, _, dones, infos = venv.step(zero)
        ends = t % T == 0
        assert dones.dtype == bool and bool(dones.all()) is ends and bool(dones.any()) is ends
        for i, info in enumerate(infos):
            if not ends:
                assert "terminal_observation" not in info and "TimeLimit.truncated" not in info
                continue
            term = info["terminal_observation"]
            assert term.shape == venv.observation_space.shape and term.dtype == np.float32
            assert not np.array_equal(term, obs[i])  # obs[i] is already the new start
            assert info["TimeLimit.truncated"] is True
            assert info["swarm_episode"]["l"] == T
        if ends:
            assert np.all(venv.core.t == 0)
    assert all(infos[i] is not infos[j] for i in range(3) for j in range(i + 1, 4))


def test_successful_swarms_reset_with_time_limit_flag_false():
    B, N = 2, 3
    venv = swarm_nav_v0.vec_env(B, n_agents=N, **INSTANT_SUCCESS)
    venv.seed(3)
    venv.reset()
    _, rewards, dones, infos = venv.step(np.zeros((venv.num_envs, 2), np.float32))
    assert dones.all()
    assert np.all(rewards > venv.cfg.reward.success - 1.0)
    for b in range(B):
        assert infos[b * N]["success"] == 1.0
        for i in range(N):
            info = infos[b * N + i]
            assert info["TimeLimit.truncated"] is False
            assert "terminal_observation" in info
            assert info["swarm_episode"]["l"] == 1


def test_only_the_finished_swarm_resets():
    B, N, T = 3, 4, 20
    venv = swarm_nav_v0.vec_env(B, n_agents=N, max_steps=T)
    twin = swarm_nav_v0.vec_env(B, n_agents=N, max_steps=T)
    zero = np.zeros((venv.num_envs, 2), np.float32)
    for e in (venv, twin):
        e.seed(4)
        e.reset()
        for _ in range(3):
            e.step(zero)
    venv.core.t[1] = T - 1  # swarm 1 ends on the next step, the others do not
    obs, _, dones, infos = venv.step(zero)
    twin_obs, *_ = twin.step(zero)
    assert dones.tolist() == [False] * N + [True] * N + [False] * N
    assert venv.core.t.tolist() == [4, 0, 4]
    for i, info in enumerate(infos):
        assert ("terminal_observation" in info) is (N <= i < 2 * N)
    live = np.r_[0:N, 2 * N : 3 * N]
    assert np.array_equal(obs[live], twin_obs[live])  # the live swarms carried on untouched
    assert np.array_equal(infos[N]["terminal_observation"], twin_obs[N])
    assert np.linalg.norm(venv.core.x[1], axis=-1).max() <= venv.cfg.init_radius  # a new start


def test_vec_monitor_reports_episodes():
    venv = VecMonitor(swarm_nav_v0.vec_env(2, n_agents=3, max_steps=4))
    venv.seed(5)
    venv.reset()
    for _ in range(4):
        _, _, dones, infos = venv.step(np.zeros((6, 2), np.float32))
    assert dones.all() and all(info["episode"]["l"] == 4 for info in infos)


def test_episode_infos_match_what_vec_monitor_reports():
    # The VecEnv reports SB3's "episode" itself, in the slots whose swarm ended, with the
    # return and length that a VecMonitor computes; swarms end at different steps here.
    B, N, T = 3, 2, 6
    plain = swarm_nav_v0.vec_env(B, n_agents=N, max_steps=T)
    monitored = VecMonitor(swarm_nav_v0.vec_env(B, n_agents=N, max_steps=T))
    for venv in (plain, monitored):
        venv.seed(7)
        venv.reset()
    plain.core.t[:] = [0, 2, 4]
    monitored.venv.core.t[:] = [0, 2, 4]
    rng = np.random.default_rng(0)
    ended = 0
    for _ in range(2 * T):
        actions = rng.uniform(-1, 1, (B * N, 2)).astype(np.float32)
        _, rewards, dones, infos = plain.step(actions)
        _, m_rewards, m_dones, m_infos = monitored.step(actions)
        np.testing.assert_array_equal(rewards, m_rewards)
        np.testing.assert_array_equal(dones, m_dones)
        for i in range(B * N):
            assert ("episode" in infos[i]) is bool(dones[i])
            if dones[i]:
                ended += 1
                mine, theirs = infos[i]["episode"], m_infos[i]["episode"]
                assert set(mine) == {"r", "l", "t"} and mine["t"] >= 0.0
                assert mine["l"] == theirs["l"]
                assert mine["r"] == pytest.approx(theirs["r"], rel=1e-5, abs=1e-6)
    assert ended >= 3 * N  # every swarm ended at least once, not all on the same step


# --------------------------------------------------------------------------- layout vs envs


def test_one_swarm_matches_the_parallel_env_through_an_auto_reset():
    """Same seed → same generator stream: slot i is agent_i, and an auto-reset equals
    ``reset()`` of the parallel env (float64 state for exact agreement)."""
    N, T = 5, 6
    venv = swarm_nav_v0.vec_env(1, n_agents=N, max_steps=T, dtype=np.float64)
    par = swarm_nav_v0.parallel_env(n_agents=N, max_cycles=T)
    venv.seed(6)
    vobs = venv.reset()
    pobs, _ = par.reset(seed=6)
    rng = np.random.default_rng(6)
    for t in range(1, 3 * T + 1):
        assert np.array_equal(vobs, np.stack([pobs[a] for a in par.possible_agents]))
        actions = uniform_actions(rng, venv)
        vobs, vrew, vdone, infos = venv.step(actions)
        pobs, prew, _, ptrunc, pinfos = par.step(
            {a: actions[i] for i, a in enumerate(par.possible_agents)}
        )
        assert np.all(vrew == np.float32(prew["agent_0"]))
        assert {k: infos[0][k] for k in STAT_KEYS} == {k: pinfos["agent_0"][k] for k in STAT_KEYS}
        assert bool(vdone.all()) is (t % T == 0) and all(ptrunc.values()) is (t % T == 0)
        if t % T == 0:
            for i, a in enumerate(par.possible_agents):
                assert np.array_equal(infos[i]["terminal_observation"], pobs[a])
            pobs, _ = par.reset()


def test_float32_state_tracks_the_float64_state():
    """The default float32 batch follows the float64 trajectory to round-off growth."""
    a = swarm_nav_v0.vec_env(4, dtype=np.float32)
    b = swarm_nav_v0.vec_env(4, dtype=np.float64)
    assert a.core.x.dtype == np.float32 and b.core.x.dtype == np.float64
    a.seed(15)
    b.seed(15)
    np.testing.assert_allclose(a.reset(), b.reset(), rtol=0, atol=1e-6)
    rng = np.random.default_rng(15)
    for _ in range(50):
        acts = uniform_actions(rng, a)
        oa, ra, _, _ = a.step(acts)
        ob, rb, _, _ = b.step(acts)
    np.testing.assert_allclose(a.core.x, b.core.x, rtol=0, atol=1e-3)
    np.testing.assert_allclose(oa, ob, rtol=0, atol=1e-3)
    np.testing.assert_allclose(ra, rb, rtol=0, atol=1e-4)


def test_swarms_are_independent():
    B, N = 3, 6
    a = swarm_nav_v0.vec_env(B, n_agents=N)
    b = swarm_nav_v0.vec_env(B, n_agents=N)
    a.seed(7)
    b.seed(7)
    a.reset()
    b.reset()
    rng = np.random.default_rng(7)
    for _ in range(15):
        acts = uniform_actions(rng, a)
        other = acts.copy()
        other[N : 2 * N] = -other[N : 2 * N]  # change only swarm 1's actions
        oa, ra, _, _ = a.step(acts)
        ob, rb, _, _ = b.step(other)
    same = np.r_[0:N, 2 * N : 3 * N]
    assert np.array_equal(oa[same], ob[same]) and np.array_equal(ra[same], rb[same])
    assert not np.array_equal(oa[N : 2 * N], ob[N : 2 * N])
    assert np.all(ra[:N] == ra[0]) and np.all(ra[N : 2 * N] == ra[N])  # one reward per swarm


# --------------------------------------------------------------------------- seeding


def test_seed_is_honoured_and_swarms_differ():
    B, N = 4, 5
    venv = swarm_nav_v0.vec_env(B, n_agents=N)
    venv.seed(8)
    o1 = venv.reset()
    venv.seed(8)
    o2 = venv.reset()
    assert np.array_equal(o1, o2)
    blocks = o1.reshape(B, N, -1)
    assert all(not np.array_equal(blocks[i], blocks[j]) for i in range(B) for j in range(i))
    venv.seed(9)
    assert not np.array_equal(venv.reset(), o1)
    venv.seed(8)
    venv.reset()
    assert not np.array_equal(venv.reset(), o1)  # the seed is used once, not on every reset


def vec_rollout(seed: int, steps: int, **kwargs: Any) -> list[tuple]:
    venv = swarm_nav_v0.vec_env(4, n_agents=6, **kwargs)
    venv.seed(seed)
    trace: list[tuple] = [(venv.reset(),)]
    rng = np.random.default_rng(seed)
    for _ in range(steps):
        obs, rewards, dones, infos = venv.step(uniform_actions(rng, venv))
        terminal = [
            info["terminal_observation"] for info in infos if "terminal_observation" in info
        ]
        trace.append((obs, rewards, dones, *terminal))
    return trace


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_300_step_vec_rollouts_are_bit_identical(dtype: type):
    a = vec_rollout(10, 300, max_steps=70, dtype=dtype)
    b = vec_rollout(10, 300, max_steps=70, dtype=dtype)
    for ta, tb in zip(a, b, strict=True):
        assert len(ta) == len(tb)
        assert all(np.array_equal(x, y) and x.dtype == y.dtype for x, y in zip(ta, tb, strict=True))
    assert sum(len(t) > 3 for t in a) == 4  # four auto-resets happened along the way
    assert not np.array_equal(a[0][0], vec_rollout(11, 0)[0][0])


def test_global_rngs_untouched():
    before = rng_states()
    venv = swarm_nav_v0.vec_env(2, n_agents=4, max_steps=5)
    venv.seed(12)
    venv.reset()
    rng = np.random.default_rng(12)
    for _ in range(12):
        venv.step(uniform_actions(rng, venv))
    venv.reset()
    assert_same_rng_states(before, rng_states())


@pytest.mark.parametrize("module", [pickle, cloudpickle], ids=["pickle", "cloudpickle"])
def test_pickle_round_trip_reproduces_rollout(module: Any):
    venv = swarm_nav_v0.vec_env(2, n_agents=4, max_steps=8)
    venv.seed(13)
    venv.reset()
    rng = np.random.default_rng(13)
    for _ in range(3):
        venv.step(uniform_actions(rng, venv))
    clone = module.loads(module.dumps(venv))
    for _ in range(12):  # crosses an auto-reset: the generator state travelled too
        acts = uniform_actions(rng, venv)
        oa, ra, da, _ = venv.step(acts)
        ob, rb, db, _ = clone.step(acts)
        assert np.array_equal(oa, ob) and np.array_equal(ra, rb) and np.array_equal(da, db)


# --------------------------------------------------------------------------- bad input


@pytest.mark.parametrize("shape", [(12, 3), (13, 2), (24,), (2, 6, 2)])
def test_wrong_action_shape_raises(shape: tuple[int, ...]):
    venv = swarm_nav_v0.vec_env(3, n_agents=4)
    venv.reset()
    with pytest.raises(ValueError, match="shape"):
        venv.step(np.zeros(shape, np.float32))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf], ids=["nan", "inf", "-inf"])
def test_non_finite_actions_raise(bad: float):
    venv = swarm_nav_v0.vec_env(3, n_agents=4)
    venv.reset()
    actions = np.zeros((12, 2), np.float32)
    actions[5, 1] = bad
    with pytest.raises(ValueError, match="finite"):
        venv.step(actions)


@pytest.mark.parametrize(
    ("args", "kwargs", "name"),
    [
        ((0,), {}, "n_swarms"),
        ((-2,), {}, "n_swarms"),
        ((1.5,), {}, "n_swarms"),
        ((True,), {}, "n_swarms"),
        ((2,), {"n_agent": 3}, "n_agent"),
        ((2,), {"dt": -1}, "dt"),
        ((2,), {"physics": {"l_r": 0}}, "l_r"),
        ((2,), {"render_mode": "human"}, "render_mode"),
        ((2,), {"dtype": np.int32}, "dtype"),
    ],
)
def test_bad_constructor_arguments_raise(args: tuple, kwargs: dict[str, Any], name: str):
    with pytest.raises(ValueError, match=name):
        swarm_nav_v0.vec_env(*args, **kwargs)


def test_config_file_and_override():
    venv = swarm_nav_v0.vec_env(2, config="configs/env/paper_navigation.yaml", n_agents=7)
    assert venv.cfg.n_agents == 7 and venv.num_envs == 14 and venv.cfg.physics.C_o == 0.7


def test_step_wait_without_step_async_raises():
    venv = swarm_nav_v0.vec_env(1, n_agents=2)
    venv.reset()
    with pytest.raises(RuntimeError, match="step_async"):
        venv.step_wait()


# --------------------------------------------------------------------------- rendering


def test_rgb_array_images_per_swarm_and_tiled_render():
    venv = swarm_nav_v0.vec_env(3, n_agents=5, render_mode="rgb_array")
    venv.seed(14)
    venv.reset()
    images = venv.get_images()
    assert len(images) == 3
    for img in images:
        assert img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 3
        assert len(np.unique(img.reshape(-1, 3), axis=0)) > 2
    assert not np.array_equal(images[0], images[1])
    assert "rgb_array" in venv.metadata["render_modes"]
    tiled = venv.render()
    assert tiled.dtype == np.uint8 and tiled.ndim == 3 and tiled.shape[2] == 3
    for _ in range(10):
        venv.step(np.ones((15, 2), np.float32))
    assert not np.array_equal(venv.get_images()[0], images[0])
    venv.close()
    venv.close()


# --------------------------------------------------------------------------- training


def test_ppo_trains_on_the_vec_env_with_nan_checks():
    venv = VecCheckNan(swarm_nav_v0.vec_env(4, n_agents=4, max_steps=50), raise_exception=True)
    model = PPO(
        "MlpPolicy",
        venv,
        n_steps=64,
        batch_size=128,
        n_epochs=2,
        policy_kwargs={"net_arch": [16, 16]},
        seed=0,
        device="cpu",
    )
    model.learn(total_timesteps=2048)
    assert model.num_timesteps >= 2048
    obs = venv.reset()
    action, _ = model.predict(obs, deterministic=True)
    assert action.shape == (venv.num_envs, 2)
    assert np.all(np.abs(action) <= 1.0)


def test_quiet_slots_are_empty_writable_infos_and_swarm_infos_read_the_step():
    from swarm_envs.envs.adapters.vec_infos import QuietInfo, SwarmInfo

    venv = swarm_nav_v0.vec_env(2, n_agents=3, max_steps=50)
    venv.reset()
    _, _, _, infos = venv.step(np.zeros((6, 2), np.float32))
    assert isinstance(infos[0], SwarmInfo) and isinstance(infos[3], SwarmInfo)
    assert all(isinstance(infos[i], QuietInfo) and len(infos[i]) == 0 for i in (1, 2, 4, 5))
    first = infos[0].copy()
    assert first == {k: float(venv.last_stats[k][0]) for k in STAT_KEYS}
    infos[1]["x"] = 1
    assert infos[1] == {"x": 1} and dict(infos[2]) == {}
    later = venv.step(np.ones((6, 2), np.float32))[3]
    assert dict(later[1]) == {} and infos[1]["x"] == 1  # the write stays in its step
    assert later[2] is infos[2]  # an unwritten quiet info is reused
    assert infos[0].copy() == first  # an old step's info keeps its values


def test_swarm_infos_are_recycled_only_once_the_caller_dropped_them():
    venv = swarm_nav_v0.vec_env(4, n_agents=2, max_steps=10**6)
    venv.reset()
    zeros = np.zeros((8, 2), np.float32)
    first_ids = [id(info) for info in venv.step(zeros)[3][::2]]  # infos dropped here
    infos = venv.step(zeros)[3]
    assert [id(info) for info in infos[::2]] == first_ids  # the dropped set came back
    kept = infos[2]  # swarm 1's info of this step only, not its list
    values = kept.copy()
    assert values == {k: float(venv.last_stats[k][1]) for k in STAT_KEYS}
    del infos
    for _ in range(4):
        infos = venv.step(np.ones((8, 2), np.float32))[3]
        assert all(id(info) not in first_ids for info in infos[::2])  # `kept` pins its set
        assert kept.copy() == values
        assert infos[2].copy() == {k: float(venv.last_stats[k][1]) for k in STAT_KEYS}
        del infos


def test_a_dropped_list_of_infos_is_recycled_with_every_slot_quiet_again():
    from swarm_envs.envs.adapters.vec_infos import QuietInfo, SwarmInfo, TerminalInfo

    venv = swarm_nav_v0.vec_env(3, n_agents=2, max_steps=2)
    venv.reset()
    zeros = np.zeros((6, 2), np.float32)
    first_id = id(venv.step(zeros)[3])  # dropped at once
    infos = venv.step(zeros)[3]  # every swarm ends here: terminal infos in every slot
    assert id(infos) == first_id
    assert all(isinstance(info, TerminalInfo) for info in infos)
    infos[1]["mine"] = 1  # a write to an info, not to the list
    del infos
    again = venv.step(zeros)[3]
    assert id(again) == first_id
    assert [type(info) for info in again] == [SwarmInfo, QuietInfo] * 3
    assert all(len(again[i]) == 0 for i in (1, 3, 5))


def test_a_held_or_changed_list_of_infos_is_never_reused():
    venv = swarm_nav_v0.vec_env(2, n_agents=2, max_steps=10**6)
    venv.reset()
    zeros = np.zeros((4, 2), np.float32)
    held = venv.step(zeros)[3]
    snapshot = list(held)
    for _ in range(3):
        assert venv.step(zeros)[3] is not held
    assert list(held) == snapshot  # the VecEnv never wrote into it again
    changed = venv.step(zeros)[3]
    changed[1] = {"mine": 1}  # the caller's own change to the list
    del changed
    for _ in range(4):
        infos = venv.step(zeros)[3]
        assert dict(infos[1]) == {}


def test_a_partial_reset_does_not_rewrite_the_returned_statistics():
    venv = swarm_nav_v0.vec_env(3, n_agents=3, max_steps=2)
    venv.seed(0)
    venv.reset()
    venv.step(np.zeros((9, 2), np.float32))
    before = {k: v.copy() for k, v in venv.last_stats.items()}
    stats = venv.last_stats
    core = venv.cores[0]
    core.reset(np.random.default_rng(1), which=np.array([True, False, False]))
    for k in STAT_KEYS:
        np.testing.assert_array_equal(stats[k], before[k])


def test_terminal_infos_read_their_step_are_writable_and_recycled():
    from stable_baselines3.common.vec_env import VecNormalize

    from swarm_envs.envs.adapters.vec_infos import TERMINAL_KEYS, TerminalInfo

    B, N, T = 2, 3, 2
    venv = swarm_nav_v0.vec_env(B, n_agents=N, max_steps=T)
    twin = swarm_nav_v0.vec_env(B, n_agents=N, max_steps=10 * T)  # no reset at T
    zero = np.zeros((venv.num_envs, 2), np.float32)
    for e in (venv, twin):
        e.seed(5)
        e.reset()
    for _ in range(T):
        _, _, dones, infos = venv.step(zero)
        before, *_ = twin.step(zero)  # at T: the last observation of the episode
    assert dones.all() and all(isinstance(info, TerminalInfo) for info in infos)
    first, other = infos[0], infos[1]
    assert list(first) == [*STAT_KEYS, *TERMINAL_KEYS] and len(first) == len(STAT_KEYS) + 4
    assert list(other) == list(TERMINAL_KEYS) and "success" not in other
    with pytest.raises(KeyError):
        other["success"]
    for i, info in enumerate(infos):
        assert np.array_equal(info["terminal_observation"], before[i])
    assert first["episode"] is first["swarm_episode"] and first["episode"]["l"] == T
    assert first["mean_goal_distance"] == float(venv.last_stats["mean_goal_distance"][0])
    # Writable: a write copies the info into a dict of its own (VecNormalize does this).
    other["terminal_observation"] = np.zeros(3, np.float32)
    del other["TimeLimit.truncated"]
    assert other["terminal_observation"].shape == (3,) and "TimeLimit.truncated" not in other
    assert isinstance(other.copy(), dict) and len(other) == 3
    # A kept info keeps its step; the next end takes a free set, or a new one.
    kept_first = first.copy()
    for _ in range(T):
        _, _, dones, later = venv.step(zero)
    assert dones.all() and later[0] is not first
    assert first.copy().keys() == kept_first.keys()
    assert np.array_equal(first["terminal_observation"], kept_first["terminal_observation"])
    written = id(other)
    del first, other, info, infos, later
    for _ in range(T):  # sets recycled once dropped, the oldest first: a written info
        _, _, _, infos = venv.step(zero)  # reads the record again
    assert id(infos[1]) == written and list(infos[1]) == list(TERMINAL_KEYS)
    assert infos[1]["TimeLimit.truncated"] is True
    # Pickled, the pools carry their sizes only, not their sets of infos.
    assert len(pickle.dumps(venv._terminal_infos)) < 200
    assert len(pickle.dumps(venv._swarm_infos)) < 200
    # SB3's VecNormalize normalises the terminal observations in place.
    norm = VecNormalize(swarm_nav_v0.vec_env(B, n_agents=N, max_steps=T), norm_reward=False)
    norm.reset()
    for _ in range(T):
        _, _, dones, infos = norm.step(zero)
    assert dones.all()
    assert all(np.all(np.abs(info["terminal_observation"]) <= norm.clip_obs) for info in infos)
