"""Self-propulsion (docs/models.md §1.7): the Rayleigh term ``(α − β|v|²) v`` in place of
the linear friction, its fixed speed, its energy balance, its step-size rate, and every
backend that runs it (numpy, torch, cut-off and the C step) against the numpy core."""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest
from helpers import CORE_TOL, assert_same_status_rollout, status_perturbations, status_rollout

from swarm_envs.config import SwarmConfig, load_swarm_config
from swarm_envs.envs.backends import unsupported
from swarm_envs.envs.cores.native import native_support
from swarm_envs.envs.cores.numpy import SwarmNavCore
from swarm_envs.physics import SocialPotentialParams, energy, forces, pair_geometry, simulate
from swarm_envs.physics.integrators import STEP_SAFETY, euler_update, stable_substep
from swarm_envs.physics.social_potential import (
    dissipation,
    dissipation_rate,
    goal_terms,
    pair_rates,
    pair_terms,
)

#: The navigation set with self-propulsion: v₀ = √(α/β) = 2.
ACTIVE = dataclasses.replace(SocialPotentialParams.navigation(), alpha=1.0, beta=0.25)


def _speed2(v: np.ndarray) -> np.ndarray:
    return (v * v).sum(axis=-1)


# --------------------------------------------------------------------------- parameters


def test_alpha_is_validated_and_names_its_field():
    assert SocialPotentialParams().alpha == 0.0
    with pytest.raises(ValueError, match=r"SocialPotentialParams\.alpha"):
        SocialPotentialParams(alpha=-0.5)
    with pytest.raises(ValueError, match=r"SocialPotentialParams\.alpha"):
        SocialPotentialParams(alpha=math.nan)
    with pytest.raises(ValueError, match=r"SocialPotentialParams\.beta .*alpha > 0"):
        SocialPotentialParams(alpha=1.0, beta=0.0)
    assert ACTIVE.cruise_speed == 2.0
    assert SocialPotentialParams().cruise_speed == 0.0


def test_physics_alpha_reaches_the_config_from_kwargs_and_yaml(tmp_path):
    cfg = load_swarm_config("paper_navigation", {"physics": {"alpha": 0.5}})
    assert cfg.physics.alpha == 0.5
    assert cfg.physics.beta == SocialPotentialParams.navigation().beta
    path = tmp_path / "active.yaml"
    path.write_text("n_agents: 5\nphysics:\n  alpha: 2.0\n  beta: 0.5\n")
    assert load_swarm_config(path).physics.cruise_speed == 2.0
    with pytest.raises(ValueError, match="alpha"):
        load_swarm_config(path, {"physics": {"alpha": -1.0}})


# --------------------------------------------------------------------------- the law


def test_without_self_propulsion_the_force_is_the_linear_friction_bit_for_bit():
    rng = np.random.default_rng(0)
    x, v, goal = rng.normal(size=(3, 7, 2)), rng.normal(size=(3, 7, 2)), rng.normal(size=2)
    p = SocialPotentialParams.navigation()
    fs, _ = pair_terms(pair_geometry(x), v, p, energy=False)
    sink = goal_terms(x, p, goal)[0]
    ref = np.stack([fc - p.beta * v[..., k] + sink[k] for k, fc in enumerate(fs)], axis=-1)
    assert np.array_equal(forces(x, v, p, goal), ref)
    assert dissipation_rate(None, p) == p.beta


def test_without_self_propulsion_a_rollout_is_the_friction_rollout_bit_for_bit():
    """``simulate`` against semi-implicit Euler written out with ``−β v``."""
    rng = np.random.default_rng(1)
    x0, v0, goal = rng.normal(size=(6, 2)), rng.normal(size=(6, 2)), np.array([3.0, -1.0])
    p = SocialPotentialParams.navigation()
    xs, vs = simulate(p, x0, v0, dt=0.02, steps=40, goal=goal)
    x, v = x0, v0
    for n in range(40):
        fs, _ = pair_terms(pair_geometry(x), v, p, energy=False)
        fs = [fc - p.beta * v[..., k] for k, fc in enumerate(fs)]
        sink = goal_terms(x, p, goal)[0]
        f = np.stack([fc + gc for fc, gc in zip(fs, sink, strict=True)], axis=-1)
        x, v = euler_update(x, v, f, 0.02, p.m)
        assert np.array_equal(xs[n + 1], x) and np.array_equal(vs[n + 1], v)


def test_the_rayleigh_term_vanishes_at_the_cruise_speed():
    v = np.array([[2.0, 0.0], [0.0, -2.0], [math.sqrt(2.0), math.sqrt(2.0)]])
    f = np.stack(dissipation([np.zeros(3), np.zeros(3)], [v[:, 0], v[:, 1]], ACTIVE), -1)
    np.testing.assert_allclose(f, 0.0, atol=1e-15)
    slow = np.stack(dissipation([np.zeros(1)] * 2, [np.array([1.0]), np.zeros(1)], ACTIVE), -1)
    assert slow[0, 0] == pytest.approx(1.0 - 0.25)  # (α − β|v|²)|v|: pushed forward


@pytest.mark.parametrize("s0", [0.1, 0.5, 5.0])
def test_a_free_agent_speed_tends_to_v0_along_the_logistic_law(s0):
    """A lone agent: ``ds/dt = (α − β s²) s/m``, so ``s² = v₀² / (1 + (v₀²/s₀² − 1)
    e^{−2αt/m})``; its heading is kept. From below and from above."""
    p = dataclasses.replace(ACTIVE, C_g=0.0)
    heading = np.array([0.6, -0.8])
    dt, steps = 1e-3, 8000
    _, vs = simulate(p, np.zeros((1, 2)), s0 * heading[None], dt=dt, steps=steps)
    t = dt * np.arange(steps + 1)
    v0 = p.cruise_speed
    exact = v0 / np.sqrt(1.0 + (v0**2 / s0**2 - 1.0) * np.exp(-2.0 * p.alpha * t / p.m))
    speed = np.sqrt(_speed2(vs[:, 0]))
    np.testing.assert_allclose(speed, exact, rtol=5e-3)
    assert abs(speed[-1] - v0) < 1e-3 * v0
    np.testing.assert_allclose(vs[-1, 0] / speed[-1], heading, atol=1e-12)


def test_a_swarm_without_a_sink_cruises_near_v0():
    """Interacting agents, no goal: the mean speed ends near v₀ (the pair forces and
    the alignment perturb the individual speeds)."""
    rng = np.random.default_rng(2)
    p = dataclasses.replace(ACTIVE, C_g=0.0)
    _, vs = simulate(p, rng.normal(size=(8, 2)), 0.1 * rng.normal(size=(8, 2)), dt=0.01, steps=3000)
    assert abs(np.sqrt(_speed2(vs[-1])).mean() - p.cruise_speed) < 0.1 * p.cruise_speed


def _power(x: np.ndarray, v: np.ndarray, p: SocialPotentialParams) -> np.ndarray:
    """``dφ/dt = Σ_i (α − β|v_i|²)|v_i|² − ½ Σ_{i≠j} C_o (v_ij·u_ij)² e^{−ρ_ij/l_o}``."""
    s2 = _speed2(v)
    active = ((p.alpha - p.beta * s2) * s2).sum(axis=-1)
    r = x[..., None, :, :] - x[..., :, None, :]
    rho = np.sqrt((r * r).sum(-1))
    u = r / np.where(rho > 0, rho, 1.0)[..., None]
    vij = v[..., :, None, :] - v[..., None, :, :]
    proj = (vij * u).sum(-1)
    align = 0.5 * p.C_o * (proj**2 * np.exp(-rho / p.l_o)).sum(axis=(-2, -1))
    return active - align


@pytest.mark.parametrize("goal", [None, np.array([2.0, 1.0])])
def test_energy_balance_with_self_propulsion(goal):
    """φ(T) − φ(0) = ∫ dφ/dt over a short rollout with a small step (trapezoid rule):
    the active term supplies energy, the alignment and the Rayleigh brake take it."""
    rng = np.random.default_rng(3)
    p = ACTIVE if goal is not None else dataclasses.replace(ACTIVE, C_g=0.0)
    x0, v0 = rng.normal(size=(6, 2)), 1.5 * rng.normal(size=(6, 2))
    dt, steps = 2e-5, 20_000
    xs, vs = simulate(p, x0, v0, dt=dt, steps=steps, goal=goal)
    phi = energy(xs, vs, p, goal)
    power = _power(xs, vs, p)
    integral = dt * (power[1:] + power[:-1]).sum() / 2.0
    change = phi[-1] - phi[0]
    assert abs(power).max() * dt * steps > 0.1  # the balance is not trivially small
    assert change == pytest.approx(integral, rel=2e-3, abs=2e-3)


@pytest.mark.parametrize("dim", [2, 3])
def test_angular_momentum_about_the_goal_follows_the_discrete_friction_law(dim):
    """Without self-propulsion, semi-implicit Euler with the sink on: the angular
    momentum about the goal is ``L_n = L_0 (1 − β dt/m)^n`` to round-off (the pair and
    sink torques cancel, ``r_{n+1} × v_{n+1} = r_n × v_{n+1}``)."""
    rng = np.random.default_rng(8)
    p = dataclasses.replace(SocialPotentialParams.navigation(), m=1.5)
    goal = rng.normal(size=dim)
    x0, v0 = rng.normal(size=(9, dim)), rng.normal(size=(9, dim))
    dt, steps = 0.01, 300
    xs, vs = simulate(p, x0, v0, dt=dt, steps=steps, goal=goal)
    r = xs - goal
    if dim == 2:
        L = (r[..., 0] * vs[..., 1] - r[..., 1] * vs[..., 0]).sum(-1)[:, None]
    else:
        L = np.cross(r, vs).sum(-2)
    law = L[0] * (1.0 - p.beta * dt / p.m) ** np.arange(steps + 1)[:, None]
    np.testing.assert_allclose(L, law, rtol=1e-9, atol=1e-12 * np.abs(L[0]).max())


# --------------------------------------------------------------------------- step size


def test_the_damping_rate_includes_the_rayleigh_jacobian():
    """γ of ``pair_rates`` bounds the largest eigenvalue of the velocity Jacobian of
    the passive force (Rayleigh term and alignment), by finite differences."""
    rng = np.random.default_rng(4)
    x, v = rng.normal(size=(5, 2)), 3.0 * rng.normal(size=(5, 2))
    p = ACTIVE
    n = v.size
    jac = np.empty((n, n))
    eps = 1e-6
    for k in range(n):
        dv = np.zeros(n)
        dv[k] = eps
        up = forces(x, v + dv.reshape(v.shape), p).ravel()
        down = forces(x, v - dv.reshape(v.shape), p).ravel()
        jac[:, k] = -(up - down) / (2 * eps)
    top = np.linalg.eigvals(jac).real.max() / p.m
    _, gamma = pair_rates(pair_geometry(x), p, v=v)
    assert top <= gamma * (1 + 1e-6)
    fastest = (3.0 * p.beta * _speed2(v).max() - p.alpha) / p.m
    assert gamma >= fastest
    with pytest.raises(ValueError, match="velocities"):
        pair_rates(pair_geometry(x), p)


def test_a_fast_agent_takes_a_substep_below_its_stability_edge():
    """A lone agent at 10 v₀: along its velocity one semi-implicit Euler step maps a
    speed perturbation by ``1 − h (3β s² − α)/m``; ``h*`` keeps it inside (−1, 1) and
    the edge ``h*/σ`` is where it reaches −1."""
    p = dataclasses.replace(ACTIVE, C_g=0.0)
    v = np.array([[[20.0, 0.0]]])
    omega2, gamma = pair_rates(pair_geometry(np.zeros((1, 1, 2))), p, v=v)
    assert gamma[0] == pytest.approx((3 * 0.25 * 400 - 1.0) / p.m)
    h = float(stable_substep(omega2, gamma)[0])
    factor = 1.0 - h * gamma[0]
    assert -1.0 < factor < 1.0
    assert 1.0 - (h / STEP_SAFETY) * gamma[0] == pytest.approx(-1.0)
    # the nonlinear run at h* settles at v₀
    _, vs = simulate(p, np.zeros((1, 2)), v[0], dt=h, steps=4000)
    err = np.abs(np.sqrt(_speed2(vs[:, 0])) - p.cruise_speed)
    assert err[-1] < 1e-6 and np.all(np.isfinite(vs))
    # at cruise the rate is 2α/m: a step past its edge leaves v₀ unstable (the speed
    # error grows into an oscillation), a step at h* settles
    cruise = np.array([[p.cruise_speed * 1.01, 0.0]])
    omega2, gamma = pair_rates(pair_geometry(np.zeros((1, 1, 2))), p, v=cruise[None])
    assert gamma[0] == pytest.approx(2.0 * p.alpha / p.m, rel=0.05)
    edge = float(stable_substep(omega2, gamma)[0]) / STEP_SAFETY
    for dt, settles in ((STEP_SAFETY * edge, True), (1.1 * edge, False)):
        _, vs = simulate(p, np.zeros((1, 2)), cruise, dt=dt, steps=300)
        err = np.abs(np.sqrt(_speed2(vs[-10:, 0])) - p.cruise_speed).max()
        assert (err < 1e-6) == settles, (dt, err)


def test_negative_damping_rates_give_a_sound_substep():
    """Every agent slower than v₀/√3: γ < 0 (energy injection). Without stiffness any
    step is stable (``inf``, one substep); with stiffness ``h*`` is finite and
    positive."""
    assert stable_substep(np.float64(0.0), np.float64(-0.5)) == math.inf
    h = stable_substep(np.float64(4.0), np.float64(-0.5))
    assert 0 < h < math.inf
    p = dataclasses.replace(ACTIVE, C_g=0.0)
    gamma = pair_rates(pair_geometry(np.zeros((1, 1, 2))), p, v=np.zeros((1, 1, 2)))[1]
    assert gamma[0] == -p.alpha / p.m


def test_the_numpy_core_steps_a_fast_self_propelled_swarm_to_cruise():
    """Starts up to 7.5 v₀: the first steps need several substeps (the Rayleigh rate
    ``3β s²``), and the speeds relax toward v₀ without an unstable step."""
    cfg = load_swarm_config(
        "paper_navigation",
        {"n_agents": 10, "init_speed": 15.0, "physics": {"alpha": 1.0, "beta": 0.25}},
    )
    core = SwarmNavCore(cfg, batch=2)
    core.reset(np.random.default_rng(5))
    assert np.sqrt(_speed2(core.v)).max() > 10.0
    *_, stats = core.step(np.zeros((2, 10, 2)))
    assert stats["substeps"].max() > 1
    for _ in range(200):
        *_, stats = core.step(np.zeros((2, 10, 2)))
    assert np.all(np.isfinite(core.v)) and not stats["unstable"].any()
    assert np.sqrt(_speed2(core.v)).max() < 5.0


# --------------------------------------------------------------------------- backends


def _rollout(core, steps: int = 25) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    core.reset(np.random.default_rng(6))
    rng = np.random.default_rng(7)
    energies = []
    for _ in range(steps):
        *_, stats = core.step(rng.uniform(-1, 1, core.x.shape))
        energies.append(np.asarray(stats["energy"]))
    return np.asarray(core.x), np.asarray(core.v), np.array(energies)


ACTIVE_OFF = dataclasses.replace(ACTIVE, alpha=0.0)


def _active_config(**kw) -> SwarmConfig:
    return SwarmConfig(**{"n_agents": 12, "physics": ACTIVE, **kw})


def test_the_torch_core_matches_the_numpy_core():
    pytest.importorskip("torch")
    from swarm_envs.envs.cores.torch.core import TorchSwarmNavCore

    cfg = _active_config()
    assert TorchSwarmNavCore.unsupported(cfg) is None
    ref = _rollout(SwarmNavCore(cfg, batch=3))
    ours = _rollout(TorchSwarmNavCore(cfg, batch=3, dtype=np.float64, compile=False))
    for a, b in zip(ours, ref, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("integrator", ["semi_implicit_euler", "velocity_verlet"])
def test_the_cutoff_core_matches_the_numpy_core(integrator):
    from swarm_envs.envs.cores.cutoff.core import CutoffSwarmNavCore

    cfg = _active_config(integrator=integrator)
    assert CutoffSwarmNavCore.unsupported(cfg) is None
    ref = _rollout(SwarmNavCore(cfg, batch=2))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ours = _rollout(CutoffSwarmNavCore(cfg, batch=2, cutoff_tol=1e-12))
    for a, b in zip(ours, ref, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-7, atol=1e-7)


#: Self-propelled configs for the C step: a fast start (the Rayleigh rate ``3β|v|²``
#: asks for several substeps), a lone slow agent without stiffness (a negative rate:
#: ``h* = inf``, one substep) and 3-D with the passive sink and without alignment.
C_CONFIGS = {
    "fast": SwarmConfig(n_agents=12, dt=0.3, init_speed=6.0, physics=ACTIVE),
    "lone-slow": SwarmConfig(
        n_agents=1, dt=0.5, init_speed=0.2, physics=dataclasses.replace(ACTIVE, C_g=0.0)
    ),
    "3d-sink": SwarmConfig(
        n_agents=9,
        dim=3,
        dt=0.3,
        init_speed=5.0,
        goal_in_physics=True,
        physics=dataclasses.replace(ACTIVE, C_o=0.0),
    ),
}


NATIVE, WHY_NOT = native_support()
needs_native = pytest.mark.skipif(not NATIVE, reason=f"C step unavailable: {WHY_NOT}")


@needs_native
@pytest.mark.parametrize("dtype", [np.float64, np.float32], ids=["f64", "f32"])
@pytest.mark.parametrize(
    ("name", "arch"),
    [(name, None) for name in C_CONFIGS] + [("fast", "x86-64-v3"), ("3d-sink", "x86-64-v3")],
    ids=lambda v: v or "native",
)
def test_the_c_step_matches_the_numpy_core(monkeypatch, name, arch, dtype):
    """Step by step against the numpy core in the same dtype: the substep counts (from
    the carried ``h*`` with the Rayleigh rate) exactly, ``h*``, the state, the
    observations, the statistics and the rewards to round-off (float32: to 2e-4); also
    in the portable build (no AVX-512 branches)."""
    from swarm_envs.envs.cores.native import NativeSwarmNavCore, build

    if arch is not None:
        monkeypatch.setenv(build.ARCH_ENV, arch)
    cfg = C_CONFIGS[name]
    assert unsupported(cfg, "native") is None
    B, N, d = 4, cfg.n_agents, cfg.dim
    core, ref = NativeSwarmNavCore(cfg, B, dtype), SwarmNavCore(cfg, B, dtype)
    core.reset(np.random.default_rng(0))
    ref.reset(np.random.default_rng(0))
    tol = CORE_TOL[dtype]
    h_rtol = 1e-12 if dtype == np.float64 else 1e-4
    counts, hs = [], [core._h.copy()]
    for a in np.random.default_rng(1).uniform(-1, 1, (10, B, N, d)).astype(dtype):
        got, want = core.step(a), ref.step(a)
        np.testing.assert_array_equal(got[3]["substeps"], want[3]["substeps"])
        np.testing.assert_array_equal(got[3]["unstable"], want[3]["unstable"])
        np.testing.assert_array_equal(got[1], want[1])
        np.testing.assert_array_equal(got[2], want[2])
        np.testing.assert_allclose(got[0], want[0], **tol, err_msg="reward")
        for key, value in got[3].items():
            np.testing.assert_allclose(value, want[3][key], **tol, err_msg=key)
        np.testing.assert_allclose(core.x, ref.x, **tol, err_msg="x")
        np.testing.assert_allclose(core.v, ref.v, **tol, err_msg="v")
        np.testing.assert_allclose(core.observe(), ref.observe(), **tol, err_msg="observations")
        np.testing.assert_allclose(core._h, ref.dynamics._h_stable, rtol=h_rtol)
        counts.append(got[3]["substeps"])
        hs.append(core._h.copy())
    assert np.array(counts).min() >= 1
    if name == "lone-slow":  # slower than v₀/√3 and nothing stiff: any step is stable
        assert np.isinf(hs).any() and np.isfinite(hs).any()
    else:
        assert np.max(counts) > 1


@needs_native
@pytest.mark.parametrize("dtype", [np.float64, np.float32], ids=["f64", "f32"])
@pytest.mark.parametrize("kind", ["removed", "frozen", "passive", "joining"])
def test_the_c_step_with_statuses_matches_the_numpy_core(kind, dtype):
    """Failed, frozen, removed and joining agents in a fast self-propelled swarm, with
    observed statuses: the C step against the numpy core in float64 (float64 to
    round-off, float32 to 2e-3), every statistic (substeps included) and observation."""
    from swarm_envs.envs.backends import make_core

    perturbations, statuses = status_perturbations()[kind]
    cfg = SwarmConfig(
        n_agents=10,
        n_neighbors=6,
        max_steps=6,
        dt=0.2,
        init_speed=4.0,
        collision_radius=0.6,
        observe_status=True,
        perturbations=perturbations,
        physics=ACTIVE,
    )
    runs = []
    for backend, dt in (("native", dtype), ("numpy", np.float64)):
        core = make_core(dataclasses.replace(cfg, backend=backend), 3, dt)
        assert core.backend == backend
        runs.append(status_rollout(core, cfg.n_agents, cfg.dim, 14, dt))
    (got, seen), (want, ref_seen) = runs
    assert seen == ref_seen and statuses <= seen
    assert max(stats["substeps"].max() for _, _, stats in want) > 1
    tol = dict(rtol=1e-9, atol=1e-9) if dtype == np.float64 else dict(rtol=2e-3, atol=2e-3)
    assert_same_status_rollout(got, want, tol)


def test_the_env_takes_physics_alpha_on_every_backend_it_runs_on():
    from swarm_envs import swarm_nav_v0
    from swarm_envs.envs import backends

    native = NATIVE and backends.unsupported(SwarmConfig(), "native") is None
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no fallback warning: the C step runs it
        env = swarm_nav_v0.parallel_env(
            n_agents=5,
            backend="native" if native else "numpy",
            physics={"alpha": 1.0, "beta": 0.25},
        )
    assert env.core.backend == ("native" if native else "numpy")
    assert env.core.cfg.physics.cruise_speed == 2.0
    obs, _ = env.reset(seed=0)
    actions = {agent: np.zeros(2, np.float32) for agent in env.agents}
    obs, *_ = env.step(actions)
    assert all(np.isfinite(o).all() for o in obs.values())


@pytest.mark.parametrize("name", ["fast", "lone-slow"])
def test_the_cutoff_core_plans_verlet_substeps_at_the_state_velocities(name):
    # With self-propulsion the damping rate depends on the velocities: the stable
    # substep of the state after a Verlet step is the one at its velocities, as the
    # dense core has it, not at the force pass's extrapolated ones.
    from swarm_envs.envs.cores.cutoff.core import CutoffSwarmNavCore

    cfg = dataclasses.replace(C_CONFIGS[name], integrator="velocity_verlet", max_steps=50)
    cores = [SwarmNavCore(cfg, batch=3)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cores.append(CutoffSwarmNavCore(cfg, batch=3, cutoff_tol=1e-12))
    for core in cores:
        core.reset(np.random.default_rng(4))
    actions = np.random.default_rng(5)
    for _ in range(12):
        a = actions.uniform(-1, 1, (3, cfg.n_agents, cfg.dim))
        ref, ours = (core.step(a)[3] for core in cores)
        np.testing.assert_array_equal(ours["substeps"], ref["substeps"])
        np.testing.assert_allclose(cores[1].v, cores[0].v, rtol=1e-7, atol=1e-7)
