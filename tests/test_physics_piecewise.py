"""Piecewise force model (Naterop §4.2, docs/models.md §4): the force law at every threshold,
the λ-nearest selection, the random force and the drag, determinism, batching, dtypes,
validation, and the reproduction of the report's dispersal and of the drag fix."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from swarm_envs import metrics
from swarm_envs.papers.naterop.piecewise import run
from swarm_envs.physics.piecewise import (
    PiecewiseParams,
    force_law,
    interaction_forces,
    nearest_neighbors,
    piecewise_forces,
    simulate_piecewise,
)

P = PiecewiseParams(F_max=100.0, r_r=1.0, r_0=5.0, r_a=20.0, R=30.0, n_neighbors=8)
QUIET = PiecewiseParams(noise=0.0)
EPS = 1e-9


def _f(rho: float, p: PiecewiseParams = P) -> float:
    return float(force_law(np.array(rho), p))


# --------------------------------------------------------------------------- force law


@pytest.mark.parametrize(
    ("rho", "expected"),
    [
        (0.0, -100.0),  # −F_max at zero separation
        (0.25, -75.0),
        (0.5, -50.0),
        (1.0, 0.0),  # r_r
        (3.0, 0.0),  # equilibrium band
        (5.0, 0.0),  # r_0
        (8.0, 20.0),  # (8 − 5)/15 F_max
        (12.5, 50.0),
        (20.0, 100.0),  # r_a
        (25.0, 100.0),
        (30.0, 0.0),  # R: outside (the jump)
        (1e6, 0.0),
    ],
)
def test_force_law_values(rho: float, expected: float) -> None:
    assert _f(rho) == pytest.approx(expected, abs=1e-9)


@pytest.mark.parametrize("threshold", [1.0, 5.0, 20.0])
def test_force_law_continuous_at_r_r_r_0_r_a(threshold: float) -> None:
    left, right = _f(threshold - EPS), _f(threshold + EPS)
    assert left == pytest.approx(right, abs=1e-5)
    assert _f(threshold) == pytest.approx(left, abs=1e-5)


def test_force_law_jump_at_R() -> None:
    assert _f(30.0 - EPS) == pytest.approx(100.0)
    assert _f(30.0) == 0.0
    assert _f(30.0 + EPS) == 0.0


def test_force_law_step_when_r_0_equals_r_a() -> None:
    p = PiecewiseParams(r_r=1.0, r_0=10.0, r_a=10.0, R=30.0)
    assert _f(10.0 - EPS, p) == 0.0
    assert _f(10.0, p) == 100.0
    assert math.isinf(p.g_a)


def test_force_law_degenerate_equal_radii() -> None:
    p = PiecewiseParams(r_r=2.0, r_0=2.0, r_a=2.0, R=2.0)
    out = force_law(np.array([0.0, 1.0, 2.0, 3.0]), p)
    assert out.tolist() == [-100.0, -50.0, 0.0, 0.0]


def test_force_law_slopes_match_properties() -> None:
    assert P.g_r == 100.0 and P.g_a == pytest.approx(100.0 / 15.0)
    assert _f(0.6) - _f(0.4) == pytest.approx(P.g_r * 0.2)
    assert _f(10.1) - _f(9.9) == pytest.approx(P.g_a * 0.2)


# --------------------------------------------------------------------------- forces


def test_sign_convention_attraction_toward_j_repulsion_away() -> None:
    # j at 10 m along +x: attracted toward j (+x); j at 0.5 m: pushed away (−x).
    far = interaction_forces(np.array([[0.0, 0.0], [10.0, 0.0]]), P)
    assert far[0, 0] == pytest.approx(_f(10.0)) and far[0, 0] > 0 and far[0, 1] == 0.0
    near = interaction_forces(np.array([[0.0, 0.0], [0.5, 0.0]]), P)
    assert near[0, 0] == pytest.approx(-50.0)


def test_only_lambda_nearest_count() -> None:
    # Agent 0 at the origin, λ = 3 neighbours at distance 8 on the axes, a 4th at 12:
    # within R (it would attract with F(12)) but beyond the 3rd neighbour.
    p = PiecewiseParams(n_neighbors=3, noise=0.0)
    x = np.array([[0.0, 0.0], [8.0, 0.0], [0.0, 8.0], [-8.0, 0.0], [0.0, -12.0]])
    f0 = interaction_forces(x, p)[0]
    expected = _f(8.0, p) * (np.array([1, 0]) + np.array([0, 1]) + np.array([-1, 0]))
    np.testing.assert_allclose(f0, expected, atol=1e-12)
    # With λ = 4 the far agent counts.
    f0_all = interaction_forces(x, PiecewiseParams(n_neighbors=4, noise=0.0))[0]
    np.testing.assert_allclose(f0_all, expected + _f(12.0, p) * np.array([0, -1]), atol=1e-12)


def test_nearest_neighbors_excludes_self_and_matches_sort() -> None:
    rng = np.random.default_rng(3)
    x = rng.uniform(0, 10, (2, 20, 2))
    rho = np.linalg.norm(x[..., None, :, :] - x[..., :, None, :], axis=-1)
    nb = nearest_neighbors(rho, 5)
    assert nb.shape == (2, 20, 5)
    masked = rho + np.diag(np.full(20, np.inf))
    ref = np.sort(np.argsort(masked, axis=-1)[..., :5], axis=-1)
    np.testing.assert_array_equal(np.sort(nb, axis=-1), ref)
    assert nearest_neighbors(rho, 100).shape == (2, 20, 19)  # λ ≥ N − 1: all others


def test_coincident_agents_finite_and_no_force() -> None:
    # A coincident pair (u_ij = 0: no force between them) and a far agent beyond R.
    x = np.array([[1.0, 1.0], [1.0, 1.0], [1e6, 0.0]])
    f = interaction_forces(x, QUIET)
    np.testing.assert_array_equal(f, np.zeros_like(f))
    # Separations of 1e-12 (full repulsion −F_max along u_ij) and 1e6: finite.
    x = np.array([[1.0, 1.0], [1.0, 1.0], [1.0, 1.0 + 1e-12], [1e6, 0.0]])
    f = interaction_forces(x, QUIET)
    assert np.isfinite(f).all()
    np.testing.assert_allclose(f[:2], [[0.0, -100.0], [0.0, -100.0]])
    xs, vs = simulate_piecewise(QUIET, x, np.zeros_like(x), dt=0.01, steps=20)
    assert np.isfinite(xs).all() and np.isfinite(vs).all()


def test_single_agent_and_3d() -> None:
    assert interaction_forces(np.zeros((1, 2)), P).tolist() == [[0.0, 0.0]]
    x = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 10.0]])
    f = interaction_forces(x, P)
    np.testing.assert_allclose(f[0], [0.0, 0.0, _f(10.0)])


# --------------------------------------------------------------------------- noise and drag


def test_rng_required_when_noise_on() -> None:
    x = np.zeros((3, 2))
    with pytest.raises(ValueError, match="rng"):
        piecewise_forces(x, x, P)
    with pytest.raises(ValueError, match="rng"):
        simulate_piecewise(P, x, x, dt=0.1, steps=1)
    with pytest.raises(ValueError, match="rng"):
        piecewise_forces(x, x, P, rng=np.random.default_rng(0).bit_generator)  # type: ignore[arg-type]
    piecewise_forces(x, x, QUIET)  # no noise: no rng needed


def test_noise_statistics() -> None:
    # Agents 100 m apart exert nothing: the force is the random force alone.
    x = np.stack([np.arange(200) * 100.0, np.zeros(200)], axis=-1)
    rng = np.random.default_rng(0)
    draws = np.stack([piecewise_forces(x, np.zeros_like(x), P, rng) for _ in range(50)])
    assert abs(draws.mean()) < 0.05 * P.sigma
    assert draws.std() == pytest.approx(100.0 / 6.0, rel=0.02)
    half = PiecewiseParams(noise=0.5)
    d2 = piecewise_forces(x, np.zeros_like(x), half, np.random.default_rng(1))
    assert d2.std() == pytest.approx(100.0 / 12.0, rel=0.1)


def test_drag_decays_isolated_velocity_exponentially() -> None:
    beta, m, dt, steps = 2.0, 0.5, 1e-4, 5000
    p = PiecewiseParams(noise=0.0, beta=beta, m=m)
    x0 = np.array([[0.0, 0.0]])
    v0 = np.array([[3.0, -1.0]])
    _, vs = simulate_piecewise(p, x0, v0, dt=dt, steps=steps)
    t = dt * steps
    np.testing.assert_allclose(vs[-1], v0 * math.exp(-beta * t / m), rtol=1e-3)
    np.testing.assert_allclose(vs[-1], v0 * (1 - beta * dt / m) ** steps, rtol=1e-12)


# --------------------------------------------------------------------------- simulate


def _start(seed: int, batch: tuple[int, ...] = (), n: int = 12) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.uniform(0, 6, (*batch, n, 2)), rng.normal(0, 0.5, (*batch, n, 2))


def test_seeded_determinism() -> None:
    x0, v0 = _start(0)
    kw = {"dt": 0.01, "steps": 50}
    a = simulate_piecewise(P, x0, v0, rng=np.random.default_rng(7), **kw)
    b = simulate_piecewise(P, x0, v0, rng=np.random.default_rng(7), **kw)
    c = simulate_piecewise(P, x0, v0, rng=np.random.default_rng(8), **kw)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    assert not np.array_equal(a[0][-1], c[0][-1])


def test_shapes_goal_ignored_and_control() -> None:
    x0, v0 = _start(1, (3,))
    xs, vs = simulate_piecewise(QUIET, x0, v0, dt=0.01, steps=5)
    assert xs.shape == vs.shape == (6, 3, 12, 2)
    np.testing.assert_array_equal(xs[0], x0)
    xg, _ = simulate_piecewise(QUIET, x0, v0, dt=0.01, steps=5, goal=np.array([5.0, 5.0]))
    np.testing.assert_array_equal(xg, xs)
    with pytest.raises(ValueError, match="goal"):
        simulate_piecewise(QUIET, x0, v0, dt=0.01, steps=5, goal=np.zeros(3))
    u = np.ones_like(x0)
    xu, _ = simulate_piecewise(QUIET, x0, v0, dt=0.01, steps=5, control=u)
    xf, _ = simulate_piecewise(QUIET, x0, v0, dt=0.01, steps=5, control=lambda t, x, v: u)
    np.testing.assert_array_equal(xu, xf)
    assert not np.array_equal(xu, xs)


def test_batched_equals_one_by_one() -> None:
    x0, v0 = _start(2, (2, 3))
    p = PiecewiseParams(noise=0.0, beta=0.5, n_neighbors=4, r_0=3.0)
    xs, vs = simulate_piecewise(p, x0, v0, dt=0.02, steps=30)
    for i in range(2):
        for j in range(3):
            xi, vi = simulate_piecewise(p, x0[i, j], v0[i, j], dt=0.02, steps=30)
            np.testing.assert_allclose(xs[:, i, j], xi, rtol=0, atol=1e-12)
            np.testing.assert_allclose(vs[:, i, j], vi, rtol=0, atol=1e-12)


def test_float32_preserved() -> None:
    x0, v0 = _start(3)
    x0, v0 = x0.astype(np.float32), v0.astype(np.float32)
    assert force_law(np.float32([0.5, 10.0]), P).dtype == np.float32
    assert piecewise_forces(x0, v0, P, np.random.default_rng(0)).dtype == np.float32
    xs, vs = simulate_piecewise(P, x0, v0, dt=0.01, steps=5, rng=np.random.default_rng(0))
    assert xs.dtype == vs.dtype == np.float32


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"F_max": -1.0}, "F_max"),
        ({"F_max": math.nan}, "F_max"),
        ({"r_r": 0.0}, "r_r"),
        ({"r_r": math.inf}, "r_r"),
        ({"r_r": 6.0}, "r_0"),  # r_0 = 5 < r_r
        ({"r_0": 25.0}, "r_0"),  # r_0 > r_a
        ({"r_a": 40.0}, "r_a"),  # r_a > R
        ({"R": math.inf}, "R"),
        ({"n_neighbors": 0}, "n_neighbors"),
        ({"n_neighbors": 2.5}, "n_neighbors"),
        ({"n_neighbors": True}, "n_neighbors"),
        ({"noise": -0.1}, "noise"),
        ({"beta": -1.0}, "beta"),
        ({"m": 0.0}, "m"),
        ({"beta": "1"}, "beta"),
    ],
)
def test_invalid_params(kwargs: dict, field: str) -> None:
    with pytest.raises(ValueError, match=rf"PiecewiseParams\.{field} must"):
        PiecewiseParams(**kwargs)


def test_invalid_simulate_arguments() -> None:
    x = np.zeros((3, 2))
    with pytest.raises(ValueError, match="dt"):
        simulate_piecewise(QUIET, x, x, dt=0.0, steps=1)
    with pytest.raises(ValueError, match="steps"):
        simulate_piecewise(QUIET, x, x, dt=0.1, steps=-1)
    with pytest.raises(ValueError, match="PiecewiseParams"):
        simulate_piecewise(object(), x, x, dt=0.1, steps=1)  # type: ignore[arg-type]


# --------------------------------------------------------------------------- reproduction


def test_long_run_bounded_with_drag_and_dispersing_without() -> None:
    """docs/design.md: the report's model disperses; with drag a long run stays bounded."""
    rng = np.random.default_rng(0)
    n = 30
    x0 = rng.uniform(0, math.sqrt(3 * n), (2, n, 2))
    v0 = np.zeros_like(x0)
    no_drag = PiecewiseParams(r_0=5.0)
    xs, _ = simulate_piecewise(no_drag, x0, v0, dt=0.1, steps=500, rng=np.random.default_rng(1))
    e = metrics.expanse(xs)
    assert (e[-1] > 5 * e[0]).all() and (e[-1] > 1.3 * e[250]).all()
    drag = PiecewiseParams(r_0=5.0, beta=0.5)
    xs, _ = simulate_piecewise(drag, x0, v0, dt=0.02, steps=10000, rng=np.random.default_rng(1))
    e = metrics.expanse(xs[::50])  # every second for 200 s
    assert np.isfinite(e).all()
    # A plateau (the mean over the last 100 s within 25 % of that over 50–100 s) at a
    # few times the start, where the no-drag run reached ~100× the start.
    assert (e[100:].mean(axis=0) <= 1.25 * e[50:100].mean(axis=0)).all()
    assert (e.max(axis=0) < 3 * e[0]).all()


def test_reproduction_quick(tmp_path: Path) -> None:
    result = run(tmp_path, quick=True)
    assert set(result) >= {"paper", "setup", "results", "verdict", "findings", "t"}
    assert set(result["results"]) == {"report", "fixed", "small_dt", "drag"}
    assert isinstance(result["verdict"]["reproduced"], bool)
    assert isinstance(result["verdict"]["fixed"], bool)
    assert result["verdict"]["reproduced"]  # the dispersal shows even in 20 s
    saved = json.loads((tmp_path / "piecewise_dispersal.json").read_text())
    assert saved["verdict"] == result["verdict"]
    png = tmp_path / "piecewise_dispersal.png"
    assert png.stat().st_size > 5000
    for res in result["results"].values():
        for curve in res["r_0"].values():
            assert len(curve["expanse_mean"]) == len(result["t"])
            assert all(v is not None for v in curve["expanse_mean"])
    with pytest.raises(ValueError, match="seeds"):
        run(None, seeds=0, quick=True)
