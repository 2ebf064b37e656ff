"""The envs in the ecosystem's vector APIs: Gymnasium's ``make_vec`` (the batched vector
env, async workers), SuperSuit's multiprocess concat, SB3's evaluation helpers, and the
SB3 VecEnv's infos as dicts (copy, deepcopy, pickle)."""

from __future__ import annotations

import copy
import multiprocessing as mp
import pickle
import warnings
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

from swarm_envs import ENV_ID, swarm_nav_v0
from swarm_envs.envs.adapters.gym_vector import SwarmNavVectorEnv
from swarm_envs.envs.adapters.vec_env import SlotEpisodesWarning

SMALL: dict[str, Any] = {"n_agents": 5, "max_steps": 6}


def _actions(rng: np.random.Generator, venv: gym.vector.VectorEnv) -> np.ndarray:
    return rng.uniform(-1, 1, venv.action_space.shape).astype(np.float32)


# ---------------------------------------------------------------- Gymnasium vector env
def test_make_vec_builds_the_batched_vector_env_with_batched_spaces():
    single = gym.make(ENV_ID, **SMALL)
    venv = gym.make_vec(ENV_ID, num_envs=3, **SMALL)
    assert isinstance(venv, SwarmNavVectorEnv)
    assert venv.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
    assert venv.single_observation_space == single.observation_space
    assert venv.single_action_space == single.action_space
    assert venv.observation_space.shape == (3, *single.observation_space.shape)
    assert venv.action_space.shape == (3, *single.action_space.shape)
    obs, info = venv.reset(seed=0)
    assert obs in venv.observation_space
    assert set(info) >= {"success", "_success"}
    assert info["_success"].all()


@pytest.mark.parametrize("backend", ["auto", "numpy"])
def test_vector_env_rollout_equals_sync_vector_env_of_gym_make(backend: str):
    """Seeds map to sub-envs as in SyncVectorEnv (seed + i), autoresets included."""
    kw = {**SMALL, "backend": backend}
    batched = gym.make_vec(ENV_ID, num_envs=3, **kw)
    sync = gym.make_vec(ENV_ID, num_envs=3, vectorization_mode="sync", **kw)
    assert sync.metadata["autoreset_mode"] is batched.metadata["autoreset_mode"]
    o1, _ = batched.reset(seed=11)
    o2, _ = sync.reset(seed=11)
    np.testing.assert_allclose(o1, o2, rtol=0, atol=1e-6)
    rng = np.random.default_rng(0)
    ended = 0
    for _ in range(3 * SMALL["max_steps"] + 2):
        a = _actions(rng, batched)
        r1, r2 = batched.step(a), sync.step(a)
        for x, y in zip(r1[:4], r2[:4], strict=True):
            np.testing.assert_allclose(x, y, rtol=0, atol=1e-6)
        for key in ("success", "mean_goal_distance"):
            np.testing.assert_allclose(r1[4][key], r2[4][key], rtol=0, atol=1e-6)
        ended += int(r1[3].sum())
    assert ended >= 6  # the autoresets were exercised


def test_next_step_autoreset_ignores_the_action_and_returns_the_new_start():
    venv = SwarmNavVectorEnv(2, **SMALL)
    venv.reset(seed=3)
    zero = np.zeros(venv.action_space.shape, np.float32)
    for t in range(1, SMALL["max_steps"] + 1):
        _, _, terminated, truncated, _ = venv.step(zero)
        assert not terminated.any()
        assert truncated.all() == (t == SMALL["max_steps"])
    # The next step restarts both sub-envs: same as a fresh env seeded the same way
    # after one episode (the generators continue).
    obs, reward, terminated, truncated, _ = venv.step(np.ones(venv.action_space.shape))
    assert not terminated.any() and not truncated.any()
    assert (reward == 0).all()
    ref = SwarmNavVectorEnv(2, **SMALL)
    ref.reset(seed=3)
    ref._reset_swarms(np.ones(2, bool))  # the second draw of each sub-env's generator
    np.testing.assert_array_equal(obs, ref.core.observe().reshape(2, -1))


def test_vector_env_reset_seed_list_and_reset_mask():
    venv = SwarmNavVectorEnv(3, **SMALL)
    a, _ = venv.reset(seed=[7, 8, 9])
    b, _ = SwarmNavVectorEnv(3, **SMALL).reset(seed=7)
    np.testing.assert_array_equal(a, b)
    venv.step(np.zeros(venv.action_space.shape))
    before = venv.core.observe().reshape(3, -1)
    after, _ = venv.reset(options={"reset_mask": np.array([False, True, False])})
    np.testing.assert_array_equal(after[[0, 2]], before[[0, 2]])
    assert not np.array_equal(after[1], before[1])


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"num_envs": 0}, "num_envs must be an integer >= 1"),
        ({"num_envs": 2, "max_episode_steps": 9}, "max_steps"),
        ({"num_envs": 2, "render_mode": "human"}, "render_mode must be None or 'rgb_array'"),
    ],
)
def test_vector_env_refuses_bad_arguments(kwargs: dict[str, Any], match: str):
    with pytest.raises(ValueError, match=match):
        SwarmNavVectorEnv(**kwargs)


def test_vector_env_refuses_bad_seeds_and_actions():
    venv = SwarmNavVectorEnv(2, **SMALL)
    with pytest.raises(ValueError, match="list of 2 seeds"):
        venv.reset(seed=[1])
    with pytest.raises(ValueError):
        venv.reset(seed=-1)
    venv.reset(seed=0)
    with pytest.raises(ValueError):
        venv.step(np.zeros((2, 3)))
    with pytest.raises(ValueError):
        venv.step(np.full(venv.action_space.shape, np.nan))


def test_vector_env_renders_one_frame_per_sub_env():
    venv = SwarmNavVectorEnv(2, render_mode="rgb_array", **SMALL)
    venv.reset(seed=0)
    frames = venv.render()
    assert len(frames) == 2
    assert all(f.dtype == np.uint8 and f.ndim == 3 for f in frames)


# ---------------------------------------------------------------- episode length
def test_gym_make_runs_max_steps_not_a_registered_time_limit():
    env = gym.make(ENV_ID, max_steps=1000)
    env.reset(seed=3)
    zero = np.zeros(env.action_space.shape, np.float32)
    steps = 0
    while True:
        _, _, terminated, truncated, _ = env.step(zero)
        steps += 1
        if terminated or truncated:
            break
    assert (steps, terminated, truncated) == (1000, False, True)


# ---------------------------------------------------------------- forked workers
def _step_in_parent(backend: str, n_agents: int, n_swarms: int) -> None:
    """Run the backend's threads in this process before it forks."""
    venv = swarm_nav_v0.vec_env(n_swarms, n_agents=n_agents, backend=backend)
    assert venv.backend == backend
    venv.reset()
    for _ in range(2):
        venv.step(np.zeros((venv.num_envs, 2)))


@pytest.mark.skipif(mp.get_start_method() != "fork", reason="the hazard is fork()")
@pytest.mark.parametrize("backend, n_agents, n_swarms", [("cutoff", 600, 1), ("native", 8, 4)])
def test_async_make_vec_works_after_the_parent_ran_openmp(
    backend: str, n_agents: int, n_swarms: int
):
    _step_in_parent(backend, n_agents, n_swarms)
    venv = gym.make_vec(
        ENV_ID,
        num_envs=2,
        vectorization_mode="async",
        n_agents=n_agents,
        backend=backend,
    )
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # the children's numpy fallback
            venv.reset(seed=0)
            for _ in range(3):
                obs, *_ = venv.step(venv.action_space.sample())
        assert obs.shape[0] == 2 and np.isfinite(obs).all()
    finally:
        venv.close()


def _batched_native_steps(queue: Any) -> None:
    venv = swarm_nav_v0.vec_env(4, n_agents=8, backend="native")
    venv.reset()
    venv.step(np.zeros((venv.num_envs, 2)))
    queue.put(venv.backend)


@pytest.mark.skipif(mp.get_start_method() != "fork", reason="the hazard is fork()")
def test_forked_child_steps_a_native_batch_after_the_parent_did():
    _step_in_parent("native", 8, 4)
    ctx = mp.get_context("fork")
    queue = ctx.Queue()
    child = ctx.Process(target=_batched_native_steps, args=(queue,))
    child.start()
    child.join(60)
    if child.is_alive():  # GNU OpenMP's inherited thread pool: a deadlock
        child.kill()
        pytest.fail("the forked child hung in the C step's OpenMP region")
    assert child.exitcode == 0 and queue.get(timeout=5) == "native"


@pytest.mark.skipif(mp.get_start_method() != "fork", reason="the hazard is fork()")
@pytest.mark.parametrize("backend, n_agents", [("cutoff", 600), ("native", 8)])
def test_supersuit_multiprocess_concat_after_the_parent_ran_openmp(backend: str, n_agents: int):
    ss = pytest.importorskip("supersuit")
    _step_in_parent(backend, n_agents, 1 if backend == "cutoff" else 4)
    par = swarm_nav_v0.parallel_env(n_agents=n_agents, backend=backend)
    vec = ss.pettingzoo_env_to_vec_env_v1(par)
    venv = ss.concat_vec_envs_v1(vec, 2, num_cpus=2, base_class="stable_baselines3")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            venv.reset()
            for _ in range(3):
                obs, *_ = venv.step(np.zeros((venv.num_envs, 2), np.float32))
        assert obs.shape[0] == 2 * n_agents and np.isfinite(obs).all()
    finally:
        venv.close()


# ---------------------------------------------------------------- SB3 evaluation
def test_sb3_evaluation_warns_once_that_it_counts_agents():
    from stable_baselines3.common.evaluation import evaluate_policy

    class ZeroPolicy:
        def predict(self, obs, state=None, episode_start=None, deterministic=True):
            return np.zeros((len(obs), 2), np.float32), None

    venv = swarm_nav_v0.vec_env(2, n_agents=5, max_steps=4)
    with pytest.warns(SlotEpisodesWarning) as caught:
        _, std = evaluate_policy(ZeroPolicy(), venv, n_eval_episodes=5)
    assert len([w for w in caught if w.category is SlotEpisodesWarning]) == 1
    assert std == 0.0  # five agents of one swarm episode: what the warning says


def test_sb3_evaluate_policy_and_eval_callback_see_the_monitor_info():
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import EvalCallback
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.monitor import Monitor

    class ZeroPolicy:
        """SB3's predict protocol: the zero action for every slot."""

        def predict(
            self,
            obs: np.ndarray,
            state: Any = None,
            episode_start: Any = None,
            deterministic: bool = True,
        ) -> tuple[np.ndarray, None]:
            return np.zeros((len(obs), 2), np.float32), None

    venv = swarm_nav_v0.vec_env(2, n_agents=3, max_steps=5)
    with pytest.warns(SlotEpisodesWarning, match="one episode per agent") as caught:
        assert venv.env_is_wrapped(Monitor) == [True] * venv.num_envs
    assert "n_eval_episodes=3 is a single swarm episode" in str(caught[0].message)
    assert venv.env_is_wrapped(gym.Wrapper) == [False] * venv.num_envs
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no Monitor warning, and ours only once
        mean, _ = evaluate_policy(ZeroPolicy(), venv, n_eval_episodes=6)
        model = PPO("MlpPolicy", venv, n_steps=4, batch_size=24, n_epochs=1, seed=0)
        callback = EvalCallback(venv, n_eval_episodes=6, eval_freq=4, verbose=0)
        model.learn(total_timesteps=48, callback=callback)  # evaluates with warn=True
    assert np.isfinite(callback.last_mean_reward)  # it did evaluate
    assert np.isfinite(mean)


# ---------------------------------------------------------------- infos as dicts
def _infos_with_every_kind() -> list[Any]:
    venv = swarm_nav_v0.vec_env(3, n_agents=4, max_steps=2)
    venv.reset()
    zero = np.zeros((venv.num_envs, 2))
    venv.step(zero)
    _, _, dones, infos = venv.step(zero)  # every swarm ends: terminal infos
    assert dones.all()
    first = venv.step(zero)[3]  # statistics and quiet slots
    return [first, infos]


def test_vec_env_infos_are_dicts_that_json_takes():
    import json

    def same(a: dict, b: dict) -> bool:
        return list(a) == list(b) and all(np.array_equal(a[k], b[k]) for k in a)

    kinds = set()
    for infos in _infos_with_every_kind():
        for info in infos:
            assert isinstance(info, dict)
            kinds.add(type(info).__name__)
            plain = {key: info[key] for key in info}
            for other in (dict(info), {**info}, info.copy(), dict(info.items())):
                assert type(other) is dict and same(other, plain)
            assert same(dict(zip(info, info.values(), strict=True)), plain)
            assert all(np.array_equal(info.get(key), plain[key]) for key in plain)
            assert info.get("no such key", 7) == 7 and len(info) == len(plain)
            if "terminal_observation" in info:  # an array: json needs it as a list
                plain["terminal_observation"] = plain["terminal_observation"].tolist()
                info = {**info, "terminal_observation": plain["terminal_observation"]}
            assert json.loads(json.dumps(info)) == plain
    assert kinds == {"SwarmInfo", "QuietInfo", "TerminalInfo"}
    # Written through any dict method, an info keeps what was written.
    swarm = _infos_with_every_kind()[0][0]
    swarm.update(extra=1)
    assert swarm["extra"] == 1 and json.loads(json.dumps(swarm))["extra"] == 1
    assert swarm.setdefault("polarization", -1.0) != -1.0


def test_vec_env_infos_copy_deepcopy_and_pickle_as_plain_dicts():
    for infos in _infos_with_every_kind():
        expected = [dict(info) for info in infos]
        for copied in (copy.deepcopy(infos), pickle.loads(pickle.dumps(infos))):
            assert type(copied) is list
            assert all(type(info) is dict for info in copied)
            assert [info.keys() for info in copied] == [info.keys() for info in expected]
            for a, b in zip(copied, expected, strict=True):
                for key in a:
                    np.testing.assert_array_equal(a[key], b[key])
            copied[1]["mine"] = 1  # each slot its own dict
            assert sum("mine" in info for info in copied) == 1
        for info in infos:
            for made in (copy.copy(info), copy.deepcopy(info), info.copy()):
                assert type(made) is dict and made.keys() == dict(info).keys()
            assert type(pickle.loads(pickle.dumps(info))) is dict


def test_vec_env_swarm_and_terminal_infos_are_writable_and_keep_their_step():
    venv = swarm_nav_v0.vec_env(2, n_agents=3, max_steps=50)
    venv.reset()
    zero = np.zeros((venv.num_envs, 2))
    infos = venv.step(zero)[3]
    kept = infos[0]
    value = kept["mean_goal_distance"]
    kept["mean_goal_distance"] = -1.0
    kept["note"] = "mine"
    assert kept["mean_goal_distance"] == -1.0 and kept["note"] == "mine"
    for _ in range(3):
        later = venv.step(zero)[3]
        assert later[0] is not kept and "note" not in later[0]
    assert kept["note"] == "mine" and value != -1.0
    infos[1]["x"] = 1  # a quiet slot's info is writable too, in its own step only
    assert infos[1]["x"] == 1 and "x" not in venv.step(zero)[3][1]
