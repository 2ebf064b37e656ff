"""Cut-off radius, its error bounds, and the pair-list forces and energy (physics.cutoff)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from swarm_envs.physics import SocialPotentialParams, energy, forces
from swarm_envs.physics.cutoff import (
    PairAccumulator,
    PairSums,
    _phi,
    cutoff_radius,
    energy_error_bound,
    force_error_bound,
    pair_force_bound,
    pair_sums,
    sparse_energy,
    sparse_forces,
    swarm_rates,
)
from swarm_envs.physics.neighbors import CELL_MARGIN, REACH, CellList, radius_pairs
from swarm_envs.physics.social_potential import (
    RHO_FLOOR,
    pair_geometry,
    pair_law,
    pair_rates,
    rate_law,
)

PARAMS = [
    SocialPotentialParams(),
    SocialPotentialParams.navigation(),
    SocialPotentialParams(C_a=2.0, C_r=0.5, l_a=2.0, l_r=0.7, C_o=0.0, l_o=0.4),
    SocialPotentialParams(C_a=0.0, C_r=1.0, C_o=3.0, l_o=3.0),
]


def all_pairs(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every pair within each swarm, as flat indices."""
    n = x.shape[-2]
    i, j = np.triu_indices(n, 1)
    shift = (np.arange(int(np.prod(x.shape[:-2]))) * n)[:, None]
    return (i + shift).ravel(), (j + shift).ravel()


def ball_density(x: np.ndarray, cutoff: float) -> float:
    """The smallest ``n`` with ``#{j ≠ i: ρ_ij ≤ ρ} ≤ n ω_d ρ^d`` for all i and ρ ≥ r_c.

    The count is a step function and ``ρ^d`` grows, so the worst ratios sit at the
    neighbour distances themselves (and at ``r_c``).
    """
    n, d = x.shape[-2:]
    rho = np.sort(np.linalg.norm(x[:, None, :] - x[None, :, :], axis=-1), axis=-1)[:, 1:]
    ball = math.pi if d == 2 else 4.0 * math.pi / 3.0
    return float((np.arange(1, n) / (ball * np.maximum(rho, cutoff) ** d)).max())


@pytest.mark.parametrize("params", PARAMS)
@pytest.mark.parametrize("tol", [1e-1, 1e-3, 1e-8])
@pytest.mark.parametrize("speed", [0.0, 0.5, 4.0])
def test_cutoff_radius_is_the_smallest_radius_within_tol(
    params: SocialPotentialParams, tol: float, speed: float
) -> None:
    r_c = cutoff_radius(params, tol, speed=speed)
    assert pair_force_bound(r_c, params, speed=speed) <= tol
    if r_c > 0:
        assert pair_force_bound(r_c * (1 - 1e-9), params, speed=speed) > tol
    else:
        assert pair_force_bound(0.0, params, speed=speed) <= tol


def test_cutoff_radius_closed_forms() -> None:
    attraction = SocialPotentialParams(C_a=2.0, l_a=0.5, C_r=0.0, C_o=0.0)
    assert cutoff_radius(attraction, 1e-4) == pytest.approx(0.5 * math.log(4.0 / 1e-4), 1e-10)
    alignment = SocialPotentialParams(C_a=0.0, C_r=0.0, C_o=0.7, l_o=1.5)
    r = cutoff_radius(alignment, 1e-3, speed=2.0)
    assert r == pytest.approx(1.5 * math.log(1.4 / 1e-3), 1e-10)
    assert cutoff_radius(alignment, 1e-3, speed=0.0) == 0.0  # no alignment at zero speed
    assert cutoff_radius(SocialPotentialParams(C_a=0, C_r=0, C_o=0), 1e-9) == 0.0
    # The defaults of the cut-off core with the navigation set.
    assert cutoff_radius(SocialPotentialParams.navigation(), 0.03) == pytest.approx(5.0752, 1e-4)


@pytest.mark.parametrize("params", PARAMS)
def test_pair_force_bound_bounds_every_pair_force(params: SocialPotentialParams) -> None:
    """Two agents: the dense force of one on the other never exceeds g(ρ; |v_i − v_j|)."""
    p = dataclasses.replace(params, beta=0.0)
    rng = np.random.default_rng(0)
    x = rng.normal(size=(2000, 2, 3)) * rng.uniform(0.01, 4.0, size=(2000, 1, 1))
    v = rng.normal(size=x.shape) * rng.uniform(0.0, 3.0, size=(2000, 1, 1))
    f = np.linalg.norm(forces(x, v, p)[:, 0], axis=-1)
    rho = np.linalg.norm(x[:, 1] - x[:, 0], axis=-1)
    w = np.linalg.norm(v[:, 1] - v[:, 0], axis=-1)
    bound = np.array([pair_force_bound(r, p, speed=s) for r, s in zip(rho, w, strict=True)])
    assert (f <= bound * (1 + 1e-12)).all()


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("r", [0.0, 0.7, 3.0, 9.0])
@pytest.mark.parametrize("length", [0.2, 1.5])
def test_phi_is_the_ball_integral(d: int, r: float, length: float) -> None:
    """``Φ_d(r, l) = ω_d r^d e^{−r/l} + S_d ∫_r^∞ ρ^{d−1} e^{−ρ/l} dρ`` (integration by parts)."""
    rho = np.linspace(r, r + 60 * length, 200_001)
    shell = 2 * math.pi if d == 2 else 4 * math.pi
    ball = math.pi if d == 2 else 4 * math.pi / 3
    f = shell * rho ** (d - 1) * np.exp(-rho / length)
    integral = float(np.sum((f[1:] + f[:-1]) * np.diff(rho)) / 2)
    expected = ball * r**d * math.exp(-r / length) + integral
    assert _phi(d, r, length) == pytest.approx(expected, rel=1e-6)


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("params", PARAMS[:3])
def test_sparse_forces_and_energy_with_all_pairs_equal_dense(
    d: int, params: SocialPotentialParams
) -> None:
    rng = np.random.default_rng(d)
    x = rng.normal(size=(3, 25, d)) * 2.0
    x[0, 5] = x[0, 6]  # coincident agents: no force between them, U(0) in the energy
    v = rng.normal(size=x.shape)
    goal = rng.normal(size=(3, d))
    p = dataclasses.replace(params, C_g=2.0)
    i, j = all_pairs(x)
    np.testing.assert_allclose(
        sparse_forces(x, v, p, i, j, goal), forces(x, v, p, goal), rtol=1e-12, atol=1e-12
    )
    np.testing.assert_allclose(
        sparse_energy(x, v, p, i, j, goal), energy(x, v, p, goal), rtol=1e-12, atol=1e-10
    )
    # Single swarm, no goal, pairs in either orientation.
    f = sparse_forces(x[1], v[1], p, j[300:600] - 25, i[300:600] - 25)
    np.testing.assert_allclose(f, forces(x[1], v[1], p), rtol=1e-12, atol=1e-12)


def test_sparse_forces_float32_and_coincident_agents() -> None:
    x = np.zeros((6, 2), dtype=np.float32)  # every agent on one point
    v = np.ones_like(x)
    p = SocialPotentialParams()
    i, j = all_pairs(x)
    f = sparse_forces(x, v, p, i, j)
    assert f.dtype == np.float32
    np.testing.assert_array_equal(f, -p.beta * v)  # pair forces vanish: u_ij = 0
    e = sparse_energy(x, v, p, i, j)
    assert e.dtype == np.float32
    assert float(e) == pytest.approx(float(energy(x, v, p)), rel=1e-6)
    y = np.random.default_rng(1).normal(size=(30, 3)).astype(np.float32)
    w = np.random.default_rng(2).normal(size=(30, 3)).astype(np.float32)
    i, j = all_pairs(y)
    np.testing.assert_allclose(sparse_forces(y, w, p, i, j), forces(y, w, p), rtol=2e-5, atol=1e-5)


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("tol", [0.1, 0.01])
def test_cutoff_error_within_documented_bounds(d: int, tol: float) -> None:
    """Per agent: |F − F_cut| ≤ (N − 1) g(r_c; w) and ≤ n Σ A_t Φ_d(r_c, l_t)."""
    p = SocialPotentialParams.navigation()
    rng = np.random.default_rng(d)
    for spread, shape in ((3.0, "ball"), (1.0, "lattice")):
        if shape == "ball":
            x = rng.normal(size=(300, d)) * spread * (300 / 30) ** (1 / d)
        else:
            axes = [np.arange(7 if d == 2 else 5) * 1.3] * d
            x = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, d)
            x = x + rng.normal(size=x.shape) * 0.05
        v = rng.normal(size=x.shape)
        n = x.shape[0]
        w = float(np.linalg.norm(v[:, None] - v[None], axis=-1).max())
        r_c = cutoff_radius(p, tol, speed=w)
        i, j = radius_pairs(x, r_c)
        err = np.linalg.norm(sparse_forces(x, v, p, i, j) - forces(x, v, p), axis=-1)
        by_n = force_error_bound(p, r_c, speed=w, n_agents=n, dim=d)
        assert by_n == pytest.approx((n - 1) * pair_force_bound(r_c, p, speed=w))
        assert 0 < err.max() <= by_n  # something was cut off, within the bound
        density = ball_density(x, r_c)
        by_density = force_error_bound(p, r_c, speed=w, density=density, dim=d)
        assert err.max() <= by_density
        assert force_error_bound(p, r_c, speed=w, n_agents=n, density=density, dim=d) == min(
            by_n, by_density
        )
        de = abs(float(sparse_energy(x, v, p, i, j) - energy(x, v, p)))
        assert de <= energy_error_bound(p, r_c, n_agents=n, density=density, dim=d)
        assert de <= energy_error_bound(p, r_c, n_agents=n, dim=d)


def test_pair_accumulator_groups_counts_and_chunks() -> None:
    rng = np.random.default_rng(0)
    x = rng.normal(size=(2, 40, 2))
    v = rng.normal(size=x.shape)
    p = SocialPotentialParams()
    i, j = all_pairs(x)
    flat_x, flat_v = x.reshape(-1, 2), v.reshape(-1, 2)
    groups = np.arange(80) // 40
    sums = pair_sums(
        flat_x, flat_v, p, i, j, groups=groups, n_groups=2, potential=True, close_radius=0.3
    )
    rho = np.linalg.norm(x[:, :, None] - x[:, None], axis=-1)
    close = [(np.triu(rho[b] < 0.3, 1)).sum() for b in range(2)]
    np.testing.assert_array_equal(sums.close, close)
    kinetic = 0.5 * np.einsum("bik,bik->b", v, v)
    np.testing.assert_allclose(sums.potential + kinetic, energy(x, v, p), rtol=1e-12)
    dense = forces(x, v, dataclasses.replace(p, beta=0.0))
    np.testing.assert_allclose(sums.force, dense.reshape(-1, 2), atol=1e-12)
    acc = PairAccumulator(p, 80, flat_v)  # the same pairs, one chunk at a time
    for s in range(0, i.size, 97):
        ii, jj = i[s : s + 97], j[s : s + 97]
        dx = [flat_x[jj, k] - flat_x[ii, k] for k in range(2)]
        acc.add(ii, jj, dx, dx[0] ** 2 + dx[1] ** 2)
    np.testing.assert_allclose(acc.result(2).force, sums.force, atol=1e-12)
    empty = PairAccumulator(p, 5).result(3, np.float32)
    assert empty.force.shape == (5, 3) and empty.force.dtype == np.float32


def direct_pair_sums(
    x: np.ndarray, v: np.ndarray | None, p: SocialPotentialParams, close_radius: float
) -> PairSums:
    """Every pair within each swarm of ``x`` ``(B, N, d)``, one at a time through
    :func:`pair_law` itself on Python floats (``math.exp``): flat forces, the potential
    per swarm, the close pairs per swarm."""
    B, N, d = x.shape
    force = np.zeros((B, N, d))
    pot = np.zeros(B)
    close = np.zeros(B, np.int64)
    for b in range(B):
        for a in range(N):
            for c in range(a + 1, N):
                r = x[b, c] - x[b, a]
                rho = math.sqrt(sum(float(t) * float(t) for t in r))
                vdot = None if v is None else float(np.dot(v[b, a] - v[b, c], r))
                inv = 1.0 / max(rho, RHO_FLOOR)
                s, u = pair_law(rho, inv, vdot, p.C_a, p.C_r, p.l_a, p.l_r, p.C_o, p.l_o, math.exp)
                force[b, a] += s * r
                force[b, c] -= s * r
                pot[b] += u
                close[b] += rho < close_radius
    return PairSums(force.reshape(B * N, d), pot, close)


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("params", PARAMS)
@pytest.mark.parametrize("with_v", [True, False])
def test_pair_accumulator_applies_pair_law(
    d: int, params: SocialPotentialParams, with_v: bool
) -> None:
    """The numpy pass sums exactly what pair_law gives per pair (so a change of the law
    reaches it): forces, potential and close pairs, coincident agents included."""
    rng = np.random.default_rng(d)
    x = rng.uniform(-2.0, 2.0, (2, 25, d))
    x[1, 3] = x[1, 7]  # a coincident pair: no force, U(0)
    v = rng.normal(size=x.shape) if with_v else None
    ref = direct_pair_sums(x, v, params, close_radius=0.5)
    i, j = all_pairs(x)
    flip = rng.random(i.size) < 0.5  # either orientation of a pair
    i, j = np.where(flip, j, i), np.where(flip, i, j)
    flat_x = x.reshape(-1, d)
    flat_v = None if v is None else v.reshape(-1, d)
    acc = PairAccumulator(
        params, 50, flat_v, groups=np.arange(50) // 25, n_groups=2, potential=True, close_radius=0.5
    )
    for s in range(0, i.size, 101):  # several chunks
        ii, jj = i[s : s + 101], j[s : s + 101]
        dx = [flat_x[jj, k] - flat_x[ii, k] for k in range(d)]
        acc.add(ii, jj, dx, sum(c * c for c in dx))
    out = acc.result(d)
    assert ref.close.sum() > 0
    scale = max(1.0, float(np.abs(ref.force).max()))
    np.testing.assert_allclose(out.force, ref.force, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(out.potential, ref.potential, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(out.close, ref.close)


PARAMS_RATES = [*PARAMS, SocialPotentialParams.large_swarm()]


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("params", PARAMS_RATES)
@pytest.mark.parametrize("sink", [False, True])
def test_rate_sums_over_every_pair_give_the_dense_rates(
    d: int, params: SocialPotentialParams, sink: bool
) -> None:
    """The step-size rule's rates summed over a pair list (numpy pass, chunked, either
    orientation) equal the dense ``pair_rates`` when every pair is listed, and each
    row's sums equal rate_law summed over its pairs one at a time."""
    rng = np.random.default_rng(d)
    B, N = 2, 30
    x = rng.uniform(-2.0, 2.0, (B, N, d))
    x[1, 3] = x[1, 7]  # coincident agents: κ(0), w(0)
    i, j = all_pairs(x)
    flip = rng.random(i.size) < 0.5
    i, j = np.where(flip, j, i), np.where(flip, i, j)
    flat = x.reshape(-1, d)
    sums = pair_sums(flat, None, params, i, j, rates=True)
    assert sums.kappa is not None and sums.damping is not None
    kappa = np.zeros(B * N)
    damping = np.zeros(B * N)
    for a, b in zip(i.tolist(), j.tolist(), strict=True):
        rho = math.sqrt(float(((flat[b] - flat[a]) ** 2).sum()))
        k, w = rate_law(rho, *(getattr(params, f) for f in RATE_FIELDS), math.exp)
        kappa[[a, b]] += k
        damping[[a, b]] += 0.0 if w is None else w
    np.testing.assert_allclose(sums.kappa, kappa, rtol=1e-12)
    np.testing.assert_allclose(sums.damping, damping, rtol=1e-12, atol=1e-15)
    omega2, gamma = swarm_rates(
        sums.kappa.reshape(B, N), sums.damping.reshape(B, N), params, sink=sink
    )
    dense_omega2, dense_gamma = pair_rates(pair_geometry(x), params, sink=sink)
    np.testing.assert_allclose(omega2, dense_omega2, rtol=1e-12)
    np.testing.assert_allclose(gamma, dense_gamma, rtol=1e-12)
    assert pair_sums(flat, None, params, i, j).kappa is None  # only when asked for


RATE_FIELDS = ("C_a", "C_r", "l_a", "l_r", "C_o", "l_o")


@pytest.mark.parametrize("d", [2, 3])
def test_rate_sums_drop_the_pairs_beyond_the_radius(d: int) -> None:
    """Over the cell list's pairs within a radius, the rates (like the force) count only
    the pairs inside it, and the compiled pass (where numba imports) sums the same as
    the numpy pass."""
    from swarm_envs.physics import compiled_pairs

    p = SocialPotentialParams.large_swarm()
    rng = np.random.default_rng(5 + d)
    B, N, radius = 2, 200, 2.5
    x = rng.uniform(-5.0, 5.0, (B, N, d))
    cells = CellList.build(x, radius * (1.0 + CELL_MARGIN) / REACH, REACH)
    groups = cells.order // N
    acc = PairAccumulator(p, B * N, None, groups=groups, n_groups=B, rates=True)
    for chunk in cells.iter_pairs(radius):
        acc.add(*chunk)
    got = acc.result(d)
    assert got.kappa is not None and got.damping is not None
    kappa = np.zeros((B, N))  # by brute force, per agent of each swarm
    damping = np.zeros((B, N))
    for b in range(B):
        rho = np.linalg.norm(x[b, :, None] - x[b, None], axis=-1)
        inside = (rho <= radius) & ~np.eye(N, dtype=bool)
        k, w = rate_law(rho, *(getattr(p, f) for f in RATE_FIELDS), np.exp)
        kappa[b] = np.where(inside, k, 0.0).sum(axis=-1)
        damping[b] = np.where(inside, w, 0.0).sum(axis=-1)
        assert 0 < inside.sum() < N * (N - 1)  # some pairs dropped, some kept
    np.testing.assert_allclose(got.kappa, kappa.ravel()[cells.order], rtol=1e-12)
    np.testing.assert_allclose(got.damping, damping.ravel()[cells.order], rtol=1e-12)
    if compiled_pairs.numba_enabled():
        fast = compiled_pairs.cell_pair_sums(
            cells, radius, p, None, groups=groups, n_groups=B, rates=True
        )
        assert fast.kappa is not None and fast.damping is not None
        np.testing.assert_allclose(fast.kappa, got.kappa, rtol=1e-12)
        np.testing.assert_allclose(fast.damping, got.damping, rtol=1e-12)
        assert compiled_pairs.cell_pair_sums(cells, radius, p, None).kappa is None


def test_invalid_input_raises() -> None:
    p = SocialPotentialParams()
    for tol in (0.0, -1.0, np.nan, np.inf):
        with pytest.raises(ValueError, match="tol"):
            cutoff_radius(p, tol)
    with pytest.raises(ValueError, match="speed"):
        cutoff_radius(p, 0.1, speed=-1.0)
    with pytest.raises(ValueError, match="SocialPotentialParams"):
        cutoff_radius({"C_a": 1.0}, 0.1)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="n_agents, density"):
        force_error_bound(p, 3.0)
    with pytest.raises(ValueError, match="n_agents"):
        force_error_bound(p, 3.0, n_agents=0)
    with pytest.raises(ValueError, match="density"):
        force_error_bound(p, 3.0, density=-1.0)
    with pytest.raises(ValueError, match="dim"):
        force_error_bound(p, 3.0, n_agents=4, dim=4)
    with pytest.raises(ValueError, match="cutoff"):
        energy_error_bound(p, -1.0, n_agents=3)
    x = np.zeros((4, 2))
    with pytest.raises(ValueError, match=r"\[0, 4\)"):
        sparse_forces(x, x, p, np.array([0]), np.array([4]))
    with pytest.raises(ValueError, match="equal length"):
        sparse_forces(x, x, p, np.array([0, 1]), np.array([2]))
    with pytest.raises(ValueError, match="integer"):
        sparse_energy(x, x, p, np.array([0.0]), np.array([1.0]))
