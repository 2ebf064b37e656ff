"""The C step (swarm_envs.envs.native_step) behind TorchSwarmNavCore on the CPU.

The same rollouts as the numpy core (every config of the torch core's tests, float32 and
float64), and as plain torch at batch 64 (the sub-batch resets) for swarms that fill
more than one block of 16 lanes; results independent of the thread count; coincident
agents; pickling; the switches (``native=``, ``SWARM_ENVS_NATIVE``) and the fallbacks
(no compiler, too many neighbours); the build cache.
"""

from __future__ import annotations

import pickle

import numpy as np
import pytest
import torch
from helpers import CORE_CONFIGS, CORE_TOL, assert_same_rollout, make_config, rollout

from swarm_envs import swarm_nav_v0
from swarm_envs.config import SwarmConfig
from swarm_envs.envs import native_step
from swarm_envs.envs.core import SwarmNavCore
from swarm_envs.envs.native_step import NativeAdvance, native_support, resolve_native
from swarm_envs.envs.torch_core import TorchSwarmNavCore
from swarm_envs.physics import torch_backend as tb

SUPPORTED, WHY = native_support()
needs_native = pytest.mark.skipif(not SUPPORTED, reason=f"C step unavailable: {WHY}")


@pytest.fixture
def fresh_library(monkeypatch, tmp_path):
    """The loader's state reset (and restored afterwards), its cache in ``tmp_path``."""
    monkeypatch.setattr(native_step, "_LIBRARY", None)
    monkeypatch.setattr(native_step, "_FAILURE", None)
    monkeypatch.setenv("SWARM_ENVS_CACHE", str(tmp_path))
    monkeypatch.delenv(native_step.NATIVE_ENV, raising=False)
    return tmp_path


@needs_native
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("name", list(CORE_CONFIGS))
def test_same_rollout_as_the_numpy_core(name, dtype):
    cfg = make_config(CORE_CONFIGS[name])
    core = TorchSwarmNavCore(cfg, batch=4, dtype=dtype, native=True)
    assert core.kernel == "native" and not core.compiled
    ref = rollout(SwarmNavCore(cfg, batch=4, dtype=dtype), seed=7, steps=36, reset_every=12)
    ours = rollout(core, seed=7, steps=36, reset_every=12)
    assert_same_rollout(ours, ref, CORE_TOL[dtype])


NATIVE_VS_PLAIN = {
    # 20 and 37 agents: two and three blocks of 16 lanes, the last one padded.
    "two_blocks": dict(n_agents=20, n_neighbors=8),
    "three_blocks_3d_goal": dict(n_agents=37, dim=3, goal_in_physics=True, collision_radius=0.6),
    "no_alignment_equal_lengths": dict(
        n_agents=17, physics={"C_o": 0.0, "l_r": 1.0, "C_r": 0.5, "beta": 0.0}
    ),
    "many_neighbours": dict(n_agents=12, n_neighbors=15),  # k > N − 1: padding slots
    # An odd k with no padding: the observation's last block is one of a pair's lanes.
    "odd_neighbours_3d": dict(n_agents=9, n_neighbors=7, dim=3),
}


@needs_native
@pytest.mark.parametrize("name", list(NATIVE_VS_PLAIN))
def test_same_rollout_as_plain_torch_with_sub_batch_resets(name):
    cfg = make_config({**NATIVE_VS_PLAIN[name], "max_steps": 16})
    native = TorchSwarmNavCore(cfg, batch=64, native=True)
    assert native.reset_batch == 4 and native._advance_part is native._advance
    plain = TorchSwarmNavCore(cfg, batch=64, compile=False, native=False)
    assert plain.kernel == "plain"
    assert_same_rollout(
        rollout(native, seed=3, steps=20, reset_every=4, few=True),
        rollout(plain, seed=3, steps=20, reset_every=4, few=True),
        CORE_TOL[np.float32],
    )


@needs_native
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_resets_measure_exactly_the_reset_swarms_in_place(monkeypatch, dtype):
    # A reset of n < B swarms re-measures those n alone, in place (measure_rows: no
    # step of the batch, no copy of the observations when none were handed out; 10 >
    # reset_batch = 4 too); a reset of all B measures the whole batch. The results
    # match the numpy core, and observe(which=...) hands out nothing.
    cfg = SwarmConfig(n_agents=6, n_neighbors=3)
    core = TorchSwarmNavCore(cfg, batch=64, dtype=dtype, native=True)
    ref = SwarmNavCore(cfg, batch=64, dtype=dtype)
    rows_measured: list[int] = []
    batches: list[int] = []
    measure_rows, call = NativeAdvance.measure_rows, NativeAdvance.__call__
    monkeypatch.setattr(
        NativeAdvance,
        "measure_rows",
        lambda self, rows, *a: rows_measured.append(len(rows)) or measure_rows(self, rows, *a),
    )
    monkeypatch.setattr(
        NativeAdvance, "__call__", lambda self, *a: batches.append(a[0].shape[1]) or call(self, *a)
    )
    rng, ref_rng = np.random.default_rng(4), np.random.default_rng(4)
    core.reset(rng)
    ref.reset(ref_rng)
    actions = np.random.default_rng(5).uniform(-1, 1, (64, 6, 2)).astype(dtype)
    for swarms in ([0], [1, 3, 5, 7, 9, 10, 11, 12, 13, 14], list(range(63)), list(range(64))):
        core.step(actions)
        ref.step(actions)
        which = np.isin(np.arange(64), swarms)
        n = len(swarms)
        last = core.observe(which=which)  # a copy of those rows
        np.testing.assert_allclose(last, ref.observe(which=which), **CORE_TOL[dtype])
        obs_memory = core._obs.data_ptr()
        rows_measured.clear()
        batches.clear()
        core.reset(rng, which=which)
        ref.reset(ref_rng, which=which)
        if n < 64:
            assert rows_measured == [n] and batches == []
            assert core._obs.data_ptr() == obs_memory  # nothing handed out: in place
        else:
            assert rows_measured == [] and batches == [64]
        assert not np.array_equal(core.observe(which=which), last)  # new starts
        np.testing.assert_allclose(core.observe(), ref.observe(), **CORE_TOL[dtype])
        for key, value in core.stats().items():
            np.testing.assert_allclose(value, ref.stats()[key], **CORE_TOL[dtype], err_msg=key)
        np.testing.assert_allclose(core.start_distance, ref.start_distance, **CORE_TOL[dtype])
        np.testing.assert_allclose(core.prev_distance, ref.prev_distance, **CORE_TOL[dtype])
        np.testing.assert_allclose(core.prev_arrived, ref.prev_arrived, **CORE_TOL[dtype])


@needs_native
def test_measure_rows_checks_what_it_writes_in_place_and_compile_time_counts_once():
    core = TorchSwarmNavCore(SwarmConfig(n_agents=5), batch=64, native=True)
    assert core.compile_seconds == core._native.compile_seconds  # one function, once
    core.reset(np.random.default_rng(0))
    args = core._args(core._no_action, core._move_none)
    packed = torch.from_numpy(core._packed)
    rows = np.array([1, 2])
    with pytest.raises(ValueError, match="obs must be float32"):
        core._native.measure_rows(rows, args, core._obs[:10], packed)
    with pytest.raises(ValueError, match="packed must be"):
        core._native.measure_rows(rows, args, core._obs, packed[:, :5])
    with pytest.raises(ValueError, match="rows must be swarms"):
        core._native.measure_rows(np.array([64]), args, core._obs, packed)


@needs_native
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_results_do_not_depend_on_the_thread_count(dtype):
    cfg = SwarmConfig(n_agents=9, dim=3)
    np_dtype = np.float32 if dtype == torch.float32 else np.float64
    core = TorchSwarmNavCore(cfg, batch=11, dtype=np_dtype, native=True)
    core.reset(np.random.default_rng(1))
    a = torch.from_numpy(np.random.default_rng(2).uniform(-1, 1, (11, 9, 3))).to(dtype)
    args = core._args(a, core._move_all)
    step, threads = NativeAdvance(cfg), torch.get_num_threads()
    outs = []
    try:
        for n in (1, 2, 5):
            torch.set_num_threads(n)  # the kernel runs on torch's OpenMP pool
            outs.append(step(*args))
    finally:
        torch.set_num_threads(threads)
    for out in outs[1:]:
        for ours, ref in zip(out[:7], outs[0][:7], strict=True):
            assert torch.equal(ours, ref)


@needs_native
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf], ids=["nan", "inf", "-inf"])
def test_non_finite_actions_raise_in_the_c_step_and_change_nothing(dtype, bad):
    # The C step checks the actions itself (the core skips numpy's isfinite and clip):
    # any NaN or inf, in the first or the last swarm, raises before anything is
    # written; finite values beyond [-1, 1] are clipped as numpy clips them.
    cfg = SwarmConfig(n_agents=5, max_steps=50)
    core = TorchSwarmNavCore(cfg, batch=3, dtype=dtype, native=True)
    core.reset(np.random.default_rng(0))
    x, v, t, obs = core.x, core.v, core.t.copy(), core.observe().copy()
    for where in [(0, 0, 0), (2, 4, 1)]:
        actions = np.zeros((3, 5, 2), dtype)
        actions[where] = bad
        with pytest.raises(ValueError, match="finite"):
            core.step(actions)
        assert np.array_equal(core.x, x) and np.array_equal(core.v, v)
        assert np.array_equal(core.t, t) and np.array_equal(core.observe(), obs)
    big = np.random.default_rng(1).uniform(-4, 4, (3, 5, 2)).astype(dtype)
    twin = pickle.loads(pickle.dumps(core))
    got, ref = core.step(big), twin.step(np.clip(big, -1, 1))
    assert np.array_equal(got[0], ref[0]) and np.array_equal(core.x, twin.x)
    assert np.array_equal(core.observe(), twin.observe())


@needs_native
def test_inlined_float32_exp_is_within_3_ulp_and_flushes_below_the_normal_range():
    # exp_f32, the exponential of the float32 pair loop (its arguments are -r/l <= 0):
    # within 4e-7 relative of the float64 exp from -87.28 (e^x = 1.2e-38, the smallest
    # normal numbers) up to 88.3, 0 below (the subnormal range, flushed), finite and
    # clamped above.
    import ctypes

    lib = native_step._load()
    fn = lib.fused_exp_f32
    fn.restype = None
    fn.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int64]
    x = np.concatenate(
        [np.linspace(-120, 95, 400_001), [-87.28, -87.279, 0.0, -0.0, 88.3, 1e30, -1e30]]
    ).astype(np.float32)
    y = np.empty_like(x)
    fn(x.ctypes.data, y.ctypes.data, x.size)
    with np.errstate(over="ignore"):
        ref = np.exp(x.astype(np.float64))
    normal = (x >= np.float32(-87.28)) & (x <= np.float32(88.3))
    np.testing.assert_allclose(y[normal], ref[normal], rtol=4e-7, atol=0)
    assert (y[x < np.float32(-87.28)] == 0).all()
    assert np.isfinite(y).all() and (y[x > 88.3] == y[x == np.float32(88.3)][0]).all()


@needs_native
def test_coincident_agents_stay_finite():
    cfg = SwarmConfig(n_agents=5, collision_radius=0.5)
    core = TorchSwarmNavCore(cfg, batch=2, native=True)
    core.reset(np.random.default_rng(0))
    core.x = np.zeros((2, 5, 2))
    core.v = np.zeros((2, 5, 2))
    reward, *_, stats = core.step(np.ones((2, 5, 2)))
    assert np.isfinite(core.observe()).all() and np.isfinite(reward).all()
    assert all(np.isfinite(value).all() for value in stats.values())
    ref = TorchSwarmNavCore(cfg, batch=2, compile=False, native=False)
    ref.reset(np.random.default_rng(0))
    ref.x, ref.v = np.zeros((2, 5, 2)), np.zeros((2, 5, 2))
    ref_reward, *_, ref_stats = ref.step(np.ones((2, 5, 2)))
    np.testing.assert_allclose(reward, ref_reward, **CORE_TOL[np.float32])
    np.testing.assert_allclose(core.observe(), ref.observe(), **CORE_TOL[np.float32])
    assert stats["collisions"].tolist() == ref_stats["collisions"].tolist() == [10.0, 10.0]


@needs_native
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_equal_distances_rank_neighbours_by_index(dtype):
    # Agents on a lattice: many pairs at exactly the same distance, and the tiles hand
    # candidates over in rotated order. Distinct velocities make the order visible in
    # the observations; it must be the (ρ, j) order of the torch step.
    N = 37  # three blocks of 16 lanes (five of 8 in float64): tiles (J, I) with J < I
    cfg = SwarmConfig(n_agents=N, n_neighbors=8)
    idx = np.arange(N)
    x = np.stack([idx % 7, idx // 7], axis=-1) * 0.5
    v = np.stack([idx * 0.01, -idx * 0.02], axis=-1)
    cores = [
        TorchSwarmNavCore(cfg, batch=2, dtype=dtype, native=True),
        TorchSwarmNavCore(cfg, batch=2, dtype=dtype, compile=False, native=False),
    ]
    for core in cores:
        core.reset(np.random.default_rng(0))
        core.x, core.v = np.stack([x, x[::-1]]), np.stack([v, v])
    obs, ref = cores[0].observe(), cores[1].observe()
    np.testing.assert_allclose(obs, ref, **CORE_TOL[dtype])
    ranked = obs[..., 2 * 2 :].reshape(2, N, 8, 5)[..., 2:4]  # neighbours' relative velocity
    assert np.unique(ranked.round(6), axis=2).shape[2] == 8  # the order is visible


@needs_native
def test_pickle_round_trip_keeps_the_native_step():
    core = TorchSwarmNavCore(SwarmConfig(n_agents=5), batch=3, native=True)
    core.reset(np.random.default_rng(0))
    clone = pickle.loads(pickle.dumps(core))
    assert clone.kernel == "native"
    for a in np.random.default_rng(4).uniform(-1, 1, (4, 3, 5, 2)):
        np.testing.assert_array_equal(core.step(a)[0], clone.step(a)[0])
        np.testing.assert_array_equal(core.observe(), clone.observe())


@needs_native
def test_auto_uses_it_unless_a_torch_path_is_asked_for(monkeypatch):
    monkeypatch.delenv(native_step.NATIVE_ENV, raising=False)
    cfg = SwarmConfig(n_agents=4)
    assert TorchSwarmNavCore(cfg, batch=2).kernel == "native"
    core = TorchSwarmNavCore(cfg, batch=2, compile=False)
    assert core.kernel == "plain" and "compile=False" in core.native_reason
    monkeypatch.setenv(native_step.NATIVE_ENV, "0")
    monkeypatch.setenv(tb.COMPILE_ENV, "0")
    assert TorchSwarmNavCore(cfg, batch=2).kernel == "plain"
    monkeypatch.setenv(native_step.NATIVE_ENV, "sometimes")
    with pytest.raises(ValueError, match="SWARM_ENVS_NATIVE must be 0, 1 or auto"):
        TorchSwarmNavCore(cfg, batch=2)
    with pytest.raises(ValueError, match="native must be 'auto', True or False"):
        TorchSwarmNavCore(cfg, batch=2, native="yes")


@needs_native
def test_the_torch_vec_env_steps_through_it():
    venv = swarm_nav_v0.vec_env(64, n_agents=8, backend="torch")
    assert venv.core.kernel == "native"
    venv.seed(0)
    obs = venv.reset()
    obs, rewards, _, _ = venv.step(np.zeros((venv.num_envs, 2), np.float32))
    assert np.isfinite(rewards).all()
    assert obs.shape == (64 * 8, venv.observation_space.shape[0]) and np.isfinite(obs).all()


@needs_native
def test_too_many_neighbours_fall_back_or_raise(monkeypatch):
    monkeypatch.setenv(tb.COMPILE_ENV, "0")
    cfg = SwarmConfig(n_agents=80, n_neighbors=70)
    core = TorchSwarmNavCore(cfg, batch=1)
    assert core.kernel == "plain" and "at most 64 neighbours" in core.native_reason
    with pytest.raises(ValueError, match="at most 64 neighbours, got n_neighbors=70"):
        TorchSwarmNavCore(cfg, batch=1, native=True)


def test_without_a_compiler_the_torch_step_runs(monkeypatch, fresh_library):
    monkeypatch.setattr(native_step, "_compiler", lambda: None)
    monkeypatch.setenv(tb.COMPILE_ENV, "0")
    assert resolve_native("auto") == (False, "no C compiler found ($CC, cc, gcc)")
    core = TorchSwarmNavCore(SwarmConfig(n_agents=4), batch=2)
    assert core.kernel == "plain" and "no C compiler" in core.native_reason
    with pytest.raises(RuntimeError, match="required but cannot be used: no C compiler"):
        TorchSwarmNavCore(SwarmConfig(n_agents=4), batch=2, native=True)
    monkeypatch.setenv(native_step.NATIVE_ENV, "1")
    with pytest.raises(RuntimeError, match="no C compiler"):
        TorchSwarmNavCore(SwarmConfig(n_agents=4), batch=2)


def test_a_failing_build_names_the_compiler_error(monkeypatch, fresh_library, tmp_path):
    broken = tmp_path / "cc"
    broken.write_text("#!/bin/sh\necho 'cc: fatal error: out of cheese' >&2\nexit 1\n")
    broken.chmod(0o755)
    monkeypatch.setattr(native_step, "_compiler", lambda: str(broken))
    ok, why = native_support()
    assert not ok and "out of cheese" in why
    assert not list(tmp_path.glob("fused_step-*.so"))  # nothing half-built is left


@needs_native
def test_the_library_is_built_once_into_the_cache(fresh_library):
    assert native_support() == (True, "supported")
    built = list(fresh_library.glob("fused_step-*.so"))
    assert len(built) == 1
    stamp = built[0].stat().st_mtime_ns
    native_step._LIBRARY = None  # a new process: loads the cached file
    assert native_support() == (True, "supported")
    assert built[0].stat().st_mtime_ns == stamp
