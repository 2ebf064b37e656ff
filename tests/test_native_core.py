"""The C step (swarm_envs.envs.cores.native): the core that runs it, its build and its contract.

Its agreement with the shared definitions over every config field is the conformance
suite's (tests/test_conformance.py). Here: what is particular to the C step — resets of a
few swarms measured alone and in place, results independent of the thread count,
actions checked in C, the inlined float32 exponential, coincident agents, ties in the
neighbour ranking, pickling, the step-size control (substeps, the cap in both modes of
``on_unstable``, a non-finite state) against the numpy core, also in the ``x86-64-v3`` build,
the generated contract, the build cache and the fallbacks (no compiler, a failing build,
more neighbours than the kernel ranks).
"""

from __future__ import annotations

import ctypes
import dataclasses
import pickle

import numpy as np
import pytest
from helpers import CORE_TOL, mill_about_goal

from swarm_envs import swarm_nav_v0
from swarm_envs.config import SwarmConfig, load_swarm_config
from swarm_envs.envs.common import SwarmUnstableError
from swarm_envs.envs.cores.native import NativeSwarmNavCore, build, contract, native_support
from swarm_envs.envs.cores.native.build import resolve_native
from swarm_envs.envs.cores.numpy import SwarmNavCore
from swarm_envs.envs.task import STATISTICS, observation_size
from swarm_envs.envs.task.observation import LAYOUT
from swarm_envs.physics import SocialPotentialParams

SUPPORTED, WHY = native_support()
needs_native = pytest.mark.skipif(not SUPPORTED, reason=f"C step unavailable: {WHY}")


@pytest.fixture
def fresh_library(monkeypatch, tmp_path):
    """The loader's state reset (and restored afterwards), its cache in ``tmp_path``, the
    libraries built at install ignored."""
    monkeypatch.setattr(build, "_LIBRARIES", {})
    monkeypatch.setattr(build, "_FAILURES", {})
    monkeypatch.setenv("SWARM_ENVS_CACHE", str(tmp_path))
    monkeypatch.setenv(build.PREBUILT_ENV, "0")
    monkeypatch.delenv(build.NATIVE_ENV, raising=False)
    return tmp_path


@needs_native
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_resets_measure_exactly_the_reset_swarms_in_place(monkeypatch, dtype):
    # A reset of n < B swarms re-measures those n alone, in place (no step of the batch,
    # no copy of the observations when none were handed out); a reset of all B measures
    # the whole batch. The results match the numpy core.
    cfg = SwarmConfig(n_agents=6, n_neighbors=3)
    core = NativeSwarmNavCore(cfg, batch=64, dtype=dtype)
    ref = SwarmNavCore(cfg, batch=64, dtype=dtype)
    calls: list[int] = []
    inner = core._call
    monkeypatch.setattr(
        core,
        "_call",
        lambda a, move, obs, rows, **kw: (
            calls.append(64 if rows is None else rows.size) or inner(a, move, obs, rows, **kw)
        ),
    )
    rng, ref_rng = np.random.default_rng(4), np.random.default_rng(4)
    core.reset(rng)
    ref.reset(ref_rng)
    actions = np.random.default_rng(5).uniform(-1, 1, (64, 6, 2)).astype(dtype)
    for swarms in ([0], [1, 3, 5, 7, 9, 10, 11, 12, 13, 14], list(range(63)), list(range(64))):
        core.step(actions)
        ref.step(actions)
        which = np.isin(np.arange(64), swarms)
        last = core.observe(which=which)  # a copy of those rows
        np.testing.assert_allclose(last, ref.observe(which=which), **CORE_TOL[dtype])
        memory = core._obs.ctypes.data
        calls.clear()
        core.reset(rng, which=which)
        ref.reset(ref_rng, which=which)
        assert calls == [len(swarms)]
        if len(swarms) < 64:
            assert core._obs.ctypes.data == memory  # nothing handed out: in place
        assert not np.array_equal(core.observe(which=which), last)  # new starts
        np.testing.assert_allclose(core.observe(), ref.observe(), **CORE_TOL[dtype])
        for key, value in core.stats().items():
            np.testing.assert_allclose(value, ref.stats()[key], **CORE_TOL[dtype], err_msg=key)


@needs_native
def test_observations_handed_out_keep_their_values():
    core = NativeSwarmNavCore(SwarmConfig(n_agents=5), batch=8)
    rng = np.random.default_rng(0)
    core.reset(rng)
    first = core.observe()
    saved = first.copy()
    for _ in range(6):  # the buffer pool must not hand this array's memory out again
        core.step(np.ones((8, 5, 2)))
        core.observe()
    core.reset(rng, which=np.arange(8) < 3)
    np.testing.assert_array_equal(first, saved)
    again = core.observe()
    assert again is not core.observe()  # a second call on the same state: a copy


@needs_native
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("dt", [0.1, 0.5], ids=["one-substep", "substeps"])
def test_results_do_not_depend_on_the_thread_count(dtype, dt):
    import torch  # the kernel runs on torch's OpenMP pool once torch is loaded

    cfg = SwarmConfig(n_agents=9, dim=3, dt=dt)
    a = np.random.default_rng(2).uniform(-1, 1, (11, 9, 3))
    threads = torch.get_num_threads()
    outs = []
    try:
        for n in (1, 2, 5):
            torch.set_num_threads(n)
            core = NativeSwarmNavCore(cfg, batch=11, dtype=dtype)
            core.reset(np.random.default_rng(1))
            reward, _, _, stats = core.step(a)
            outs.append((reward, core.observe(), core.x, stats["substeps"]))
    finally:
        torch.set_num_threads(threads)
    assert (outs[0][3] > 1).any() == (dt == 0.5)
    for out in outs[1:]:
        for ours, ref in zip(out, outs[0], strict=True):
            assert np.array_equal(ours, ref)


@needs_native
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf], ids=["nan", "inf", "-inf"])
def test_non_finite_actions_raise_in_the_c_step_and_change_nothing(dtype, bad):
    # The C step checks the actions itself: any NaN or inf, in the first or the last
    # swarm, raises before anything is written; finite values beyond [-1, 1] are clipped
    # as numpy clips them.
    cfg = SwarmConfig(n_agents=5, max_steps=50)
    core = NativeSwarmNavCore(cfg, batch=3, dtype=dtype)
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
    fn = build.load_library().lib.fused_exp_f32
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


def _set_state(core, x, v) -> None:
    """Put ``x, v`` (B, N, d) into a core and re-measure (test-only access)."""
    if isinstance(core, NativeSwarmNavCore):
        core._x[...] = np.transpose(x, (2, 0, 1))
        core._v[...] = np.transpose(v, (2, 0, 1))
        core._measure()
    else:
        core.x, core.v = x.astype(core.dtype), v.astype(core.dtype)
        core._after_reset(np.arange(core.batch), np.random.default_rng(0))
        core._measure()


@needs_native
def test_coincident_agents_stay_finite():
    cfg = SwarmConfig(n_agents=5, collision_radius=0.5)
    cores = [NativeSwarmNavCore(cfg, batch=2), SwarmNavCore(cfg, batch=2)]
    results = []
    for core in cores:
        core.reset(np.random.default_rng(0))
        _set_state(core, np.zeros((2, 5, 2)), np.zeros((2, 5, 2)))
        results.append((*core.step(np.ones((2, 5, 2))), core.observe()))
    (reward, _, _, stats, obs), (ref_reward, _, _, ref_stats, ref_obs) = results
    assert np.isfinite(obs).all() and np.isfinite(reward).all()
    assert all(np.isfinite(value).all() for value in stats.values())
    np.testing.assert_allclose(reward, ref_reward, **CORE_TOL[np.float64])
    np.testing.assert_allclose(obs, ref_obs, **CORE_TOL[np.float64])
    assert stats["collisions"].tolist() == ref_stats["collisions"].tolist() == [10.0, 10.0]


@needs_native
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_equal_distances_rank_neighbours_by_index(dtype):
    # Agents on a lattice: many pairs at exactly the same distance, and the tiles hand
    # candidates over in rotated order. Distinct velocities make the order visible in
    # the observations; it must be the (ρ, j) order of the shared definition.
    N = 37  # three blocks of 16 lanes (five of 8 in float64): tiles (J, I) with J < I
    cfg = SwarmConfig(n_agents=N, n_neighbors=8)
    idx = np.arange(N)
    x = np.stack([idx % 7, idx // 7], axis=-1) * 0.5
    v = np.stack([idx * 0.01, -idx * 0.02], axis=-1)
    obs = []
    for core in (NativeSwarmNavCore(cfg, 2, dtype), SwarmNavCore(cfg, 2, dtype)):
        core.reset(np.random.default_rng(0))
        _set_state(core, np.stack([x, x[::-1]]), np.stack([v, v]))
        obs.append(core.observe())
    np.testing.assert_allclose(obs[0], obs[1], **CORE_TOL[dtype])
    ranked = obs[0][..., 2 * 2 :].reshape(2, N, 8, 5)[..., 2:4]  # relative velocities
    assert np.unique(ranked.round(6), axis=2).shape[2] == 8  # the order is visible


@needs_native
def test_pickle_round_trip_reproduces_the_rollout():
    core = NativeSwarmNavCore(SwarmConfig(n_agents=5), batch=3)
    core.reset(np.random.default_rng(0))
    clone = pickle.loads(pickle.dumps(core))
    for a in np.random.default_rng(4).uniform(-1, 1, (4, 3, 5, 2)):
        np.testing.assert_array_equal(core.step(a)[0], clone.step(a)[0])
        np.testing.assert_array_equal(core.observe(), clone.observe())


@needs_native
def test_the_envs_run_on_it_by_default():
    venv = swarm_nav_v0.vec_env(64, n_agents=8)
    assert venv.backend == "native" and isinstance(venv.core, NativeSwarmNavCore)
    venv.seed(0)
    obs = venv.reset()
    obs, rewards, _, _ = venv.step(np.zeros((venv.num_envs, 2), np.float32))
    assert np.isfinite(rewards).all()
    assert obs.shape == (64 * 8, venv.observation_space.shape[0]) and np.isfinite(obs).all()
    assert isinstance(swarm_nav_v0.parallel_env(n_agents=8).core, NativeSwarmNavCore)


@needs_native
def test_too_many_neighbours_are_refused_with_the_reason(recwarn):
    cfg = SwarmConfig(n_agents=80, n_neighbors=70)
    assert "at most 64 neighbours, got n_neighbors=70" in NativeSwarmNavCore.unsupported(cfg)
    with pytest.raises(ValueError, match="at most 64 neighbours, got n_neighbors=70"):
        NativeSwarmNavCore(cfg)
    with pytest.warns(UserWarning, match="backend 'native' cannot run this config"):
        env = swarm_nav_v0.parallel_env(**{**dataclasses.asdict(cfg), "backend": "native"})
    assert env.core.backend == "numpy"


# --------------------------------------------------------------------------- step-size control

#: Configs whose steps take several substeps: the navigation physics in a dense swarm, a
#: long control period, 3-D, no alignment with equal decay lengths, the passive sink.
SUBSTEP_CONFIGS = {
    "n64": SwarmConfig(n_agents=64),
    "dt0.5": SwarmConfig(n_agents=10, dt=0.5),
    "3d": SwarmConfig(n_agents=7, dim=3, dt=0.4),
    "plain-morse": SwarmConfig(
        n_agents=20,
        dt=0.5,
        physics=SocialPotentialParams(C_o=0.0, l_a=0.5, l_r=0.5, C_r=3.0, beta=2.0),
    ),
    "sink": SwarmConfig(n_agents=20, dt=0.3, goal_in_physics=True),
}
#: The stable substeps h* carried by both cores agree to this (float32: the sums of the
#: rates are rounded in another order; the counts must still agree in these rollouts).
H_RTOL = {np.float32: 1e-4, np.float64: 1e-12}


@needs_native
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_the_substep_rule_in_c_is_the_python_rule(dtype):
    # stable_substep in the state's dtype (float32: to rounding, the C compiler may fuse
    # a multiply-add) and substep_plan in float64 (exactly: the same operations), over
    # decades of rates, the edge cases (0, inf, NaN) and ratios at an integer up to the
    # 1e-9 slack and just past it.
    from swarm_envs.physics.integrators import STEP_SAFETY, stable_substep, substep_plan

    lib = build.load_library().lib
    rng = np.random.default_rng(0)
    inf, nan = np.inf, np.nan
    omega2 = np.concatenate([10 ** rng.uniform(-6, 8, 4000), [0, 0, inf, 1, nan, 0, inf, 2]])
    gamma = np.concatenate([10 ** rng.uniform(-6, 4, 4000), [0, 1, 0, inf, 0, nan, inf, 3]])
    omega2[:1000] = 0.0  # damping alone
    gamma[1000:2000] = 0.0  # stiffness alone
    omega2, gamma = omega2.astype(dtype), gamma.astype(dtype)
    h = np.empty(omega2.size)
    ptr = ctypes.c_void_p
    fn = getattr(lib, f"fused_stable_substep_{np.dtype(dtype).name.replace('float', 'f')}")
    fn.restype = None
    fn.argtypes = [ptr, ptr, ptr, ctypes.c_int64]
    fn(omega2.ctypes.data, gamma.ctypes.data, h.ctypes.data, h.size)
    want = stable_substep(omega2, gamma).astype(np.float64)
    rtol = 1e-6 if dtype == np.float32 else 1e-15
    np.testing.assert_allclose(h, want, rtol=rtol, atol=0)
    edge_cases = [inf, 2.0 * STEP_SAFETY, 0.0, 0.0, inf, inf, 0.0]
    np.testing.assert_allclose(h[-8:-1], edge_cases, rtol=1e-7)
    np.testing.assert_array_equal(h[-8:-1], want[-8:-1])

    k = rng.integers(1, 200, 3000).astype(np.float64)
    tau = rng.uniform(0.001, 2.0, 3000)
    hs = np.concatenate([tau[:1000] / k[:1000], rng.uniform(1e-4, 3.0, 2000)])
    hs[:300] *= 1 + 1e-10  # within the slack: k substeps
    hs[300:600] *= 1 - 1e-10  # within the slack the other way: still k
    hs[600:900] *= 1 - 1e-8  # past it: k + 1
    tau = np.concatenate([tau, [0.0, 0.5, 0.5, 0.5, 0.0, 1e-300]])
    hs = np.concatenate([hs, [0.1, 0.0, inf, 1e-300, 0.0, 1.0]])
    n, h = np.empty_like(tau), np.empty_like(tau)
    plan = lib.fused_substep_plan
    plan.restype = None
    plan.argtypes = [ptr, ptr, ptr, ptr, ctypes.c_int64]
    plan(tau.ctypes.data, hs.ctypes.data, n.ctypes.data, h.ctypes.data, tau.size)
    want_n, want_h = substep_plan(tau, hs)
    assert np.array_equal(n, want_n) and np.array_equal(h, want_h)
    assert np.array_equal(n[:600], k[:600]) and np.array_equal(n[600:900], k[600:900] + 1)
    edge = n[-6:].tolist()
    assert edge[:3] == [0.0, inf, 1.0] and edge[3] > 1e299 and edge[4:] == [0.0, 1.0]
    assert h[-6] == h[-5] == h[-2] == 0.0 and h[-4] == 0.5


def _assert_same_step(got: tuple, want: tuple, core, ref, dtype) -> None:
    """One step's results, state and observations: the C step's against numpy's."""
    tol = CORE_TOL[dtype]
    np.testing.assert_allclose(got[0], want[0], **tol, err_msg="reward")
    np.testing.assert_array_equal(got[1], want[1], err_msg="terminated")
    np.testing.assert_array_equal(got[2], want[2], err_msg="truncated")
    np.testing.assert_array_equal(got[3]["substeps"], want[3]["substeps"])
    np.testing.assert_array_equal(got[3]["unstable"], want[3]["unstable"])
    for key, value in got[3].items():
        np.testing.assert_allclose(value, want[3][key], **tol, err_msg=key)
    np.testing.assert_allclose(core.x, ref.x, **tol, err_msg="x")
    np.testing.assert_allclose(core.v, ref.v, **tol, err_msg="v")
    np.testing.assert_allclose(core.observe(), ref.observe(), **tol, err_msg="observations")


@needs_native
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize(
    ("name", "arch"),
    [(name, None) for name in SUBSTEP_CONFIGS] + [("n64", "x86-64-v3"), ("3d", "x86-64-v3")],
    ids=lambda v: v or "native",
)
def test_substeps_match_the_numpy_core(monkeypatch, name, arch, dtype):
    # Every swarm plans its own substeps from the stable substep it carries: the same
    # counts, states, statistics and rewards as the numpy core, step after step; the
    # count is 0 after a reset (of all swarms or some, as the numpy core reports it).
    if arch is not None:  # the x86-64-v3 build: no AVX-512 branches
        monkeypatch.setenv(build.ARCH_ENV, arch)
    cfg = SUBSTEP_CONFIGS[name]
    B, N, d = 4, cfg.n_agents, cfg.dim
    core, ref = NativeSwarmNavCore(cfg, B, dtype), SwarmNavCore(cfg, B, dtype)
    rng, ref_rng = np.random.default_rng(0), np.random.default_rng(0)
    core.reset(rng)
    ref.reset(ref_rng)
    assert (core.stats()["substeps"] == 0).all()
    counts = []
    for a in np.random.default_rng(1).uniform(-1, 1, (8, B, N, d)).astype(dtype):
        got, want = core.step(a), ref.step(a)
        _assert_same_step(got, want, core, ref, dtype)
        np.testing.assert_allclose(core._h, ref.dynamics._h_stable, rtol=H_RTOL[dtype])
        counts.append(got[3]["substeps"])
    assert (np.array(counts) >= 1).all() and np.max(counts) > 1
    which = np.arange(B) < 2
    core.reset(rng, which=which)
    ref.reset(ref_rng, which=which)
    # the swarms reset took no step yet; the others keep their last step's count
    np.testing.assert_array_equal(core.stats()["substeps"], ref.stats()["substeps"])
    assert (core.stats()["substeps"][which] == 0).all()
    assert (core.stats()["substeps"][~which] == counts[-1][~which]).all()
    np.testing.assert_allclose(core.observe(), ref.observe(), **CORE_TOL[dtype])


def _cap_rollout(cfg: SwarmConfig, dtype, steps: int = 14):
    """The C step's and the numpy core's step results side by side, the swarms whose
    episode ended reset as the VecEnv resets them (an error ends the rollout)."""
    B, N, d = 4, cfg.n_agents, cfg.dim
    core, ref = NativeSwarmNavCore(cfg, B, dtype), SwarmNavCore(cfg, B, dtype)
    rng, ref_rng = np.random.default_rng(0), np.random.default_rng(0)
    core.reset(rng)
    ref.reset(ref_rng)
    for a in np.random.default_rng(1).uniform(-1, 1, (steps, B, N, d)).astype(dtype):
        before = core.x
        got, want = core.step(a), ref.step(a)
        yield core, ref, before, got, want
        ended = got[1] | got[2]
        core.reset(rng, which=ended)
        ref.reset(ref_rng, which=ended)


@needs_native
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_a_step_over_the_cap_raises_as_in_the_numpy_core(dtype):
    # max_substeps = 2 where the steps need 3 or more: the first step raises, naming the
    # swarm, the substeps it needed and the keys to change, in both cores alike.
    cfg = SwarmConfig(n_agents=10, dt=0.5, max_substeps=2)
    core, ref = NativeSwarmNavCore(cfg, 4, dtype), SwarmNavCore(cfg, 4, dtype)
    core.reset(np.random.default_rng(0))
    ref.reset(np.random.default_rng(0))
    a = np.random.default_rng(1).uniform(-1, 1, (4, 10, 2)).astype(dtype)
    with pytest.raises(SwarmUnstableError) as err:
        core.step(a)
    with pytest.raises(SwarmUnstableError) as ref_err:
        ref.step(a)
    assert str(err.value) == str(ref_err.value)
    assert "swarm 0 of 4, step 1" in str(err.value)
    assert "more than max_substeps=2" in str(err.value)


@needs_native
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_a_step_over_the_cap_is_undone_as_in_the_numpy_core(dtype):
    # on_unstable="truncate" with a cap that some steps of some swarms exceed: those
    # swarms go back to their state before the step (re-measured: substeps 0, unstable
    # 1, reward 0, truncated), the others step on; the same as the numpy core.
    cfg = SwarmConfig(n_agents=10, dt=0.5, max_substeps=4, on_unstable="truncate")
    undone = stepped = 0
    for core, ref, before, got, want in _cap_rollout(cfg, dtype):
        _assert_same_step(got, want, core, ref, dtype)
        bad = got[3]["unstable"] == 1.0
        undone += bad.sum()
        stepped += (~bad).sum()
        assert np.array_equal(core.x[bad], before[bad])
        assert (got[0][bad] == 0).all() and got[2][bad].all() and not got[1][bad].any()
        assert (got[3]["substeps"][bad] == 0).all() and (got[3]["substeps"][~bad] >= 1).all()
    assert undone > 0 and stepped > 0


@needs_native
@pytest.mark.parametrize("mode", ["raise", "truncate"])
def test_a_non_finite_state_is_unstable_as_in_the_numpy_core(mode):
    # A NaN velocity in swarm 1 (within the cap): its step is unstable for the
    # finiteness of the statistics; the other swarms are sound.
    cfg = SwarmConfig(n_agents=6, on_unstable=mode)
    x = np.random.default_rng(0).uniform(-2, 2, (3, 6, 2))
    v = np.zeros((3, 6, 2))
    v[1, 2, 0] = np.nan
    results = []
    for core in (NativeSwarmNavCore(cfg, batch=3), SwarmNavCore(cfg, batch=3)):
        core.reset(np.random.default_rng(0))
        _set_state(core, x, v)
        if mode == "raise":
            with pytest.raises(SwarmUnstableError, match=r"swarm 1 of 3.*NaN or infinite") as err:
                core.step(np.zeros((3, 6, 2)))
            results.append(str(err.value))
        else:
            reward, _, truncated, stats = core.step(np.zeros((3, 6, 2)))
            assert stats["unstable"].tolist() == [0.0, 1.0, 0.0]
            assert truncated.tolist() == [False, True, False] and reward[1] == 0
            results.append(np.isnan(core.v).any(axis=(1, 2)).tolist())
    assert results[0] == results[1]


# --------------------------------------------------------------------------- contract


def test_every_config_field_has_a_place_in_the_contract():
    names = {f.name for f in dataclasses.fields(SwarmConfig)}
    kernel, host = set(contract.KERNEL_CONFIG_FIELDS), set(contract.HOST_CONFIG_FIELDS)
    assert not kernel & host
    assert kernel | host == names, "classify the new SwarmConfig field in the C contract"


def test_the_struct_is_generated_from_the_dataclasses():
    from swarm_envs.physics import SocialPotentialParams

    fields = [f.name for f in contract.step_fields()]
    for f in dataclasses.fields(SocialPotentialParams):
        assert f"physics_{f.name}" in fields
    struct = contract.params_struct()
    assert [name for name, _ in struct._fields_] == fields
    text = contract.header()
    assert all(f" {name};" in text for name in fields)
    cfg = load_swarm_config(overrides={"n_agents": 7, "dt": 0.03, "physics": {"C_o": 0.25}})
    params = contract.step_params(cfg, np.float64)
    assert (params.n_agents, params.dt, params.physics_C_o) == (7, 0.03, 0.25)


def _kernel_code(cfg: SwarmConfig, actions: np.ndarray, x: np.ndarray, **params) -> int:
    """The C step's return value for one float64 swarm at ``x`` ``(N, d)`` at rest,
    called directly, with ``params`` overriding fields of its ``StepParams``."""
    struct = contract.step_params(cfg, np.float64)
    struct.batch = 1
    for name, value in params.items():
        setattr(struct, name, value)
    n, d = cfg.n_agents, cfg.dim
    state = [np.ascontiguousarray(x.T[:, None, :]), np.zeros((d, 1, n)), np.zeros((d, 1, n))]
    out = [np.zeros((d, 1, n)) for _ in range(3)]
    h, h_out = np.full(1, np.inf), np.zeros(1)
    obs = np.zeros((1, n, observation_size(cfg)), np.float32)
    packed = np.zeros((1, len(contract.PACKED_COLUMNS)))
    arrays = [*state, h, np.zeros((1, d)), actions, np.ones(1, np.uint8), None, *out, h_out]
    pointers = [None if a is None else a.ctypes.data for a in [*arrays, obs, packed]]
    return build.load_library().f64(ctypes.addressof(struct), 0, 1, None, *pointers)


@needs_native
def test_the_kernel_returns_the_contracts_codes_and_each_maps_to_its_error():
    # The codes come from contract.StepCode through the generated header: the C step
    # returns them by name, and step_error turns each into its own exception.
    cfg = SwarmConfig(n_agents=5)
    x = np.random.default_rng(0).uniform(-1, 1, (5, 2))
    still = np.zeros((1, 5, 2))
    assert _kernel_code(cfg, still, x) == contract.StepCode.OK
    kmax = build.load_library().info.kmax
    code = _kernel_code(cfg, still, x, k_rank=kmax + 1)
    assert code == contract.StepCode.TOO_MANY_NEIGHBOURS
    with pytest.raises(RuntimeError, match="rank more neighbours"):
        raise contract.step_error(code)
    code = _kernel_code(cfg, np.full((1, 5, 2), np.nan), x)
    assert code == contract.StepCode.NON_FINITE_ACTIONS
    with pytest.raises(ValueError, match="finite"):
        raise contract.step_error(code)
    x[2] = np.nan  # a non-finite state: the guard's flag, no error
    assert _kernel_code(cfg, still, x) == contract.UNSOUND
    assert isinstance(contract.step_error(contract.StepCode.NO_SCRATCH), MemoryError)
    assert "unknown code" in str(contract.step_error(2 * contract.UNSOUND))
    assert all(code < contract.UNSOUND for code in contract.StepCode)


def test_the_header_names_the_statuses_and_their_flags_from_the_python_definitions():
    from swarm_envs.envs.task import agent_status

    text = contract.header()
    for name in contract.AGENT_STATUSES:
        assert f"STATUS_{name} = {getattr(agent_status, name)}," in text
    flags = contract.status_flags()
    for name, value in zip(contract.AGENT_STATUSES, range(len(flags)), strict=True):
        m = agent_status.masks(np.array(getattr(agent_status, name)))
        want = {"PRESENT": m.present, "MOBILE": m.mobile, "ACTIVE": m.controlled}
        assert set(flags[name]) == {flag for flag, on in want.items() if on}, (name, value)


def test_a_config_the_kernel_does_not_implement_is_refused():
    from swarm_envs.physics import SocialPotentialParams

    info = contract.KernelInfo(
        physics=("C_a", "C_r", "l_a", "l_r"),  # as if alignment were missing
        statistics=(),
        obs_layouts=("another layout",),
        kmax=64,
    )
    cfg = SwarmConfig()
    assert "physics.C_o is not implemented" in contract.unsupported(cfg, info)
    no_alignment = dataclasses.replace(cfg, physics=SocialPotentialParams())
    assert "observation layout" in contract.unsupported(no_alignment, info)
    assert "dynamics='social_potential'" in contract.unsupported(SwarmConfig(dynamics="zone"), info)


@needs_native
def test_the_kernel_declares_what_it_implements():
    info = build.load_library().info
    assert info.obs_layouts == (LAYOUT, LAYOUT + ",status")
    assert set(info.statuses) == set(contract.STATUS_MASKS)
    assert info.kmax == 64
    assert set(info.statistics) <= set(contract.PACKED_COLUMNS)
    from swarm_envs.physics import SocialPotentialParams

    # every field, self-propulsion included (test_self_propulsion.py)
    fields = {f.name for f in dataclasses.fields(SocialPotentialParams)}
    assert set(info.physics) == fields


# --------------------------------------------------------------------------- build


def test_without_a_compiler_auto_warns_and_runs_numpy(monkeypatch, fresh_library):
    monkeypatch.setattr(build, "_compiler", lambda: None)
    why = "no C compiler found ($CC, cc, gcc); SWARM_ENVS_NATIVE_PREBUILT=0"
    assert resolve_native("auto") == (False, why)
    assert "no C compiler" in NativeSwarmNavCore.unsupported(SwarmConfig())
    from swarm_envs.envs import backends

    monkeypatch.setattr(backends, "_WARNED", set())
    with pytest.warns(UserWarning, match="backend 'native' unavailable .*no C compiler"):
        env = swarm_nav_v0.parallel_env(n_agents=4)
    assert env.core.backend == "numpy"
    with pytest.raises(RuntimeError, match="required but cannot be used: no C compiler"):
        resolve_native(True)
    monkeypatch.setenv(build.NATIVE_ENV, "1")
    with pytest.raises(RuntimeError, match="no C compiler"):
        resolve_native("auto")


def test_a_failing_build_names_the_compiler_error(monkeypatch, fresh_library, tmp_path):
    broken = tmp_path / "cc"
    broken.write_text("#!/bin/sh\necho 'cc: fatal error: out of cheese' >&2\nexit 1\n")
    broken.chmod(0o755)
    monkeypatch.setattr(build, "_compiler", lambda: str(broken))
    ok, why = native_support()
    assert not ok and "out of cheese" in why
    assert not list(tmp_path.glob("fused_step-*.so"))  # nothing half-built is left


@needs_native
def test_the_library_is_built_once_into_the_cache(fresh_library):
    assert native_support() == (True, "supported")
    built = list(fresh_library.glob("fused_step-*.so"))
    assert len(built) == 1
    stamp = built[0].stat().st_mtime_ns
    build._LIBRARIES.clear()  # a new process: loads the cached file
    assert native_support() == (True, "supported")
    assert built[0].stat().st_mtime_ns == stamp


def test_flags_follow_the_arch_variable_and_cflags(monkeypatch):
    monkeypatch.delenv(build.ARCH_ENV, raising=False)
    monkeypatch.delenv("CFLAGS", raising=False)
    assert "-march=native" in build.build_flags()
    monkeypatch.setenv(build.ARCH_ENV, "x86-64-v3")
    monkeypatch.setenv("CFLAGS", "-g -DEXTRA=1")
    flags = build.build_flags()
    assert "-march=x86-64-v3" in flags and flags[-2:] == ("-g", "-DEXTRA=1")
    monkeypatch.setenv(build.ARCH_ENV, build.PORTABLE)  # the compiler's default target
    flags = build.build_flags()
    assert not any(f.startswith("-march") for f in flags) and flags[-2:] == ("-g", "-DEXTRA=1")


def test_the_switch_turns_it_off_or_requires_it(monkeypatch):
    from swarm_envs.envs import backends

    monkeypatch.setattr(backends, "_WARNED", set())
    monkeypatch.setenv(build.NATIVE_ENV, "0")
    assert NativeSwarmNavCore.unsupported(SwarmConfig()) == "switched off (SWARM_ENVS_NATIVE=0)"
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # switched off on purpose: no warning
        assert swarm_nav_v0.vec_env(4, n_agents=3).backend == "numpy"
    monkeypatch.setenv(build.NATIVE_ENV, "sometimes")
    with pytest.raises(ValueError, match="SWARM_ENVS_NATIVE must be 0, 1 or auto"):
        NativeSwarmNavCore.unsupported(SwarmConfig())


@needs_native
def test_a_statistic_the_kernel_does_not_write_comes_from_the_shared_definition():
    # As if the kernel did not declare these statistics: the core computes them from its
    # state with the definitions of swarm_envs.envs.task.statistics (the pair measures
    # in numpy where one of them may read them).
    cfg = SwarmConfig(n_agents=7, n_neighbors=3)
    core, ref = NativeSwarmNavCore(cfg, batch=2), SwarmNavCore(cfg, batch=2)
    names = (
        "polarization",
        "nearest_neighbor_distance",
        "fraction_arrived",
        "goal_angular_momentum",
    )
    core._extra = tuple(i for i, s in enumerate(STATISTICS) if s.name in names)
    core._extra_pairs = True
    core._packed[:] = np.nan  # the kernel's columns for them must not be read
    rng, ref_rng = np.random.default_rng(3), np.random.default_rng(3)
    core.reset(rng)
    ref.reset(ref_rng)
    a = np.random.default_rng(4).uniform(-1, 1, (2, 7, 2))
    for _ in range(3):
        got, want = core.step(a)[3], ref.step(a)[3]
        for key in names:
            np.testing.assert_allclose(got[key], want[key], rtol=1e-12, atol=1e-12)


@needs_native
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("dim", [2, 3])
def test_the_statistics_about_the_goal_are_the_kernels_and_match_the_numpy_core(dim, dtype):
    # goal_angular_momentum, mill_speed and mill_order come from the kernel (the core
    # computes none of them in Python; the mill's success alone, without pair measures),
    # step after step as the numpy core gives them: a self-propelled swarm started about
    # its goal, agents inside and outside the arrival radius.
    cfg = mill_about_goal(12, dim)
    about_goal = ("goal_angular_momentum", "mill_speed", "mill_order")
    assert set(about_goal) <= set(build.load_library().info.statistics)
    B, N = 4, cfg.n_agents
    core, ref = NativeSwarmNavCore(cfg, B, dtype), SwarmNavCore(cfg, B, dtype)
    assert [STATISTICS[i].name for i in core._extra] == ["success"]
    assert not core._extra_pairs
    rng, ref_rng = np.random.default_rng(0), np.random.default_rng(0)
    core.reset(rng)
    ref.reset(ref_rng)
    seen = []
    for a in np.random.default_rng(1).uniform(-1, 1, (12, B, N, dim)).astype(dtype):
        got, want = core.step(a), ref.step(a)
        _assert_same_step(got, want, core, ref, dtype)
        seen.append([got[3][key] for key in about_goal])
        ended = got[1] | got[2]
        core.reset(rng, which=ended)
        ref.reset(ref_rng, which=ended)
    momentum, speed, order = np.moveaxis(np.array(seen), 1, 0)
    assert (momentum > 0).all() and (speed > 0).any() and (speed < momentum).any()
    assert ((order > 0) & (order < 1)).any()
    np.testing.assert_allclose(order, np.minimum(speed / cfg.physics.cruise_speed, 1.0))
