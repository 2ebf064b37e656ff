"""Tests of the Lagrangian gradient model (Vanualailai & Sharma, eqs. 6–7)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from swarm_envs.papers import vanualailai_sharma as vs_paper
from swarm_envs.physics.lagrangian import (
    LagrangianParams,
    lagrangian_frame,
    lagrangian_gradient,
    lagrangian_value,
    lagrangian_velocity,
    min_pair_clearance,
    pair_clearance,
    simulate_lagrangian,
    well_separated,
)


def _spread_points(n: int, rng: np.random.Generator, side: float = 10.0) -> np.ndarray:
    pts: list[np.ndarray] = []
    while len(pts) < n:
        p = rng.uniform(0, side, 2)
        if all(np.linalg.norm(p - q) > 1.5 for q in pts):
            pts.append(p)
    return np.array(pts)


def _hetero(n: int, gradient: str, seed: int = 0) -> LagrangianParams:
    rng = np.random.default_rng(seed)
    return LagrangianParams(
        alpha=tuple(map(tuple, rng.uniform(0.5, 1.5, (n, 2)).tolist())),
        gamma=tuple(rng.uniform(0.5, 2.0, n).tolist()),
        beta=tuple(map(tuple, rng.uniform(0.5, 2.0, (n, n)).tolist())),
        r=tuple(rng.uniform(0.2, 0.5, n).tolist()),
        gradient=gradient,
    )


def _fd_gradient(x: np.ndarray, p: LagrangianParams, goal=None, h: float = 1e-6) -> np.ndarray:
    g = np.zeros_like(x)
    for i in range(x.shape[0]):
        for k in range(x.shape[1]):
            xp, xm = x.copy(), x.copy()
            xp[i, k] += h
            xm[i, k] -= h
            g[i, k] = (lagrangian_value(xp, p, goal) - lagrangian_value(xm, p, goal)) / (2 * h)
    return g


@pytest.mark.parametrize("goal", [None, np.array([3.0, -1.0])])
def test_exact_gradient_matches_finite_differences(goal):
    x = _spread_points(5, np.random.default_rng(1))
    p = _hetero(5, "exact")
    g = lagrangian_gradient(x, p, goal)
    fd = _fd_gradient(x, p, goal)
    np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-6 * np.abs(fd).max())


def test_seed_gradient_is_not_the_exact_gradient():
    x = _spread_points(5, np.random.default_rng(2))
    p = _hetero(5, "seed")
    assert not np.allclose(lagrangian_gradient(x, p), _fd_gradient(x, p), rtol=1e-3)


def test_seed_gradient_hand_case():
    # x1 = (0,0), x2 = (4,0), x3 = (0,3); r = 0.5 (r_i + r_j = 1); γ = 1, β = 2.
    # Centroid (4/3, 1); e1 = (−4/3, −1); R_1 = 25/18; R_12 = 15/2, R_13 = 4.
    # w_1 = 1 + 2/7.5 + 2/4 = 53/30;  B_12 = 2 R_1/R_12² = 4/81;  B_13 = 2 R_1/R_13² = 25/144.
    # ∂L/∂x_1 = w_1 e_1 − 2 [B_12 (x1 − x2) + B_13 (x1 − x3)]
    #         = (−106/45 + 32/81, −53/30 + 25/24) = (−794/405, −87/120).
    x = np.array([[0.0, 0.0], [4.0, 0.0], [0.0, 3.0]])
    p = LagrangianParams(alpha=1.0, gamma=1.0, beta=2.0, r=0.5, gradient="seed")
    g = lagrangian_gradient(x, p)
    np.testing.assert_allclose(g[0], [-794 / 405, -87 / 120], rtol=1e-13)
    # and L itself: L = Σ_i R_i (γ + Σ_j β/R_ij)
    R = [25 / 18, 0.5 * ((4 - 4 / 3) ** 2 + 1), 0.5 * (16 / 9 + 4)]
    Rij = {(0, 1): 7.5, (0, 2): 4.0, (1, 2): 12.0}
    L = sum(
        R[i] * (1 + sum(2 / Rij[min(i, j), max(i, j)] for j in range(3) if j != i))
        for i in range(3)
    )
    assert float(lagrangian_value(x, p)) == pytest.approx(L, rel=1e-13)


def test_seed_gradient_matches_a_loop_reference_with_random_parameters():
    n = 4
    x = _spread_points(n, np.random.default_rng(3))
    p = _hetero(n, "seed", seed=4)
    gam, bet, rad = np.array(p.gamma), np.array(p.beta), np.array(p.r)
    c = x.mean(0)
    ref = np.zeros_like(x)
    for i in range(n):
        Ri = 0.5 * np.sum((x[i] - c) ** 2)
        w, rep = gam[i], np.zeros(2)
        for j in range(n):
            if j == i:
                continue
            Rij = 0.5 * (np.sum((x[i] - x[j]) ** 2) - (rad[i] + rad[j]) ** 2)
            w += bet[i, j] / Rij
            rep += 2 * bet[i, j] * Ri / Rij**2 * (x[i] - x[j])
        ref[i] = w * (x[i] - c) - rep
    np.testing.assert_allclose(lagrangian_gradient(x, p), ref, rtol=1e-12)
    alpha = np.array(p.alpha)
    np.testing.assert_allclose(lagrangian_velocity(x, p), -alpha * ref, rtol=1e-12)


def test_exact_flow_decreases_L_and_keeps_clearance():
    # Heterogeneous parameters and a near-contact pair (R_12 small) to stress the step rule.
    n = 6
    x0 = _spread_points(n, np.random.default_rng(5))
    x0[1] = x0[0] + np.array([0.0, 1.02 * (0.5 + 0.5)])
    p = LagrangianParams(
        alpha=tuple(np.random.default_rng(6).uniform(0.5, 3.0, n).tolist()),
        gamma=tuple(np.random.default_rng(7).uniform(0.5, 3.0, n).tolist()),
        beta=5.0,
        r=0.5,
        gradient="exact",
    )
    assert float(min_pair_clearance(x0, p)) > 0
    xs, vs = simulate_lagrangian(p, x0, np.zeros_like(x0), dt=0.2, steps=150)
    L = lagrangian_value(xs, p)
    assert np.all(np.isfinite(L))
    assert np.all(np.diff(L) <= 0)
    assert L[-1] < L[0]
    assert np.all(min_pair_clearance(xs, p) > 0)
    np.testing.assert_allclose(vs, lagrangian_velocity(xs, p))


def test_exact_gradient_keeps_centroid_fixed_with_uniform_alpha():
    x0 = _spread_points(5, np.random.default_rng(8))
    p = LagrangianParams(alpha=2.0, gamma=1.0, beta=3.0, r=0.5, gradient="exact")
    np.testing.assert_allclose(lagrangian_gradient(x0, p).sum(0), 0, atol=1e-10)
    xs, _ = simulate_lagrangian(p, x0, np.zeros_like(x0), dt=0.1, steps=30)
    np.testing.assert_allclose(xs.mean(1), x0.mean(0)[None].repeat(31, 0), atol=1e-9)


def test_seed_flow_keeps_clearance():
    p = LagrangianParams.randomized(
        8, np.random.default_rng(9), alpha=5.0, gamma=1.0, r=0.3, beta_range=(2.0, 5.0)
    )
    x0 = _spread_points(8, np.random.default_rng(10))
    xs, _ = simulate_lagrangian(p, x0, np.zeros_like(x0), dt=0.05, steps=100)
    assert np.all(min_pair_clearance(xs, p) > 0)
    assert np.all(np.isfinite(xs))


@pytest.mark.parametrize("gradient", ["seed", "exact"])
def test_batched_equals_one_by_one(gradient):
    p = LagrangianParams(alpha=1.0, gamma=1.0, beta=2.0, r=0.4, gradient=gradient)
    x0 = np.stack([_spread_points(5, np.random.default_rng(s)) for s in range(3)])
    xs, vs = simulate_lagrangian(p, x0, np.zeros_like(x0), dt=0.1, steps=25)
    assert xs.shape == (26, 3, 5, 2)
    for b in range(3):
        xb, vb = simulate_lagrangian(p, x0[b], np.zeros_like(x0[b]), dt=0.1, steps=25)
        np.testing.assert_allclose(xs[:, b], xb, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(vs[:, b], vb, rtol=1e-12, atol=1e-12)
    # the pure functions too
    np.testing.assert_allclose(
        lagrangian_value(x0, p), [lagrangian_value(x0[b], p) for b in range(3)]
    )
    np.testing.assert_allclose(
        lagrangian_gradient(x0, p), np.stack([lagrangian_gradient(x0[b], p) for b in range(3)])
    )


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"alpha": 0.0}, "alpha"),
        ({"gamma": -1.0}, "gamma"),
        ({"beta": float("nan")}, "beta"),
        ({"r": -0.1}, "r"),
        ({"gradient": "numeric"}, "gradient"),
        ({"step_tol": 0.0}, "step_tol"),
        ({"gamma": (1.0, -2.0)}, "gamma"),
        ({"beta": (1.0, 2.0)}, "beta"),
        ({"alpha": "fast"}, "alpha"),
    ],
)
def test_invalid_params_name_the_field(kwargs, field):
    with pytest.raises(ValueError, match=rf"LagrangianParams\.{field}\b"):
        LagrangianParams(**kwargs)


def test_shape_mismatch_and_bad_state():
    p = LagrangianParams(gamma=(1.0, 2.0, 3.0), r=0.1)
    with pytest.raises(ValueError, match=r"LagrangianParams\.gamma"):
        lagrangian_gradient(np.zeros((4, 2)) + np.arange(4)[:, None], p)
    q = LagrangianParams(r=1.0)
    overlapping = np.array([[0.0, 0.0], [1.0, 0.0]])
    assert float(lagrangian_value(overlapping, q)) == np.inf
    assert float(pair_clearance(overlapping, q)[0, 1]) < 0
    with pytest.raises(ValueError, match="R_ij > 0"):
        simulate_lagrangian(q, overlapping, np.zeros((2, 2)), dt=0.1, steps=1)
    with pytest.raises(ValueError, match="velocities shape"):
        simulate_lagrangian(q, overlapping * 5, np.zeros((3, 2)), dt=0.1, steps=1)
    with pytest.raises(ValueError, match="dt"):
        simulate_lagrangian(q, overlapping * 5, np.zeros((2, 2)), dt=0.0, steps=1)


def test_randomized_is_seeded_and_in_range():
    kw = {"gamma_range": (0.01, 1.0), "beta_range": (200.0, 500.0), "alpha_range": (1.0, 2.0)}
    a = LagrangianParams.randomized(6, np.random.default_rng(42), **kw)
    b = LagrangianParams.randomized(6, np.random.default_rng(42), **kw)
    c = LagrangianParams.randomized(6, np.random.default_rng(43), **kw)
    assert a == b and hash(a) == hash(b)
    assert a != c
    g, be, al = np.array(a.gamma), np.array(a.beta), np.array(a.alpha)
    assert g.shape == (6,) and be.shape == (6, 6) and al.shape == (6, 2)
    assert np.all((g >= 0.01) & (g <= 1.0))
    assert np.all((be >= 200) & (be <= 500)) and not np.allclose(be, be.T)
    sym = LagrangianParams.randomized(
        6, np.random.default_rng(0), beta_range=(1.0, 2.0), symmetric_beta=True
    )
    np.testing.assert_allclose(np.array(sym.beta), np.array(sym.beta).T)
    x0 = _spread_points(6, np.random.default_rng(1), side=3000.0)
    p = LagrangianParams.randomized(6, np.random.default_rng(42), r=1.0, **kw)
    r1 = simulate_lagrangian(p, x0, np.zeros_like(x0), dt=0.01, steps=5)
    r2 = simulate_lagrangian(p, x0, np.zeros_like(x0), dt=0.01, steps=5)
    np.testing.assert_array_equal(r1[0], r2[0])


def test_reproduction_quick(tmp_path):
    res = vs_paper.run(tmp_path, quick=True)
    for name in ("fig1", "fig2", "fig3", "fig4", "fig5"):
        assert (tmp_path / f"vs_{name}.png").stat().st_size > 1000
        assert res[name]["verdict"].startswith("quick run")
        assert res[name]["measures"]["min_R_ij"] > 0
    assert res["fig1_exact_gradient"]["L_non_increasing"] is True
    assert res["fig1_exact_gradient"]["centroid_displacement"] < 1e-8
    loaded = json.loads((tmp_path / "vanualailai_sharma.json").read_text())
    assert loaded["fig3"]["paper"]["beta"] == 100.0


@pytest.mark.parametrize("gap", [0.1001, 0.10001])
def test_a_pair_of_bins_all_but_touching_is_flagged_not_held_silently(gap):
    # Two bins (r = 0.05) a hair apart: rule 2 rejects every substep above dt·2⁻⁴⁰ when
    # the gap is 0.01 % of r_i + r_j, and the frame must say so (over_cap) rather than
    # hold the swarm as if at rest; at 0.1 % the frame integrates.
    p = LagrangianParams.navigation()
    x = np.array([[[0.0, 0.0], [gap, 0.0], [1.0, 1.0]]])
    goal = np.array([[5.0, 0.0]])
    control = np.ones_like(x) * 0.5
    frame = lagrangian_frame(x, p, dt=0.1, goal=goal, control=control, max_substeps=1000)
    held = bool((frame.x == x).all())
    assert bool(frame.over_cap[0]) == held
    assert held == (gap < 0.1001)
    assert well_separated(x, p) == np.array([False])


def test_simulate_refuses_a_frame_it_cannot_integrate():
    p = LagrangianParams.navigation()
    x0 = np.array([[0.0, 0.0], [0.100003, 0.0], [1.0, 1.0]])  # 0.003 % from touching
    with pytest.raises(RuntimeError, match="frame 1 cannot be integrated"):
        simulate_lagrangian(p, x0, np.zeros_like(x0), dt=0.1, steps=3)
    x0[1, 0] = 0.103  # well separated: it runs
    xs, _ = simulate_lagrangian(p, x0, np.zeros_like(x0), dt=0.1, steps=3)
    assert xs.shape == (4, 3, 2)
