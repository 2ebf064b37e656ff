"""The integrator with implicit damping and its step-size rule (docs/models.md §7).

``"implicit_damping_euler"``: the block bound of the Hessian
(:func:`~swarm_envs.physics.social_potential.stiffness_rate`) bounds its largest
eigenvalue; the damping alone never grows, at any step; a swarm driven as a whole
accelerates as the force says; the pair forces keep the momentum; the passive energy
falls with dissipation; the trajectories converge at order 1; the start's
needs are predicted by the same rule.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarm_envs.config import SwarmConfig
from swarm_envs.envs.cores.numpy import SwarmNavCore
from swarm_envs.envs.step_control import check_step_control, start_substeps
from swarm_envs.physics import SocialPotentialParams, pair_geometry, simulate
from swarm_envs.physics.integrators import implicit_damping_update, stable_substep
from swarm_envs.physics.social_potential import (
    block_bound,
    damping_rates,
    energy,
    forces,
    kinetic_energy,
    pair_rates,
    stiffness_law,
    stiffness_rate,
)

IMPLICIT = "implicit_damping_euler"

PARAMS = (
    SocialPotentialParams(),
    SocialPotentialParams.navigation(),
    SocialPotentialParams.large_swarm(),
    SocialPotentialParams(C_a=2.0, C_r=0.5, l_a=1.5, l_r=0.5),  # attraction near contact
)


def hessian(x: np.ndarray, p: SocialPotentialParams) -> np.ndarray:
    """The Hessian of ``Σ_{i<j} U(ρ_ij)`` at ``x`` ``(N, d)``, assembled pair by pair."""
    n, d = x.shape
    h = np.zeros((n * d, n * d))
    for i in range(n):
        for j in range(n):
            if i == j:
                continue
            r = x[j] - x[i]
            rho = float(np.linalg.norm(r))
            u = r / rho
            ea, er = math.exp(-rho / p.l_a), math.exp(-rho / p.l_r)
            u2 = p.C_r / p.l_r**2 * er - p.C_a / p.l_a**2 * ea
            u1 = (p.C_a / p.l_a * ea - p.C_r / p.l_r * er) / rho
            block = u2 * np.outer(u, u) + u1 * (np.eye(d) - np.outer(u, u))
            h[i * d : i * d + d, i * d : i * d + d] += block
            h[i * d : i * d + d, j * d : j * d + d] -= block
    return h


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("p", PARAMS, ids=lambda p: f"C_r={p.C_r},l_r={p.l_r}")
def test_the_block_bound_bounds_the_hessian_and_beats_gershgorin(p, dim):
    rng = np.random.default_rng(dim)
    for scale in (0.2, 1.0, 3.0):
        x = rng.normal(size=(12, dim)) * scale
        top = np.linalg.eigvalsh(hessian(x, p)).max() / p.m
        omega2 = float(stiffness_rate(pair_geometry(x), p))
        assert omega2 >= top - 1e-9 * max(1.0, abs(top))
        # in 2-D never above the Gershgorin sum of the same blocks' norms, 2 max_i Σ_j b_ij
        # (k = b + t, p = a − t: b = a where p ≥ 0, b = t where p < 0)
        rho = np.linalg.norm(x[:, None] - x[None], axis=-1)
        np.fill_diagonal(rho, np.inf)
        k, q = stiffness_law(rho, 1 / rho, p.C_a, p.C_r, p.l_a, p.l_r, np.exp, np.maximum)
        b = k - np.where(q < 0, k / 2, (k - q) / 2)
        if dim == 2:
            assert omega2 <= 2 * b.sum(-1).max() / p.m * (1 + 1e-12)
        # the bound never exceeds the plain Gershgorin sum of the old rule's stiffness
        # where the transverse stiffness stays below κ (every set here but the last)
        if p.C_r / p.l_r > p.C_a / p.l_a:
            assert omega2 <= float(pair_rates(pair_geometry(x), p)[0]) * (1 + 1e-12)


@pytest.mark.parametrize("dim", [2, 3])
def test_the_agents_own_block_bound_is_an_eigenvalue_bound_exact_in_2d(dim):
    rng = np.random.default_rng(0)
    for _ in range(50):
        a = rng.normal(size=(dim, dim))
        s = a + a.T
        q = [[s[i][j] for j in range(dim)] for i in range(dim)]
        bound = block_bound(0.0, q, dim, np)
        top = np.linalg.eigvalsh(s).max()
        assert bound >= top - 1e-12
        if dim == 2:
            assert bound == pytest.approx(top, abs=1e-12)


def _pure_damping(n: int, dim: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.normal(size=(n, dim)) * 0.5, rng.normal(size=(n, dim))


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("beta", [0.0, 0.5])
def test_the_damping_alone_never_grows_at_any_step(dim, beta):
    # No potential, strong alignment, steps far beyond every explicit limit (h C_o N up
    # to 10⁷). At a fixed state the velocity map of one step, v ↦ v + Δv(F(x, v)), has
    # no eigenvalue outside the unit disc; along a trajectory the kinetic energy stays
    # below its start. Semi-implicit Euler grows at once.
    p = SocialPotentialParams(C_a=0.0, C_r=0.0, C_o=1e3, l_o=1.5, beta=beta)
    x, v = _pure_damping(12, dim, seed=dim)
    geo = pair_geometry(x)
    own, align = damping_rates(geo, v, p)
    for h in (0.1, 10.0, 1e3):
        columns = []
        for k in range(x.size):
            e = np.zeros(x.size)
            e[k] = 1.0
            unit = e.reshape(x.shape)
            accel = forces(x, unit, p, geometry=geo)  # linear in v: −D v
            _, out = implicit_damping_update(
                x, unit, accel, h, p.m, own[..., None], align[..., None]
            )
            columns.append(out.ravel())
        radius = np.abs(np.linalg.eigvals(np.array(columns).T)).max()
        assert radius <= 1 + 1e-9, (h, radius)
        _, vs = simulate(p, x, v, dt=h, steps=30, integrator=IMPLICIT)
        kinetic = kinetic_energy(vs, p)
        assert np.all(np.isfinite(kinetic)) and kinetic.max() <= kinetic[0] * (1 + 1e-9)
    _, vs = simulate(p, x, v, dt=0.1, steps=30)
    assert kinetic_energy(vs, p)[-1] > kinetic_energy(vs, p)[0]


def test_a_swarm_driven_as_a_whole_accelerates_as_the_force_says():
    # At rest, no potential, a uniform force u: every agent's increment is the implicit
    # friction's h u/(m + h β), however strong the alignment.
    p = SocialPotentialParams(C_a=0.0, C_r=0.0, C_o=50.0, beta=0.7, m=2.0)
    x, _ = _pure_damping(16, 2, seed=3)
    u = np.array([1.5, -0.5])
    geo = pair_geometry(x)
    own, align = damping_rates(geo, np.zeros_like(x), p)
    assert align.min() > 10
    h = 0.3
    accel = np.broadcast_to(u, x.shape)
    _, v = implicit_damping_update(
        x, np.zeros_like(x), accel, h, p.m, own[..., None], align[..., None]
    )
    np.testing.assert_allclose(v, np.broadcast_to(h * u / (p.m + h * p.beta), x.shape))


@pytest.mark.parametrize("dim", [2, 3])
def test_the_pair_forces_keep_the_momentum(dim):
    p = SocialPotentialParams(C_o=2.0, beta=0.0)
    rng = np.random.default_rng(dim)
    x, v = rng.normal(size=(3, 15, dim)), rng.normal(size=(3, 15, dim))
    _, vs = simulate(p, x, v, dt=0.05, steps=40, integrator=IMPLICIT)
    momentum = vs.sum(axis=-2)
    np.testing.assert_allclose(momentum, np.broadcast_to(momentum[0], momentum.shape), atol=1e-11)


def test_the_passive_energy_falls_with_dissipation_and_no_alignment():
    # The env's rule takes the substeps; no alignment, linear friction, no sink.
    cfg = SwarmConfig(
        n_agents=24,
        integrator=IMPLICIT,
        physics=SocialPotentialParams(C_o=0.0, beta=1.0),
        init_speed=2.0,
        max_steps=10**6,
    )
    core = SwarmNavCore(cfg, batch=4)
    core.reset(np.random.default_rng(0))
    zero = np.zeros((4, cfg.n_agents, cfg.dim))
    phi = [energy(core.x, core.v, cfg.physics)]
    for _ in range(60):
        core.step(zero)
        phi.append(energy(core.x, core.v, cfg.physics))
    phi = np.array(phi)
    # symplectic Euler's energy oscillates by O(h) about a decreasing one: over every
    # 5 steps it falls, and a single step never gives back more than 0.1 % of it
    assert np.all(np.diff(phi[::5], axis=0) < 0)
    assert np.all(np.diff(phi, axis=0) <= 1e-3 * np.abs(phi[0]))


def test_the_trajectories_converge_at_order_one():
    p = SocialPotentialParams.navigation()
    rng = np.random.default_rng(5)
    x, v = rng.uniform(-1.5, 1.5, size=(2, 12, 2)), rng.normal(size=(2, 12, 2)) * 0.3
    goal = np.array([3.0, 1.0])
    t_end, fine = 1.0, 1e-4
    xs, _ = simulate(p, x, v, dt=fine, steps=round(t_end / fine), goal=goal, integrator=IMPLICIT)
    errors = []
    for dt in (0.004, 0.002, 0.001):
        ys, _ = simulate(p, x, v, dt=dt, steps=round(t_end / dt), goal=goal, integrator=IMPLICIT)
        errors.append(float(np.abs(ys[-1] - xs[-1]).max()))
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all((orders > 0.8) & (orders < 1.3)), (errors, orders)


def test_its_rule_needs_no_more_substeps_than_the_explicit_rule():
    rng = np.random.default_rng(2)
    for p in PARAMS[:3]:
        x = rng.normal(size=(4, 30, 2)) * 0.7
        v = rng.normal(size=x.shape)
        geo = pair_geometry(x)
        explicit = stable_substep(*pair_rates(geo, p, v=v))
        omega2 = stiffness_rate(geo, p)
        implicit = stable_substep(omega2, 0 * omega2, integrator=IMPLICIT)
        assert np.all(implicit >= explicit)


@pytest.mark.parametrize("n", [16, 32, 128])
def test_the_start_prediction_follows_the_rule(n):
    cfg = SwarmConfig(n_agents=n, integrator=IMPLICIT, physics=SocialPotentialParams.navigation())
    predicted = start_substeps(cfg)
    assert predicted <= start_substeps(
        SwarmConfig(n_agents=n, physics=SocialPotentialParams.navigation())
    )
    core = SwarmNavCore(cfg, batch=16)
    core.reset(np.random.default_rng(1))
    core.step(np.zeros((16, n, 2)))
    taken = core.stats()["substeps"]
    # an average start: the rule's count over the drawn starts brackets the prediction
    assert taken.min() - 1 <= predicted <= taken.max() + 1


def test_a_predictably_stiff_start_is_refused_for_the_implicit_rule_too():
    cfg = SwarmConfig(
        n_agents=400,
        init_radius=0.5,
        integrator=IMPLICIT,
        max_substeps=3,
        physics=SocialPotentialParams.navigation(),
    )
    assert start_substeps(cfg) > 3
    with pytest.raises(ValueError, match="predictably unstable"):
        check_step_control(cfg)
