"""The VecEnv split over worker threads steps exactly like one core."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from swarm_envs import swarm_nav_v0

# Worker threads split the numpy backends (the C step threads inside).
KW = {"n_agents": 5, "max_steps": 12, "n_neighbors": 3, "backend": "numpy"}


def copy_state(src_cores, dst_core) -> None:
    """Put the swarms of several cores, in order, into one core of the same total batch."""
    for name in ("x", "v", "goal", "t"):
        setattr(dst_core, name, np.concatenate([getattr(c, name) for c in src_cores]).copy())
    for name in ("prev", "start"):  # the reward's previous and start statistics
        records = [c.task.records for c in src_cores]
        keys = getattr(records[0], name)
        merged = {k: np.concatenate([getattr(r, name)[k] for r in records]) for k in keys}
        setattr(dst_core.task.records, name, merged)
    from swarm_envs.physics import pair_geometry

    dst_core._geometry = pair_geometry(dst_core.x)
    dst_core._measure()  # the statistics and the carried force of the copied state


def test_threaded_step_equals_single_core_step_from_the_same_state():
    threaded = swarm_nav_v0.vec_env(6, n_threads=3, **KW)
    single = swarm_nav_v0.vec_env(6, n_threads=1, **KW)
    threaded.seed(0)
    threaded.reset()
    single.seed(0)
    single.reset()
    copy_state(threaded.cores, single.core)
    rng = np.random.default_rng(1)
    for _ in range(30):  # crosses several auto-resets (max_steps = 12)
        actions = rng.uniform(-1, 1, (threaded.num_envs, 2)).astype(np.float32)
        o1, r1, d1, i1 = threaded.step(actions)
        o2, r2, d2, i2 = single.step(actions)
        if d1.any():  # the new starts come from different generator orders: re-sync
            np.testing.assert_array_equal(d1, d2)
            for a, b in zip(i1, i2, strict=True):
                if "terminal_observation" in a:
                    np.testing.assert_array_equal(
                        a["terminal_observation"], b["terminal_observation"]
                    )
            copy_state(threaded.cores, single.core)
            continue
        np.testing.assert_array_equal(o1, o2)
        np.testing.assert_array_equal(r1, r2)
        assert i1[0]["energy"] == i2[0]["energy"]


def rollout(n_threads: int, seed: int) -> np.ndarray:
    venv = swarm_nav_v0.vec_env(8, n_threads=n_threads, **KW)
    venv.seed(seed)
    obs = [venv.reset()]
    rng = np.random.default_rng(seed + 1)
    for _ in range(40):
        obs.append(venv.step(rng.uniform(-1, 1, (venv.num_envs, 2)).astype(np.float32))[0])
    venv.close()
    return np.array(obs)


def test_threaded_rollouts_are_reproducible_and_seeded():
    a, b = rollout(2, seed=4), rollout(2, seed=4)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a[0], rollout(2, seed=5)[0])


def test_threaded_env_pickles_and_continues_identically():
    venv = swarm_nav_v0.vec_env(4, n_threads=2, **KW)
    venv.seed(0)
    venv.reset()
    actions = np.full((venv.num_envs, 2), 0.5, np.float32)
    venv.step(actions)
    clone = pickle.loads(pickle.dumps(venv))
    for _ in range(15):
        np.testing.assert_array_equal(venv.step(actions)[0], clone.step(actions)[0])
    venv.close()
    venv.close()  # twice is safe


def test_default_threads_follow_the_batch_size():
    assert swarm_nav_v0.vec_env(16, **KW).n_threads == 1
    big = swarm_nav_v0.vec_env(1024, n_agents=2, n_neighbors=1, backend="numpy")
    assert 1 <= big.n_threads <= 2
    assert sum(c.batch for c in big.cores) == 1024


@pytest.mark.parametrize("bad", [0, 9, 1.5, True, "2"])
def test_bad_thread_counts_raise(bad):
    with pytest.raises(ValueError, match="n_threads must"):
        swarm_nav_v0.vec_env(8, n_threads=bad, **KW)


def test_core_property_needs_a_single_core():
    with pytest.raises(AttributeError, match=r"use \.cores"):
        _ = swarm_nav_v0.vec_env(4, n_threads=2, **KW).core
