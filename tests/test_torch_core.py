"""TorchSwarmNavCore: the numpy SwarmNavCore's interface and numbers, in torch.

Same seed and actions → same starts, observations, rewards, flags and statistics as
:class:`SwarmNavCore` over dozens of steps (float32 and float64), including partial
resets (of the whole batch, and of a few swarms through the sub-batch function),
padding (N − 1 < k), N = 1, 3-D and the passive goal; coincident agents, seeding,
pickling and bad input (docs/testing.md). Step-size control: steps that
need several substeps (64 and 100 agents, a long dt; each swarm its own count), the cap
in both ``on_unstable`` modes (a raise leaves the last sound state), a non-finite state,
a start that overflows the dtype and the substeps after a reset give the numpy core's
statistics, flags, states and error messages. Two tests compile (64 swarms of 6: the
step and the sub-batch reset; 4 swarms of 8 with substeps and truncations: the substep
function) and check them against plain torch or numpy; the rest run plain torch, the
fallback path. The CUDA tests (also with substeps and truncations) run where a GPU is
present.
"""

from __future__ import annotations

import dataclasses
import pickle

import numpy as np
import pytest
import torch
from helpers import CORE_CONFIGS as CONFIGS
from helpers import CORE_TOL as TOL
from helpers import assert_same_rollout, make_config, rollout

from swarm_envs._runtime.torch_compile import compile_support
from swarm_envs.config import SwarmConfig
from swarm_envs.envs.common import SwarmUnstableError
from swarm_envs.envs.cores.numpy import SwarmNavCore
from swarm_envs.envs.cores.torch.core import TorchSwarmNavCore
from swarm_envs.envs.task import OBS_BOUND, STAT_KEYS


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("name", list(CONFIGS))
def test_same_rollout_as_the_numpy_core(name, dtype):
    cfg = make_config(CONFIGS[name])
    batch = 4
    ref = rollout(SwarmNavCore(cfg, batch=batch, dtype=dtype), seed=7, steps=36, reset_every=12)
    ours = rollout(
        TorchSwarmNavCore(cfg, batch=batch, dtype=dtype, compile=False),
        seed=7,
        steps=36,
        reset_every=12,
    )
    assert_same_rollout(ours, ref, TOL[dtype])


def step_stats(out: list[tuple]) -> tuple[np.ndarray, np.ndarray]:
    """``substeps`` and ``unstable`` per step ``(steps, B)`` of a :func:`~helpers.rollout`."""
    steps = [stats for _, reward, _, _, stats in out if reward is not None]
    return np.array([s["substeps"] for s in steps]), np.array([s["unstable"] for s in steps])


#: Configs whose steps need several substeps: a swarm of 64 and one of 100 (default
#: navigation physics, dense enough to need 4-7), and a dt five times the default.
SUBSTEP_CONFIGS = {
    "n64": dict(n_agents=64),
    "n100_goal_physics": dict(n_agents=100, goal_in_physics=True, max_steps=8),
    "dt_half": dict(n_agents=10, dt=0.5),
}


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("name", list(SUBSTEP_CONFIGS))
def test_substeps_match_the_numpy_core(name, dtype):
    # float64 to round-off (1e-9), float32 to 2e-4, with the substep counts exact; the
    # swarms of a batch take different counts (dt_half: 3 and 4 in one step).
    cfg = make_config(SUBSTEP_CONFIGS[name])
    ref = rollout(SwarmNavCore(cfg, batch=3, dtype=dtype), seed=2, steps=12, reset_every=5)
    ours = rollout(
        TorchSwarmNavCore(cfg, batch=3, dtype=dtype, compile=False),
        seed=2,
        steps=12,
        reset_every=5,
    )
    assert_same_rollout(ours, ref, TOL[dtype])
    substeps, unstable = step_stats(ours)
    assert substeps.min() >= 1 and substeps.max() >= 3 and not unstable.any()
    if name == "dt_half":
        assert any(len(set(row)) > 1 for row in substeps.tolist())


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize(
    "overrides",
    [dict(n_agents=10, dt=0.5, max_substeps=3), dict(n_agents=20, max_substeps=1)],
    ids=["cap3", "cap1"],
)
def test_substep_cap_truncates_as_the_numpy_core(overrides, dtype):
    # on_unstable="truncate": swarms needing more than max_substeps are put back to
    # their state before the step (reward 0, truncated, unstable 1) and then reset.
    cfg = SwarmConfig(**overrides, on_unstable="truncate")
    ref = rollout(SwarmNavCore(cfg, batch=4, dtype=dtype), seed=7, steps=12, reset_every=5)
    ours = rollout(
        TorchSwarmNavCore(cfg, batch=4, dtype=dtype, compile=False),
        seed=7,
        steps=12,
        reset_every=5,
    )
    assert_same_rollout(ours, ref, TOL[dtype])
    substeps, unstable = step_stats(ours)
    assert unstable.any() and not unstable.all()
    assert (substeps[unstable == 1] == 0).all()  # the step was undone
    assert (substeps[unstable == 0] >= 1).all()
    for _, reward, _, truncated, stats in ours:
        if reward is not None:
            hit = stats["unstable"] == 1
            assert truncated[hit].all() and (reward[hit] == 0).all()


@pytest.mark.parametrize(
    "overrides",
    [dict(n_agents=10, dt=0.5, max_substeps=3), dict(n_agents=20, max_substeps=1)],
    ids=["cap3", "cap1"],
)
def test_substep_cap_raises_as_the_numpy_core(overrides):
    cfg = SwarmConfig(**overrides)  # on_unstable="raise", the default
    messages, states = [], []
    for core in (
        SwarmNavCore(cfg, batch=3),
        TorchSwarmNavCore(cfg, batch=3, dtype=np.float64, compile=False),
    ):
        core.reset(np.random.default_rng(0))
        with pytest.raises(SwarmUnstableError, match="max_substeps") as err:
            for _ in range(10):
                core.step(np.zeros((3, cfg.n_agents, 2)))
        messages.append(str(err.value))
        states.append((core.x, core.v, core.stats()))
    assert messages[0] == messages[1]
    assert f"more than max_substeps={cfg.max_substeps}" in messages[1]
    # The core stays at the last sound state: the unstable swarm's step is undone.
    (x_ref, v_ref, stats_ref), (x, v, stats) = states
    np.testing.assert_allclose(x, x_ref, **TOL[np.float64])
    np.testing.assert_allclose(v, v_ref, **TOL[np.float64])
    np.testing.assert_array_equal(stats["substeps"], stats_ref["substeps"])
    assert not stats["unstable"].any()


def test_non_finite_state_raises_as_the_numpy_core():
    # Velocities of 1e200 make the kinetic energy infinite: the guard's finiteness
    # check (not the cap) must catch it, although the state's stable substep is finite.
    cfg = SwarmConfig(n_agents=5)
    messages = []
    for core in (
        SwarmNavCore(cfg, batch=3),
        TorchSwarmNavCore(cfg, batch=3, dtype=np.float64, compile=False),
    ):
        core.reset(np.random.default_rng(0))
        core.step(np.zeros((3, 5, 2)))
        v = np.array(core.v)
        v[1] = 1e200
        core.v = v
        with pytest.raises(SwarmUnstableError, match="NaN or infinite") as err:
            core.step(np.zeros((3, 5, 2)))
        messages.append(str(err.value))
    assert messages[0] == messages[1] and "swarm 1 of 3" in messages[1]


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_resets_of_a_few_swarms_with_substeps(dtype):
    # The sub-batch reset writes the reset swarms' stable substeps and their substeps
    # statistic (0), and the unstable statistic of every swarm becomes 0, as after the
    # numpy core's reset.
    cfg = SwarmConfig(n_agents=8, dt=0.3, max_substeps=2, on_unstable="truncate")
    ours = TorchSwarmNavCore(cfg, batch=64, dtype=dtype, compile=False)
    got = rollout(ours, seed=3, steps=12, reset_every=3, few=True)
    ref = rollout(
        SwarmNavCore(cfg, batch=64, dtype=dtype), seed=3, steps=12, reset_every=3, few=True
    )
    assert_same_rollout(got, ref, TOL[dtype])
    substeps, unstable = step_stats(got)
    assert substeps.max() == 2 and unstable.any()


@pytest.mark.parametrize("batch", [4, 64])
def test_substeps_are_zero_after_a_reset_only_for_the_swarms_reset(batch):
    # 4 swarms: a reset measures the whole batch; 64: the sub-batch of the swarms reset.
    cfg = SwarmConfig(n_agents=10, dt=0.5)
    core = TorchSwarmNavCore(cfg, batch=batch, dtype=np.float64, compile=False)
    ref = SwarmNavCore(cfg, batch=batch)
    which = np.zeros(batch, dtype=bool)
    which[[1, 2]] = True
    for c in (core, ref):
        c.reset(np.random.default_rng(0))
        assert (c.stats()["substeps"] == 0).all()
        c.step(np.zeros((batch, 10, 2)))
        c.reset(np.random.default_rng(1), which=which)
    substeps = core.stats()["substeps"]
    assert (substeps[which] == 0).all() and (substeps[~which] >= 3).all()
    np.testing.assert_array_equal(substeps, ref.stats()["substeps"])


def test_a_start_that_overflows_the_dtype_raises_as_the_numpy_core():
    cfg = SwarmConfig(n_agents=4, init_speed=1e25)  # |v|² overflows float32
    messages = []
    for core in (
        SwarmNavCore(cfg, batch=2, dtype=np.float32),
        TorchSwarmNavCore(cfg, batch=2, compile=False),
    ):
        with pytest.raises(SwarmUnstableError, match="not finite in float32") as err:
            core.reset(np.random.default_rng(0))
        messages.append(str(err.value))
    assert messages[0] == messages[1]


def test_same_seed_same_start_and_attributes_as_numpy():
    cfg = SwarmConfig(n_agents=8)
    ref = SwarmNavCore(cfg, batch=3, dtype=np.float32)
    ours = TorchSwarmNavCore(cfg, batch=3, compile=False)
    ref.reset(np.random.default_rng(11))
    ours.reset(np.random.default_rng(11))
    for name in ("x", "v", "goal"):  # the same draws, cast the same way: bit for bit
        np.testing.assert_array_equal(getattr(ours, name), getattr(ref, name), err_msg=name)
    for key, value in ref.stats().items():  # the start's statistics
        np.testing.assert_allclose(ours.stats()[key], value, rtol=1e-5, atol=1e-6, err_msg=key)
    assert ours.x.shape == (3, 8, 2) and ours.x.dtype == np.float32
    assert ours.batch == 3 and ours.obs_dim == ref.obs_dim and ours.cfg is cfg
    np.testing.assert_array_equal(ours.t, ref.t)
    ours.reset(np.random.default_rng(12))
    assert not np.array_equal(ours.x, ref.x)  # different seed, different start


def test_step_counter_is_writable_and_truncates():
    cfg = SwarmConfig(n_agents=3, max_steps=10)
    core = TorchSwarmNavCore(cfg, batch=3, compile=False)
    core.reset(np.random.default_rng(0))
    core.t[1] = cfg.max_steps - 1  # as the VecEnv tests do on the numpy core
    _, terminated, truncated, _ = core.step(np.zeros((3, 3, 2)))
    assert truncated.tolist() == [False, True, False] and not terminated.any()


def test_state_views_are_read_only_copies_and_assignment_remeasures():
    core = TorchSwarmNavCore(SwarmConfig(n_agents=4), batch=2, compile=False)
    core.reset(np.random.default_rng(0))
    x = core.x
    with pytest.raises(ValueError, match="read-only"):
        x[0, 0, 0] = 1.0
    before = core.observe()
    core.x = x + 1.0  # shifts every agent: the goal offset in the observation changes
    after = core.observe()
    np.testing.assert_allclose(after[..., :2], before[..., :2] - 0.1, atol=1e-6)
    np.testing.assert_allclose(core.x, x + 1.0)
    with pytest.raises(ValueError, match="finite numeric array of shape"):
        core.v = np.zeros((2, 4, 3))
    with pytest.raises(ValueError, match="finite"):
        core.goal = np.full((2, 2), np.nan)


def test_observe_hands_out_fresh_arrays():
    core = TorchSwarmNavCore(SwarmConfig(n_agents=4), batch=2, compile=False)
    core.reset(np.random.default_rng(0))
    core.step(np.zeros((2, 4, 2)))
    first = core.observe()
    second = core.observe()
    np.testing.assert_array_equal(first, second)
    first[:] = 99.0
    assert np.abs(core.observe()).max() <= OBS_BOUND
    stats = core.stats()
    stats["energy"][:] = 0.0
    assert core.stats()["energy"].any()


def test_coincident_agents_and_bound_actions_stay_finite():
    cfg = SwarmConfig(n_agents=6, collision_radius=0.5)
    core = TorchSwarmNavCore(cfg, batch=2, compile=False)
    core.reset(np.random.default_rng(0))
    core.x = np.zeros((2, 6, 2))  # everybody on the same spot
    signs = np.random.default_rng(1).choice([-1.0, 1.0], size=(2, 6, 2))
    for _ in range(5):
        reward, _, _, stats = core.step(signs)
        obs = core.observe()
        assert np.isfinite(obs).all() and np.abs(obs).max() <= OBS_BOUND
        assert np.isfinite(reward).all()
        assert all(np.isfinite(stats[k]).all() for k in STAT_KEYS)


def test_torch_actions_and_flat_actions_are_accepted():
    cfg = SwarmConfig(n_agents=3)
    a = np.random.default_rng(0).uniform(-1, 1, (2, 3, 2))
    results = []
    for actions in (a, torch.from_numpy(a), a.reshape(-1)):
        core = TorchSwarmNavCore(cfg, batch=2, compile=False)
        core.reset(np.random.default_rng(0))
        results.append(core.step(actions)[0])
    np.testing.assert_allclose(results[1], results[0], rtol=1e-6)
    np.testing.assert_array_equal(results[2], results[0])


@pytest.mark.parametrize(
    ("actions", "match"),
    [
        (np.zeros((2, 3, 3)), "shape"),
        (np.full((2, 3, 2), np.nan), "finite"),
        (np.array([["a"]]), "numeric"),
        (torch.full((2, 3, 2), float("inf")), "finite"),
        (torch.zeros(2, 3, 3), "shape"),
    ],
)
def test_bad_actions_raise_value_error(actions, match):
    core = TorchSwarmNavCore(SwarmConfig(n_agents=3), batch=2, compile=False)
    core.reset(np.random.default_rng(0))
    with pytest.raises(ValueError, match=match):
        core.step(actions)


def test_unsupported_configs_and_options_raise_value_error():
    with pytest.raises(ValueError, match="semi_implicit_euler"):
        TorchSwarmNavCore(SwarmConfig(integrator="velocity_verlet"), compile=False)
    if any(f.name == "dynamics" for f in dataclasses.fields(SwarmConfig)):
        with pytest.raises(ValueError, match="social_potential"):
            TorchSwarmNavCore(SwarmConfig(dynamics="zone"), compile=False)
    with pytest.raises(ValueError, match="dtype"):
        TorchSwarmNavCore(SwarmConfig(), dtype=np.int32, compile=False)
    with pytest.raises(ValueError, match="batch"):
        TorchSwarmNavCore(SwarmConfig(), batch=0, compile=False)
    with pytest.raises(ValueError, match="device"):
        TorchSwarmNavCore(SwarmConfig(), device="warp-drive", compile=False)
    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match="cuda"):
            TorchSwarmNavCore(SwarmConfig(), device="cuda", compile=False)
    with pytest.raises(ValueError, match="compile"):
        TorchSwarmNavCore(SwarmConfig(), compile="sometimes")


def test_pickle_round_trip_reproduces_the_rollout():
    cfg = SwarmConfig(n_agents=5)
    core = TorchSwarmNavCore(cfg, batch=2, compile=False)
    core.reset(np.random.default_rng(3))
    actions = np.random.default_rng(4).uniform(-1, 1, (6, 2, 5, 2))
    core.step(actions[0])
    clone = pickle.loads(pickle.dumps(core))
    for a in actions[1:]:
        r1, *_ = core.step(a)
        r2, *_ = clone.step(a)
        np.testing.assert_array_equal(r1, r2)
        np.testing.assert_array_equal(core.observe(), clone.observe())
    np.testing.assert_array_equal(core.t, clone.t)
    np.testing.assert_array_equal(core.stats()["substeps"], clone.stats()["substeps"])


def test_fallback_is_used_when_compiling_is_unavailable(monkeypatch):
    from swarm_envs._runtime import torch_compile as tb

    monkeypatch.delenv(tb.COMPILE_ENV, raising=False)
    monkeypatch.setattr(tb, "compile_support", lambda device="cpu": "no C++ compiler found")
    core = TorchSwarmNavCore(SwarmConfig(n_agents=3), batch=2)  # compile="auto"
    assert not core.compiled and core.compile_seconds is not None
    monkeypatch.setenv(tb.COMPILE_ENV, "0")
    monkeypatch.setattr(tb, "compile_support", lambda device="cpu": None)
    assert not TorchSwarmNavCore(SwarmConfig(n_agents=3), batch=2).compiled


def count_calls(monkeypatch, fn) -> list[int]:
    """Wrap ``fn`` (a MaybeCompiled) so that each call appends its batch size."""
    calls: list[int] = []
    inner = fn._call

    def counted(*args):
        calls.append(args[0].shape[1])
        return inner(*args)

    monkeypatch.setattr(fn, "_call", counted)
    if fn._direct is not None:  # the compiled graph called without Dynamo's guards
        direct = fn._direct

        class Counted:
            arity = direct.arity

            def __call__(self, args):
                calls.append(args[0].shape[1])
                return direct(args)

        monkeypatch.setattr(fn, "_direct", Counted())
    return calls


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_resets_of_a_few_swarms_measure_only_those(monkeypatch, dtype):
    # B = 64: resets of up to 4 swarms run the fused function on 4 swarms (padded);
    # the truncation of all 64 at step 20 re-measures the whole batch. Observations
    # handed out before a reset must keep their values (rollout keeps them all).
    cfg = SwarmConfig(n_agents=8, max_steps=20)
    ours = TorchSwarmNavCore(cfg, batch=64, dtype=dtype, compile=False)
    assert ours.reset_batch == 4
    part = count_calls(monkeypatch, ours._advance_part)
    full = count_calls(monkeypatch, ours._advance)
    got = rollout(ours, seed=3, steps=30, reset_every=5, few=True)
    ref = rollout(
        SwarmNavCore(cfg, batch=64, dtype=dtype), seed=3, steps=30, reset_every=5, few=True
    )
    assert_same_rollout(got, ref, TOL[dtype])
    # Six partial resets (after steps 5, 10, ..., 30): those of at most 4 swarms ran on
    # 4, the others (all 64 truncated after step 20, successes) on the whole batch.
    assert len(part) >= 3 and set(part) == {4}
    assert full == [64] * (1 + 30 + 6 - len(part))  # reset(), the steps, the rest
    assert TorchSwarmNavCore(cfg, batch=63, compile=False).reset_batch is None


def test_observations_handed_out_keep_their_values_through_a_few_resets():
    core = TorchSwarmNavCore(SwarmConfig(n_agents=5), batch=64, compile=False)
    rng = np.random.default_rng(0)
    core.reset(rng)
    core.step(np.zeros((64, 5, 2)))
    tensor = core.observe_tensor()
    saved = tensor.clone()
    which = np.zeros(64, bool)
    which[[3, 40]] = True
    core.reset(rng, which=which)  # a sub-batch reset: 2 ≤ reset_batch = 4
    assert torch.equal(tensor, saved)
    after = core.observe()
    assert not np.array_equal(after[which], saved.numpy()[which])  # new starts
    np.testing.assert_array_equal(after[~which], saved.numpy()[~which])
    core.reset(rng, which=which)
    np.testing.assert_array_equal(after[~which], saved.numpy()[~which])  # the array too


@pytest.mark.skipif(compile_support("cpu") is not None, reason="torch.compile unavailable")
def test_compiled_core_matches_plain_core():
    # 64 swarms: the compiled sub-batch reset (4 swarms, padded) is checked too.
    cfg = SwarmConfig(n_agents=6, n_neighbors=3, max_steps=16)
    compiled = TorchSwarmNavCore(cfg, batch=64, compile=True)
    assert compiled.compiled and compiled.compile_seconds > 0
    assert compiled._advance_part is not None and compiled._advance_part.compiled
    plain = TorchSwarmNavCore(cfg, batch=64, compile=False)
    assert_same_rollout(
        rollout(compiled, seed=5, steps=24, reset_every=4, few=True),
        rollout(plain, seed=5, steps=24, reset_every=4, few=True),
        TOL[np.float32],
    )


@pytest.mark.skipif(compile_support("cpu") is not None, reason="torch.compile unavailable")
@pytest.mark.parametrize("integrator", ["semi_implicit_euler", "implicit_damping_euler"])
def test_compiled_substeps_match_the_numpy_core(monkeypatch, integrator):
    # Every step needs two substeps for some swarm, and some swarms need more than the
    # cap of 2 (truncated): the compiled substep function, float64, against numpy.
    dt = 0.3 if integrator == "semi_implicit_euler" else 1.0
    cfg = SwarmConfig(
        n_agents=8,
        dt=dt,
        max_substeps=2,
        on_unstable="truncate",
        max_steps=16,
        integrator=integrator,
    )
    compiled = TorchSwarmNavCore(cfg, batch=4, dtype=np.float64, compile=True)
    assert compiled.compiled and compiled._substep.compiled
    calls = count_calls(monkeypatch, compiled._substep)
    got = rollout(compiled, seed=5, steps=24, reset_every=4)
    ref = rollout(SwarmNavCore(cfg, batch=4), seed=5, steps=24, reset_every=4)
    assert_same_rollout(got, ref, TOL[np.float64])
    substeps, unstable = step_stats(got)
    assert len(calls) >= 24 and substeps.max() == 2 and unstable.any()


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
@pytest.mark.parametrize(
    ("overrides", "dtype"),
    [
        (dict(n_agents=12), np.float32),
        (dict(n_agents=8, dt=0.3, max_substeps=2, on_unstable="truncate"), np.float64),
        (dict(n_agents=20, max_substeps=1, on_unstable="truncate"), np.float64),
    ],
    ids=["one_substep", "substeps_and_truncation", "cap1_truncation"],
)
def test_cuda_core_matches_cpu_core(overrides, dtype):
    # With substeps: the substep function runs outside the CUDA graph, and a truncated
    # swarm goes back to the state kept from the graph's inputs (cap 1) or a copy.
    cfg = SwarmConfig(**overrides)
    gpu = TorchSwarmNavCore(cfg, batch=16, dtype=dtype, device="cuda")
    cpu = TorchSwarmNavCore(cfg, batch=16, dtype=dtype, device="cpu", compile=False)
    assert_same_rollout(
        rollout(gpu, seed=9, steps=30, reset_every=10),
        rollout(cpu, seed=9, steps=30, reset_every=10),
        TOL[np.float32],
    )
