"""Every backend executes the same definitions: the conformance suite.

For random valid configs (hypothesis: every numeric field of the env config — reward
weights, observation scales, k, d, dt, u_max, the goal radius, the physics, and for a
share of the configs the perturbations and ``observe_status`` — and the state's dtype),
every backend either matches the reference, the numpy core in float64 (float64: to
round-off; float32: to 2e-3), through automatic resets, or refuses the config up front
with a reason. The C step runs in the variant chosen for this CPU and in the prebuilt
``x86-64-v3`` one (no AVX-512 branches); CI also runs its variants on the prebuilt
portable one (no ``-march``).
``tests/conformance.py`` holds the machinery; the tests at the end show that it catches
one backend's perturbed term.
"""

from __future__ import annotations

import dataclasses
import os
import warnings

import numpy as np
import pytest
from conformance import (
    NOT_DRAWN,
    VARIANTS,
    Variant,
    check,
    compare,
    configs,
    field_strategies,
    perturbed,
    rollout,
)
from hypothesis import HealthCheck, given, settings

from swarm_envs import swarm_nav_v0
from swarm_envs.config import DYNAMICS, RewardWeights, SwarmConfig
from swarm_envs.envs import backends
from swarm_envs.envs.cores.numpy import SwarmNavCore
from swarm_envs.envs.task import REWARD_TERMS
from swarm_envs.perturbations import Perturbations
from swarm_envs.physics import SocialPotentialParams

SETTINGS = settings(
    max_examples=int(os.environ.get("SWARM_ENVS_CONFORMANCE_EXAMPLES", "25")),
    deadline=None,
    # The same examples on every run; SWARM_ENVS_EXPLORE=1 draws new ones.
    derandomize=not os.environ.get("SWARM_ENVS_EXPLORE"),
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)


@pytest.mark.parametrize("variant", VARIANTS, ids=lambda v: v.name)
@SETTINGS
@given(cfg=configs())
def test_every_backend_matches_the_reference_or_refuses(variant, cfg):
    problems = check(variant, cfg)
    if problems and problems[0].startswith("refused: "):
        assert len(problems) == 1
        return
    assert not problems, f"{variant.name} on {cfg}: {problems}"


@pytest.mark.parametrize("variant", VARIANTS, ids=lambda v: v.name)
def test_every_backend_runs_the_default_and_the_navigation_configs(variant):
    # A backend that refused everything would pass the property above.
    for cfg in (SwarmConfig(), SwarmConfig(n_agents=31, dim=3, goal_in_physics=True)):
        if variant.backend in ("native",) and variant.unsupported(cfg):
            pytest.skip(f"C step unavailable: {variant.unsupported(cfg)}")
        assert check(variant, cfg) == []


#: Configs whose steps take several substeps (one of them a self-propelled swarm started
#: fast: the Rayleigh term's rate), and one with a cap that some steps exceed (their
#: episodes truncated and reset, as the VecEnv resets them).
SUBSTEP_CONFIGS = (
    SwarmConfig(n_agents=24, dt=0.3),
    SwarmConfig(n_agents=10, dt=0.5, dim=3, goal_in_physics=True),
    SwarmConfig(
        n_agents=10, n_neighbors=3, dt=0.3, init_speed=4.0, physics=SocialPotentialParams(alpha=1.0)
    ),
    SwarmConfig(n_agents=10, dt=0.5, max_substeps=4, on_unstable="truncate"),
    # the implicit damping and its block rule (docs/models.md §7)
    SwarmConfig(n_agents=24, dt=0.3, integrator="implicit_damping_euler"),
    SwarmConfig(
        n_agents=10, dt=0.5, dim=3, goal_in_physics=True, integrator="implicit_damping_euler"
    ),
    SwarmConfig(
        n_agents=10,
        n_neighbors=3,
        dt=0.3,
        init_speed=4.0,
        physics=SocialPotentialParams(alpha=1.0),
        integrator="implicit_damping_euler",
    ),
)


@pytest.mark.parametrize(
    "variant", [v for v in VARIANTS if v.backend == "native"], ids=lambda v: v.name
)
def test_the_c_step_matches_the_reference_through_substeps_and_the_cap(variant):
    for cfg in SUBSTEP_CONFIGS:
        if variant.unsupported(cfg):
            pytest.skip(f"C step unavailable: {variant.unsupported(cfg)}")
        assert check(variant, cfg) == [], cfg


#: The torch core through the same configs, and 64 agents of the default physics (a
#: different count per swarm). In float32 the comparison stops where two neighbours tie
#: to that precision, at once in a swarm this dense: tests/test_torch_core.py compares
#: float32 with the numpy core in float32.
TORCH_SUBSTEP_CONFIGS = (*SUBSTEP_CONFIGS, SwarmConfig(n_agents=64))


@pytest.mark.parametrize(
    "variant", [v for v in VARIANTS if v.backend == "torch"], ids=lambda v: v.name
)
def test_the_torch_core_matches_the_reference_through_substeps_and_the_cap(variant):
    for cfg in TORCH_SUBSTEP_CONFIGS:
        assert check(variant, cfg) == [], cfg


#: Perturbed configs every variant runs or refuses: failures (passive, frozen, removed)
#: at drawn steps, absent and joining agents, noise and dropout, observed statuses. A
#: backend without agent statuses refuses the ones that need them, and only those. (The
#: sizes are ones whose seeded rollouts stay decidable in float32 through every step.)
PERTURBED_CONFIGS = (
    SwarmConfig(
        n_agents=8,
        max_steps=6,
        perturbations=Perturbations(
            failed_fraction=0.25,
            failure_time=[0, 4],
            obs_noise=0.05,
            action_noise=[0.1, 0.3],
            neighbor_dropout=0.3,
        ),
    ),
    SwarmConfig(
        n_agents=8,
        max_steps=8,
        goal_in_physics=True,
        observe_status=True,
        perturbations=Perturbations(
            failed_fraction=0.25,
            failure_mode="frozen",
            failure_time=[1, 5],
            absent_fraction=0.1,
            join_fraction=0.2,
            join_time=[1, 6],
        ),
    ),
    SwarmConfig(
        n_agents=12,
        dim=3,
        max_steps=8,
        perturbations=Perturbations(
            failed_fraction=[0.1, 0.3], failure_mode="removed", failure_time=2, obs_noise=0.1
        ),
    ),
    SwarmConfig(  # self-propelled: passive failed agents and joining ones cruise too
        n_agents=10,
        n_neighbors=2,
        max_steps=8,
        init_radius=3.0,
        init_speed=2.0,
        observe_status=True,
        physics=SocialPotentialParams(alpha=0.5, beta=0.5),
        perturbations=Perturbations(
            failed_fraction=0.3, failure_time=[0, 3], join_fraction=0.2, join_time=[1, 5]
        ),
    ),
)

#: The frozen/joining and the self-propelled ones again with the implicit damping.
PERTURBED_CONFIGS = (
    *PERTURBED_CONFIGS,
    *(
        dataclasses.replace(cfg, integrator="implicit_damping_euler")
        for cfg in PERTURBED_CONFIGS[1::2]
    ),
)


def _needs_statuses(cfg: SwarmConfig) -> bool:
    return cfg.observe_status or cfg.perturbations.needs_masks


@pytest.mark.parametrize("variant", VARIANTS, ids=lambda v: v.name)
def test_every_backend_runs_the_perturbations_it_takes(variant):
    if variant.backend == "native" and variant.unsupported(SwarmConfig()):
        pytest.skip(f"C step unavailable: {variant.unsupported(SwarmConfig())}")
    for cfg in PERTURBED_CONFIGS:
        reason = variant.unsupported(cfg)
        if reason is None:
            assert check(variant, cfg) == [], cfg
        elif variant.backend == "cutoff" and cfg.integrator == "implicit_damping_euler":
            assert "integrator" in reason  # the cut-off core does not run it (refused)
        else:
            assert _needs_statuses(cfg), reason
            assert variant.backend not in backends.STATUS_BACKENDS, reason


@SETTINGS
@given(cfg=configs(dynamics=DYNAMICS))
def test_other_models_are_refused_with_a_reason_and_run_on_numpy(cfg):
    # The zone, piecewise and Lagrangian models run on the numpy core only; their
    # discrete rules (zones, turning limits) make float32 and float64 diverge, so they
    # are checked for finite results in both, not against each other.
    # With observe_status a backend without agent statuses may name that first.
    for backend in ("cutoff", "torch", "native"):
        reason = backends.unsupported(cfg, backend)
        if cfg.dynamics != "social_potential":
            assert reason and ("social_potential" in reason or "statuses" in reason)
    for dtype in (np.float32, np.float64):
        core = perturbed(SwarmNavCore(cfg, batch=3, dtype=dtype))
        for obs, reward, _, _, stats in rollout(core, 0):
            assert np.isfinite(obs).all() and all(np.isfinite(v).all() for v in stats.values())
            assert reward is None or np.isfinite(reward).all()


def test_a_refused_backend_falls_back_with_one_warning_naming_both(monkeypatch):
    monkeypatch.setattr(backends, "_WARNED", set())
    cfg = dict(n_agents=4, dynamics="zone", backend="native")
    with pytest.warns(
        UserWarning, match=r"backend 'native' cannot run this config \(.*\); using 'numpy'"
    ):
        env = swarm_nav_v0.parallel_env(**cfg)
    assert env.core.backend == "numpy"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        swarm_nav_v0.parallel_env(**cfg)  # once


def test_the_suite_draws_every_field_of_the_env_config():
    drawn = field_strategies()
    names = {f.name for f in dataclasses.fields(SwarmConfig)}
    assert set(drawn) | set(NOT_DRAWN) == names
    assert set(drawn["reward"]) == set(RewardWeights.shipped_terms())
    assert set(drawn["physics"]) == {f.name for f in dataclasses.fields(SocialPotentialParams)}
    assert set(drawn["perturbations"]) == {f.name for f in dataclasses.fields(Perturbations)}


def test_reward_terms_and_weights_are_the_same_list():
    assert [t.name for t in REWARD_TERMS] == list(RewardWeights.shipped_terms())


# --------------------------------------------------------------------------- the suite bites

BROKEN_CONFIG = SwarmConfig(n_agents=12, n_neighbors=4, collision_radius=0.6, goal_radius=3.0)


def test_a_perturbed_reward_term_in_one_backend_is_caught(monkeypatch):
    # The torch core's execution of the reward with the collision term doubled.
    from swarm_envs.envs.cores.torch import step as torch_step
    from swarm_envs.envs.task import reward as shared_reward

    def broken(weights, inputs):
        heavier = dataclasses.replace(weights, collision=2 * weights.collision)
        return shared_reward(heavier, inputs)

    monkeypatch.setattr(torch_step, "reward", broken)
    problems = check(Variant("torch", np.float64), BROKEN_CONFIG)
    assert problems and "reward" in problems[0]


def test_a_perturbed_observation_scale_in_one_backend_is_caught(monkeypatch):
    # The C step given the wrong velocity scale (as a hand-kept contract could).
    from swarm_envs.envs.cores.native import core as native_core

    if backends.unsupported(BROKEN_CONFIG, "native"):
        pytest.skip("C step unavailable")
    right = native_core.step_params

    def wrong(cfg, dtype):
        return right(dataclasses.replace(cfg, obs_velocity_scale=2 * cfg.obs_velocity_scale), dtype)

    monkeypatch.setattr(native_core, "step_params", wrong)
    problems = check(Variant("native", np.float64), BROKEN_CONFIG)
    assert problems and all("velocity" in p for p in problems)


def test_a_perturbed_numpy_term_is_caught(monkeypatch):
    # The float32 numpy core (the reference's code in another dtype) with its time
    # penalty doubled: the numpy family is held to the reference too.
    from swarm_envs.envs.task import RewardInputs
    from swarm_envs.envs.task import layer as task_layer  # the host cores' reward
    from swarm_envs.envs.task import reward as shared_reward

    def broken(weights, inputs: RewardInputs):
        if inputs.stats["success"].dtype == np.float64 and inputs.effort.dtype == np.float32:
            weights = dataclasses.replace(weights, time=2 * weights.time)
        return shared_reward(weights, inputs)

    monkeypatch.setattr(task_layer, "reward", broken)
    problems = check(Variant("numpy", np.float32), BROKEN_CONFIG)
    assert problems and "reward" in problems[0]


def test_frozen_agents_that_move_in_one_backend_are_caught(monkeypatch):
    # The float32 numpy core integrating the frozen agents too (its mobile mask ignored).
    from swarm_envs.envs import dynamics

    right = dynamics.SocialPotentialDynamics._mobile_force

    def broken(self, f, rows):
        return f if f.dtype == np.float32 else right(self, f, rows)

    monkeypatch.setattr(dynamics.SocialPotentialDynamics, "_mobile_force", broken)
    assert check(Variant("numpy", np.float64), PERTURBED_CONFIGS[1]) == []
    problems = check(Variant("numpy", np.float32), PERTURBED_CONFIGS[1])
    assert problems and not problems[0].startswith("refused")


@pytest.mark.parametrize("column", ["energy", "collisions"])
def test_a_perturbed_term_in_the_c_step_is_caught(monkeypatch, tmp_path, column):
    # The C step built with one output column deliberately off (a -D flag the kernel
    # honours for this test only): the statistic, and for collisions the reward too.
    from swarm_envs.envs.cores.native import build

    if not build.native_support()[0]:
        pytest.skip("C step unavailable")
    monkeypatch.setenv("SWARM_ENVS_CACHE", str(tmp_path))
    monkeypatch.setenv("CFLAGS", f"-DSWARM_ENVS_PERTURB_COLUMN=PK_{column}")
    problems = check(Variant("native", np.float64), BROKEN_CONFIG)
    assert problems and f"statistic {column}" in problems[0]


def test_compare_names_the_reference_state_it_could_not_decide():
    # Two agents exactly at the collision radius: the comparison stops there, clean.
    cfg = SwarmConfig(n_agents=2, collision_radius=1.0, n_neighbors=1)
    ref, ours = SwarmNavCore(cfg, batch=3), SwarmNavCore(cfg, batch=3, dtype=np.float32)
    assert compare(ours, ref, seed=0, tol=dict(rtol=1e-3, atol=1e-3), margin=1e-4) == []


def test_a_new_reward_term_is_one_definition_on_every_backend(monkeypatch):
    # docs/design.md's worked example, done at run time: a term in REWARD_TERMS and a
    # weight beside the others reach every backend, the C step's included.
    import importlib

    from swarm_envs.envs.task import RewardTerm

    reward_module = importlib.import_module("swarm_envs.envs.task.reward")

    spread = RewardTerm("spread", -1.0, "expanse", lambda r: r.stats["expanse"])
    monkeypatch.setattr(reward_module, "REWARD_TERMS", (*REWARD_TERMS, spread))

    @dataclasses.dataclass(frozen=True)
    class WithSpread(RewardWeights):
        spread: float = 0.0

    base = SwarmConfig(n_agents=6, max_steps=50, reward=WithSpread())
    cfg = dataclasses.replace(base, reward=WithSpread(spread=0.5))
    actions = np.random.default_rng(1).uniform(-1, 1, (3, 6, 2))
    for backend in ("numpy", "cutoff", "torch", "native"):
        if backends.unsupported(base, backend):
            continue
        rewards = []
        for c in (base, cfg):
            core = Variant(backend, np.float64).make(c)
            core.reset(np.random.default_rng(0))
            rewards.append(core.step(actions)[0])
            expanse = core.stats()["expanse"]
        np.testing.assert_allclose(rewards[1], rewards[0] - 0.5 * expanse, rtol=1e-12)
