"""Step-size control (docs/models.md §7): the rule, its bounds, and never-silent steps."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from swarm_envs.config import SwarmConfig
from swarm_envs.envs.backends import make_core
from swarm_envs.envs.common import SwarmUnstableError
from swarm_envs.envs.cores.numpy import SwarmNavCore
from swarm_envs.envs.step_control import check_step_control, start_substeps
from swarm_envs.physics import SocialPotentialParams, pair_geometry, simulate
from swarm_envs.physics.integrators import STEP_SAFETY, stable_substep, substep_plan
from swarm_envs.physics.social_potential import pair_rates

PASSIVE = dataclasses.replace(SocialPotentialParams.navigation(), C_g=0.0)


def _spectral_radius(h: float, omega2: float, gamma: float) -> float:
    """Of one semi-implicit Euler step on q̈ = −ω² q − γ q̇."""
    step = np.array([[1.0 - h * h * omega2, h * (1.0 - h * gamma)], [-h * omega2, 1.0 - h * gamma]])
    return float(np.abs(np.linalg.eigvals(step)).max())


@pytest.mark.parametrize(
    ("omega2", "gamma"), [(100.0, 0.0), (0.0, 4.0), (400.0, 3.0), (25.0, 60.0), (1e4, 1e3)]
)
def test_stable_substep_is_the_stability_edge_of_semi_implicit_euler(omega2, gamma):
    edge = float(stable_substep(np.float64(omega2), np.float64(gamma))) / STEP_SAFETY
    assert _spectral_radius(0.999 * edge, omega2, gamma) <= 1.0 + 1e-12
    assert _spectral_radius(1.001 * edge, omega2, gamma) > 1.0
    inside = _spectral_radius(STEP_SAFETY * edge, omega2, gamma)
    assert inside < 1.0 if omega2 > 0 and gamma > 0 else inside <= 1.0 + 1e-12


def test_substep_plan_splits_the_time_left_evenly():
    n, h = substep_plan(np.array([0.1, 0.1, 0.1, 0.0]), np.array([0.1, 0.0333, np.inf, 1.0]))
    assert n.tolist() == [1.0, 4.0, 1.0, 0.0]
    np.testing.assert_allclose(h, [0.1, 0.025, 0.1, 0.0])
    n, h = substep_plan(np.array([0.1]), np.array([0.0]))  # no stable step exists
    assert n[0] == np.inf and h[0] == 0.0


def _hessian_and_damping(x: np.ndarray, p: SocialPotentialParams) -> tuple[np.ndarray, np.ndarray]:
    """The Hessian of the Morse pair potential and the alignment's damping matrix
    (per unit mass, without β) of positions ``x`` (N, d), built pair by pair."""
    n, d = x.shape
    K, D = np.zeros((n * d, n * d)), np.zeros((n * d, n * d))
    for i in range(n):
        for j in range(i + 1, n):
            r = x[j] - x[i]
            rho = np.linalg.norm(r)
            u = r / rho
            d1 = -p.C_r / p.l_r * np.exp(-rho / p.l_r) + p.C_a / p.l_a * np.exp(-rho / p.l_a)
            d2 = p.C_r / p.l_r**2 * np.exp(-rho / p.l_r) - p.C_a / p.l_a**2 * np.exp(-rho / p.l_a)
            block = d2 * np.outer(u, u) + d1 / rho * (np.eye(d) - np.outer(u, u))
            damp = p.C_o * np.exp(-rho / p.l_o) * np.outer(u, u)
            for M, b in ((K, block), (D, damp)):
                si, sj = slice(i * d, i * d + d), slice(j * d, j * d + d)
                M[si, si] += b
                M[sj, sj] += b
                M[si, sj] -= b
                M[sj, si] -= b
    return K / p.m, D / p.m


@pytest.mark.parametrize(("n_agents", "dim"), [(12, 2), (31, 2), (20, 3)])
def test_gershgorin_rates_bound_the_largest_eigenvalues(n_agents, dim):
    """On states the env visits (relaxing swarms of the navigation set), ω² and γ of
    ``pair_rates`` bound the largest eigenvalues of the Hessian and of the damping."""
    cfg = SwarmConfig(n_agents=n_agents, dim=dim, physics=PASSIVE, backend="numpy")
    core = SwarmNavCore(cfg, batch=1)
    core.reset(np.random.default_rng(3))
    for t in range(60):
        core.step(np.zeros((1, n_agents, dim)))
        if t % 20 == 0:
            x = core.x[0]
            K, D = _hessian_and_damping(x, PASSIVE)
            omega2, gamma = pair_rates(pair_geometry(x[None]), PASSIVE)
            top_k, top_d = np.linalg.eigvalsh(K).max(), np.linalg.eigvalsh(D).max()
            assert top_k <= omega2[0] * (1 + 1e-12)
            assert PASSIVE.beta / PASSIVE.m + top_d <= gamma[0] * (1 + 1e-12)
            assert top_k >= omega2[0] / 8  # a bound, not a blanket: within the Gershgorin slack


def _passive_energies(cfg: SwarmConfig, steps: int) -> tuple[np.ndarray, np.ndarray]:
    core = SwarmNavCore(cfg, batch=2)
    core.reset(np.random.default_rng(1))
    energies, substeps = [core.stats()["energy"]], []
    for _ in range(steps):
        *_, stats = core.step(np.zeros((2, cfg.n_agents, cfg.dim)))
        energies.append(stats["energy"])
        substeps.append(stats["substeps"])
    return np.array(energies), np.array(substeps)


@pytest.mark.parametrize(("n_agents", "dim"), [(57, 2), (150, 2), (80, 3)])
def test_passive_energy_never_rises_at_sizes_a_fixed_step_cannot_take(n_agents, dim):
    """Without control the energy is a Lyapunov function (docs/models.md §1.1). With
    step-size control it falls on every step; a fixed step of the same ``dt`` (the
    physics' ``simulate``) makes it rise."""
    cfg = SwarmConfig(n_agents=n_agents, dim=dim, physics=PASSIVE, backend="numpy")
    energies, substeps = _passive_energies(cfg, 150)
    assert np.all(np.diff(energies, axis=0) <= 0)
    assert substeps.max() > 1
    core = SwarmNavCore(cfg, batch=1)
    core.reset(np.random.default_rng(1))
    xs, vs = simulate(PASSIVE, core.x[0], core.v[0], dt=cfg.dt, steps=150)
    from swarm_envs.physics import energy

    fixed = energy(xs, vs, PASSIVE)
    assert np.diff(fixed).max() > 0


def test_substeps_follow_a_brute_force_small_step_reference():
    """100 agents at dt = 0.1 (about 7 substeps a step, re-planned) against a fixed
    step 50 times smaller, the same held actions: the energy and the expanse agree
    within a few per cent after 3 time units, while the fixed step of 0.1 is far off."""
    cfg = SwarmConfig(n_agents=100, physics=PASSIVE, backend="numpy")
    core = SwarmNavCore(cfg, batch=1)
    core.reset(np.random.default_rng(7))
    x0, v0 = core.x[0].copy(), core.v[0].copy()
    rng = np.random.default_rng(0)
    actions = rng.uniform(-0.3, 0.3, (30, 1, 100, 2))
    for a in actions:
        *_, stats = core.step(a)

    def held(t, x, v):
        return cfg.u_max * actions[min(int(t / cfg.dt + 1e-9), len(actions) - 1), 0]

    def final(dt: float) -> tuple[float, float]:
        steps = round(3.0 / dt)
        xs, vs = simulate(PASSIVE, x0, v0, dt=dt, steps=steps, control=held)
        from swarm_envs.physics import energy

        x = xs[-1]
        return float(energy(xs[-1], vs[-1], PASSIVE)), float(
            np.linalg.norm(x - x.mean(0), axis=-1).mean()
        )

    e_ref, r_ref = final(cfg.dt / 50)
    e_fixed, _ = final(cfg.dt)
    e, r = float(stats["energy"][0]), float(stats["expanse"][0])
    assert abs(e - e_ref) <= 0.03 * abs(e_ref)
    assert abs(r - r_ref) <= 0.03 * r_ref
    assert abs(e_fixed - e_ref) > 10 * abs(e - e_ref)


def test_an_unstable_step_raises_naming_the_cause_and_the_keys():
    cfg = SwarmConfig(n_agents=100, physics=PASSIVE, max_substeps=2, backend="numpy")
    core = SwarmNavCore(cfg, batch=2)
    core.reset(np.random.default_rng(0))
    with pytest.raises(SwarmUnstableError, match="more than max_substeps=2") as err:
        for _ in range(5):
            core.step(np.zeros((2, 100, 2)))
    for key in ("dt", "max_substeps", "on_unstable"):
        assert key in str(err.value)


def test_truncate_undoes_the_unstable_step_and_marks_it():
    cfg = SwarmConfig(
        n_agents=100, physics=PASSIVE, max_substeps=3, on_unstable="truncate", backend="numpy"
    )
    core = SwarmNavCore(cfg, batch=2)
    core.reset(np.random.default_rng(0))
    for _ in range(20):
        x_before = core.x.copy()
        reward, terminated, truncated, stats = core.step(np.zeros((2, 100, 2)))
        bad = stats["unstable"] == 1.0
        if bad.any():
            break
    assert bad.any()
    assert np.all(truncated[bad]) and not np.any(terminated[bad]) and np.all(reward[bad] == 0)
    np.testing.assert_array_equal(core.x[bad], x_before[bad])
    assert np.all(np.isfinite(core.observe()))


def test_predictably_unstable_configs_are_refused_when_built():
    assert start_substeps(SwarmConfig(n_agents=10)) == 1
    with pytest.raises(ValueError, match=r"predictably unstable.*max_substeps=1000"):
        make_core(SwarmConfig(n_agents=30_000))
    with pytest.raises(ValueError, match=r"predictably unstable.*max_substeps=100\b"):
        make_core(SwarmConfig(n_agents=3_000, max_substeps=100))
    with pytest.raises(ValueError, match="piecewise"):
        check_step_control(SwarmConfig(dynamics="piecewise", dt=2.0, max_substeps=1))
    check_step_control(SwarmConfig(n_agents=1000))  # dense, but an average start fits


def test_n_agents_one_needs_no_substeps_beyond_damping():
    cfg = SwarmConfig(n_agents=1, backend="numpy")
    core = SwarmNavCore(cfg, batch=1)
    core.reset(np.random.default_rng(0))
    *_, stats = core.step(np.ones((1, 1, 2)))
    assert stats["substeps"][0] == 1.0


# --------------------------------------------------------------------------- property


@st.composite
def _scale(draw, low: float, high: float) -> float:
    """Log-uniform on [10^low, 10^high]; one draw in 20 is 0, one in 20 huge."""
    special = draw(st.integers(0, 19))
    if special == 0:
        return 0.0
    if special == 1:
        return draw(st.sampled_from([1e12, 1e20]))
    return 10.0 ** draw(st.floats(low, high))


_LENGTHS = st.floats(-1.0, 1.0).map(lambda e: 10.0**e)


@st.composite
def _configs(draw) -> dict:
    physics = {
        "C_a": draw(_scale(-1, 1)),
        "C_r": draw(_scale(-1, 1)),
        "l_a": draw(_LENGTHS),
        "l_r": draw(_LENGTHS),
        "C_o": draw(_scale(-2, 1)),
        "l_o": draw(_LENGTHS),
        "beta": draw(_scale(-2, 1)),
        "C_g": draw(_scale(-1, 2)),
        "l_g": draw(_LENGTHS),
    }
    return {
        "n_agents": draw(st.integers(1, 24)),
        "dim": draw(st.sampled_from([2, 3])),
        "dt": draw(st.floats(-2.5, 0.5).map(lambda e: 10.0**e)),
        "integrator": draw(st.sampled_from(["semi_implicit_euler", "velocity_verlet"])),
        "max_substeps": draw(st.integers(1, 100)),
        "on_unstable": draw(st.sampled_from(["raise", "truncate"])),
        "goal_in_physics": draw(st.booleans()),
        "init_radius": draw(st.floats(0.0, 20.0)),
        "init_speed": draw(_scale(-2, 1)),
        "u_max": draw(st.floats(-2.0, 2.0).map(lambda e: 10.0**e)),
        "physics": physics,
        "backend": "numpy",
    }


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(_configs(), st.sampled_from([np.float32, np.float64]), st.integers(0, 2**32 - 1))
def test_no_valid_config_gives_a_non_finite_observation_or_reward(overrides, dtype, seed):
    """A valid config runs with finite observations and rewards, or is refused when
    built (ValueError), or a reset or step raises SwarmUnstableError: never NaN or inf."""
    from swarm_envs.config import config_from_mapping

    try:
        cfg = config_from_mapping(SwarmConfig, overrides)
        core = make_core(cfg, batch=2, dtype=dtype)
    except ValueError:
        return
    rng = np.random.default_rng(seed)
    try:
        core.reset(rng)  # a start that overflows the dtype raises too
        assert np.all(np.isfinite(core.observe()))
        for _ in range(25):
            a = rng.uniform(-1.0, 1.0, (2, cfg.n_agents, cfg.dim))
            reward, terminated, truncated, _ = core.step(a)
            assert np.all(np.isfinite(reward))
            assert np.all(np.isfinite(core.observe()))
            if (terminated | truncated).any():
                core.reset(rng, terminated | truncated)
                assert np.all(np.isfinite(core.observe()))
    except SwarmUnstableError:
        return
