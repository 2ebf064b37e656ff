"""The fuzzing campaign as tests: random configs, status sequences and actions on every
backend, checked for finite values inside their bounds, agreement with the reference,
and clear errors.

Short form (run always, a few examples each): the status-sequence property on every
backend that takes statuses (the torch core compiled and plain), and random configs,
integrators and action sequences on every backend. Long form (``@pytest.mark.slow``,
``--runslow``): more examples, larger and stiffer configs, and the reproducer of the
compiled torch step with agents that are absent and join later, 10,000 steps against the
numpy reference.
"""

from __future__ import annotations

import dataclasses
import os
import warnings

import numpy as np
import pytest
from conformance import (
    BATCH,
    MARGIN,
    STATUS_CONFIG,
    TOLERANCE,
    Variant,
    compare_statuses,
    configs,
    status_sequences,
)
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from swarm_envs import SwarmUnstableError
from swarm_envs.config import INTEGRATORS, SwarmConfig
from swarm_envs.envs.cores.numpy import SwarmNavCore
from swarm_envs.envs.task.observation import OBS_BOUND
from swarm_envs.perturbations import Perturbations

#: Examples per long-form property (``SWARM_ENVS_FUZZ_EXAMPLES`` overrides).
LONG = int(os.environ.get("SWARM_ENVS_FUZZ_EXAMPLES", "50"))


def _settings(examples: int) -> settings:
    return settings(
        max_examples=examples,
        deadline=None,
        # The same examples on every run (a test suite passes or fails reproducibly);
        # SWARM_ENVS_EXPLORE=1 draws new ones, to hunt for new failures.
        derandomize=not os.environ.get("SWARM_ENVS_EXPLORE"),
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    )


# --------------------------------------------------------------------------- statuses

#: The variants of the status property: every backend that takes statuses (the C step
#: where it is built), the torch core plain and compiled.
STATUS_VARIANTS = (
    ("numpy-float32", Variant("numpy", np.float32), None),
    ("cutoff-float64", Variant("cutoff", np.float64), None),
    ("torch-plain-float64", Variant("torch", np.float64), False),
    ("torch-plain-float32", Variant("torch", np.float32), False),
    ("torch-compiled-float64", Variant("torch", np.float64), True),
    ("native-float64", Variant("native", np.float64), None),
)

_CORES: dict[str, tuple] = {}


def _status_cores(name: str, variant: Variant, compiled: bool | None) -> tuple:
    """The variant's core and the reference for :data:`STATUS_CONFIG`, built once per
    session (compiling the torch step takes most of the short form's time)."""
    if name not in _CORES:
        cfg = STATUS_CONFIG
        reason = variant.unsupported(cfg)
        if reason is not None:
            if variant.backend == "native":
                pytest.skip(f"C step unavailable: {reason}")
            pytest.fail(f"{name} refuses a config it must run: {reason}")
        if compiled is None:
            ours = variant.make(cfg).inner  # the core itself: the test gives the statuses
        else:
            from swarm_envs._runtime.torch_compile import compile_support
            from swarm_envs.envs.cores.torch.core import TorchSwarmNavCore

            if compiled and compile_support("cpu") is not None:
                pytest.skip(f"torch.compile unavailable: {compile_support('cpu')}")
            ours = TorchSwarmNavCore(cfg, batch=BATCH, dtype=variant.dtype, compile=compiled)
            assert ours.compiled == compiled
        _CORES[name] = (ours, SwarmNavCore(cfg, batch=BATCH, dtype=np.float64))
    return _CORES[name]


def _direct_calls(core) -> list:
    """The compiled functions of a torch core that call their graphs directly."""
    fns = [core._advance, core._substep, core._advance_part]
    return [fn._direct for fn in fns if fn is not None and fn._direct is not None]


@pytest.mark.parametrize(
    ("name", "variant", "compiled"), STATUS_VARIANTS, ids=[v[0] for v in STATUS_VARIANTS]
)
@_settings(5)
@given(sequence=status_sequences(), seed=st.integers(0, 2**16))
def test_any_status_sequence_matches_the_reference(name, variant, compiled, sequence, seed):
    # Agents absent, joining, failing (passive or frozen) and leaving at random steps.
    ours, ref = _status_cores(name, variant, compiled)
    start, events = sequence
    dtype = np.dtype(variant.dtype)
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)  # no fallback, no relaid graph input
        problems = compare_statuses(ours, ref, start, events, seed, TOLERANCE[dtype], MARGIN[dtype])
    assert not problems, f"{name}: {problems}"
    if compiled:  # every call ran the traced graph on tensors of its traced layout
        directs = _direct_calls(ours)
        assert directs, "the compiled torch core calls no graph directly"
        assert [(d.relaid, d.guarded) for d in directs] == [(0, 0)] * len(directs)


# --------------------------------------------------------------------------- configs


def _backend_names() -> list[str]:
    return ["numpy", "cutoff", "torch", "native"]


def _make(cfg: SwarmConfig, backend: str, dtype) -> object | None:
    """The backend's core for ``cfg`` (inside its perturbations), or ``None`` where it
    refuses the config; a refusal must give a reason."""
    variant = Variant(backend, dtype)
    reason = variant.unsupported(cfg)
    if reason is not None:
        assert reason.strip(), f"{backend} refuses {cfg} without a reason"
        return None
    return variant.make(cfg)


@st.composite
def action_sequences(draw, steps: int) -> list:
    """Per step, how the actions are drawn: uniform, at the bounds (saturated, flipping
    sign every step), zero, or out of range (clipped by the core)."""
    kinds = st.sampled_from(("uniform", "saturated", "flipping", "zero", "wide"))
    return draw(st.lists(kinds, min_size=steps, max_size=steps))


def _actions(kind: str, step: int, shape: tuple, rng: np.random.Generator) -> np.ndarray:
    if kind == "uniform":
        return rng.uniform(-1.0, 1.0, shape)
    if kind == "saturated":
        return np.sign(rng.uniform(-1.0, 1.0, shape))
    if kind == "flipping":
        return np.full(shape, 1.0 if step % 2 else -1.0)
    if kind == "zero":
        return np.zeros(shape)
    return rng.uniform(-50.0, 50.0, shape)


def run_checked(core, kinds: list, seed: int) -> int:
    """Step ``core`` through the actions ``kinds`` (resetting ended swarms); check that
    every observation is finite and inside ``±OBS_BOUND``, every reward finite in
    float32 and every statistic finite; return the steps taken before a
    :class:`SwarmUnstableError` (whose message must name the cause and the fix)."""
    rng = np.random.default_rng(seed)
    core.reset(rng)
    shape = (core.batch, core.cfg.n_agents, core.cfg.dim)
    actions = np.random.default_rng(seed + 1)
    for step, kind in enumerate(kinds):
        _check_finite(core, step)
        try:
            reward, terminated, truncated, stats = core.step(_actions(kind, step, shape, actions))
        except SwarmUnstableError as err:
            message = str(err)
            assert "unstable step" in message and "To fix:" in message, message
            return step
        assert reward.shape == (core.batch,) and np.isfinite(reward).all(), (step, reward)
        assert np.isfinite(reward.astype(np.float32)).all(), (step, reward)
        for key, value in stats.items():
            assert np.isfinite(value).all(), (step, key, value)
        ended = terminated | truncated
        if ended.any():
            core.reset(rng, which=ended)
    _check_finite(core, len(kinds))
    return len(kinds)


def _check_finite(core, step: int) -> None:
    obs = core.observe()
    assert obs.dtype == np.float32 and np.isfinite(obs).all(), step
    assert np.abs(obs).max(initial=0.0) <= OBS_BOUND, step
    assert np.isfinite(core.x).all() and np.isfinite(core.v).all(), step


@st.composite
def fuzz_configs(draw, stiff: bool = False) -> SwarmConfig:
    """A config of the conformance suite's strategy with the integrator, the step and
    the unstable policy drawn over their whole ranges (large ``dt`` included), and
    (``stiff``) denser, larger swarms."""
    cfg = draw(configs())
    dt = draw(st.sampled_from((0.05, 0.3, 1.0, 5.0)))
    fields = {
        "dt": dt,
        "integrator": draw(st.sampled_from(INTEGRATORS)),
        "on_unstable": draw(st.sampled_from(("raise", "truncate"))),
        "max_substeps": draw(st.sampled_from((4, 64, 1000))),
        "max_steps": draw(st.integers(1, 30)),
    }
    if stiff:
        fields["n_agents"] = draw(st.integers(20, 120))
        fields["init_density"] = draw(st.floats(0.3, 1.5))
        fields["init_radius"] = 1.5  # the default: init_density sets the start radius
    if cfg.dynamics == "lagrangian":
        fields.pop("init_density", None)
        fields.pop("init_radius", None)
    if fields["integrator"] != "semi_implicit_euler" and cfg.perturbations.needs_masks:
        fields["integrator"] = "semi_implicit_euler"  # masks need Euler (a config rule)
    try:
        return dataclasses.replace(cfg, **fields)
    except ValueError:  # a combination the config refuses, with its reason
        return cfg


@pytest.mark.parametrize("backend", _backend_names())
@_settings(6)
@given(cfg=fuzz_configs(), kinds=action_sequences(12), seed=st.integers(0, 2**16))
def test_random_configs_run_finite_or_fail_loudly(backend, cfg, kinds, seed):
    core = _make(cfg, backend, np.float64 if backend != "numpy" else np.float32)
    if core is None:
        return
    run_checked(core, kinds, seed)


@pytest.mark.slow
@pytest.mark.parametrize("backend", _backend_names())
@_settings(LONG)
@given(cfg=fuzz_configs(stiff=True), kinds=action_sequences(40), seed=st.integers(0, 2**16))
def test_random_stiff_configs_run_finite_or_fail_loudly_long(backend, cfg, kinds, seed):
    for dtype in (np.float32, np.float64):
        core = _make(cfg, backend, dtype)
        if core is not None:
            run_checked(core, kinds, seed)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "variant", "compiled"), STATUS_VARIANTS, ids=[v[0] for v in STATUS_VARIANTS]
)
@_settings(LONG)
@given(sequence=status_sequences(), seed=st.integers(0, 2**16))
def test_any_status_sequence_matches_the_reference_long(name, variant, compiled, sequence, seed):
    test_any_status_sequence_matches_the_reference.hypothesis.inner_test(
        name, variant, compiled, sequence, seed
    )


# --------------------------------------------------------------------------- reproducers


def test_verlet_at_a_large_step_is_integrated_stably():
    # dt=5 with velocity Verlet: its explicit damping is stable only to h·γ < 1, half
    # of Euler's edge; the rule of that integrator keeps the swarm bounded.
    env_cfg = SwarmConfig(integrator="velocity_verlet", dt=5.0, n_agents=10)
    for backend in ("numpy", "cutoff"):
        core = _make(env_cfg, backend, np.float64)
        assert run_checked(core, ["uniform"] * 40, seed=0) == 40
        assert np.abs(core.v).max() < 50.0, backend


@pytest.mark.slow
@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "plain"])
def test_absent_and_joining_agents_10000_steps_on_the_torch_core(compiled, monkeypatch):
    # The campaign's crash: the compiled step after agents joined (their positions
    # stored in another layout than the graph was traced for).
    from swarm_envs import swarm_nav_v0
    from swarm_envs._runtime.torch_compile import COMPILE_ENV, compile_support

    if compiled and compile_support("cpu") is not None:
        pytest.skip("torch.compile unavailable")
    monkeypatch.setenv(COMPILE_ENV, "1" if compiled else "0")
    kwargs = dict(
        n_agents=10,
        perturbations=Perturbations(absent_fraction=0.3, join_fraction=0.3, join_time=[1, 200]),
        observe_status=True,
        dtype=np.float64,
    )
    ours = swarm_nav_v0.vec_env(16, backend="torch", **kwargs)
    ref = swarm_nav_v0.vec_env(16, backend="numpy", **kwargs)
    ours.seed(0)
    ref.seed(0)
    ours.reset()
    ref.reset()
    rng = np.random.default_rng(0)
    core, ref_core = ours.cores[0], ref.cores[0]
    joined = 0
    for _ in range(10_000):
        a = rng.uniform(-1, 1, (ours.num_envs, *ours.action_space.shape)).astype(np.float32)
        before = core.status.copy()
        obs, reward, done, _ = ours.step(a)
        _, ref_reward, ref_done, _ = ref.step(a)
        joined += int(((before == 3) & (core.status != 3)).sum())
        assert np.isfinite(obs).all() and np.isfinite(reward).all()
        np.testing.assert_array_equal(done, ref_done)
        np.testing.assert_array_equal(core.status, ref_core.status)
        np.testing.assert_allclose(reward, ref_reward, rtol=1e-4, atol=1e-4)
    assert joined > 1000


@pytest.mark.parametrize("backend", ["numpy", "cutoff"])
def test_a_diverging_integration_is_stopped_by_the_energy_bound(backend, monkeypatch):
    # Verlet given Euler's step-size edge (twice its stable damping) diverges while its
    # state stays finite and its observation clipped: the guard's energy bound stops it.
    from swarm_envs.physics import integrators

    monkeypatch.setitem(integrators._DAMPING_WEIGHT, "velocity_verlet", 1.0)
    cfg = SwarmConfig(integrator="velocity_verlet", dt=5.0, n_agents=10)
    core = _make(cfg, backend, np.float64)
    core.reset(np.random.default_rng(0))
    actions = np.random.default_rng(1)
    with pytest.raises(SwarmUnstableError, match="left its bound"):
        for _ in range(40):
            reward = core.step(actions.uniform(-1, 1, (BATCH, 10, 2)))[0]
            assert np.isfinite(reward.astype(np.float32)).all()
    assert core.t.max() < 15  # within a few steps of leaving the terminal speed


def test_a_speed_bound_past_float_range_leaves_the_guard_off():
    # Found by the fuzz module: a vanishing friction (β = 3.6e-300) makes the terminal
    # speed finite but its square overflow; the energy bound is then infinite, not an error.
    import dataclasses
    import math

    from swarm_envs.config import SwarmConfig
    from swarm_envs.envs.common import energy_bound
    from swarm_envs.physics import SocialPotentialParams

    params = dataclasses.replace(SocialPotentialParams.navigation(), beta=3.64e-300)
    assert energy_bound(SwarmConfig(physics=params)) == math.inf


def test_a_state_that_diverges_inside_a_torch_step_fails_loudly():
    # Found by the fuzz module: dt = 5 on the self-propelled swarm makes the state NaN
    # inside the compiled step; the neighbour ranking then held no entry and produced an
    # index out of range (a RuntimeError from a gather). Now the guard reports it.
    from swarm_envs.config import RewardWeights, SwarmConfig
    from swarm_envs.physics import SocialPotentialParams

    params = SocialPotentialParams(
        C_a=0.0,
        C_r=1.0,
        l_a=1.0,
        l_r=0.5,
        C_o=0.0,
        l_o=1.0,
        beta=2.0,
        C_g=0.0,
        m=1.5,
        alpha=0.5,
    )
    cfg = SwarmConfig(
        n_agents=12,
        dt=5.0,
        max_substeps=64,
        physics=params,
        init_radius=1.0,
        init_speed=0.0,
        goal_distance_min=0.0,
        goal_distance_max=0.0,
        goal_radius=1.0,
        max_steps=3,
        u_max=4.0,
        n_neighbors=1,
        collision_radius=0.0,
        task="mill",
        reward=RewardWeights(progress=0, arrival=0, collision=0, effort=0, time=0, mill=0),
    )
    core = _make(cfg, "torch", np.float64)
    if core is None:
        pytest.skip("the torch backend does not take this config here")
    run_checked(core, ["uniform"] * 10 + ["zero", "uniform"], 0)


def test_an_energy_bound_past_float32_is_compared_in_float64():
    # Found by the conformance suite: a bound of 1e302 against float32 energies was cast
    # to float32 (an overflow warning, an error in the tests) instead of compared.
    from swarm_envs.envs.common import beyond_bound

    energy = np.array([1.0, 3e38], np.float32)
    assert not beyond_bound({"energy": energy}, 1e302)
    assert beyond_bound({"energy": energy}, 1e30)
