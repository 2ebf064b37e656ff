"""Invariants of the zone model (Naterop §4.1, docs/models.md §3) and its table-3 reproduction."""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarm_envs import metrics
from swarm_envs.physics.zone import (
    ZoneAgentParams,
    ZoneParams,
    desired_direction,
    draw_agent_params,
    draw_informed,
    informed_count,
    neighbor_mask,
    simulate_zone,
    turn_toward,
    zone_step,
)

DET = dict(param_spread=0.0, informed_fraction=0.0)


def _random_state(seed: int, batch: tuple[int, ...], n: int, d: int = 2, box: float = 6.0):
    rng = np.random.default_rng(seed)
    x = rng.uniform(-box, box, (*batch, n, d))
    h = rng.standard_normal((*batch, n, d))
    return x, h / np.linalg.norm(h, axis=-1, keepdims=True)


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.arccos(np.clip(np.einsum("...k,...k->...", a, b), -1.0, 1.0))


@pytest.mark.parametrize("d", [2, 3])
def test_speed_constant_and_turn_bounded(d: int) -> None:
    p = ZoneParams.naterop(5.0, max_turn=math.radians(30))
    x0, h0 = _random_state(0, (2,), 20, d)
    xs, vs = simulate_zone(p, x0, h0, dt=0.1, steps=60, rng=np.random.default_rng(1))
    speeds = np.linalg.norm(vs, axis=-1)
    # Per-agent speeds (spread σ = 0.05) are constant in time.
    np.testing.assert_allclose(speeds, np.broadcast_to(speeds[0], speeds.shape), rtol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(xs[1:] - xs[:-1], axis=-1), 0.1 * speeds[1:])
    hs = vs / speeds[..., None]
    turn = _angle(hs[1:], hs[:-1])
    # The per-agent φ̄ spreads by 5 %: the turn never exceeds the agent's own limit.
    assert turn.max() <= math.radians(30) * (1 + 5 * 0.05) + 1e-9
    xs, vs = simulate_zone(ZoneParams(**DET, max_turn=0.2), x0, h0, dt=0.1, steps=60)
    np.testing.assert_allclose(np.linalg.norm(vs, axis=-1), 2.0, rtol=1e-12)
    hs = vs / 2.0
    assert _angle(hs[1:], hs[:-1]).max() <= 0.2 + 1e-9


def test_turn_toward_exact_in_2d() -> None:
    h = np.array([[1.0, 0.0]] * 4)
    d = np.array([[0.0, 1.0], [0.0, -1.0], [1.0, 0.1], [0.0, 0.0]])
    out = turn_toward(h, d, 0.3)
    np.testing.assert_allclose(out[0], [math.cos(0.3), math.sin(0.3)])
    np.testing.assert_allclose(out[1], [math.cos(0.3), -math.sin(0.3)])
    np.testing.assert_allclose(out[2], d[2] / np.linalg.norm(d[2]))  # within the limit
    np.testing.assert_allclose(out[3], h[3])  # no desire: keep heading
    h3 = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    out3 = turn_toward(h3, np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]]), 0.3)
    np.testing.assert_allclose(_angle(out3, h3), 0.3)
    np.testing.assert_allclose(out3[0], [math.cos(0.3), 0.0, math.sin(0.3)])


def test_repulsion_has_priority() -> None:
    # Agent 0 has one neighbour inside r_r (to its right) and many aligned neighbours
    # in the orientation zone heading up: it must head straight away from the close one.
    p = ZoneParams(r_r=1.0, r_o=5.0, r_a=10.0, **DET)
    x = np.array([[0.0, 0.0], [0.5, 0.0], [-3.0, 0.0], [0.0, 3.0], [0.0, -3.0], [8.0, 0.0]])
    h = np.tile([0.0, 1.0], (6, 1))
    d = desired_direction(x, h, p)
    np.testing.assert_allclose(d[0], [-1.0, 0.0], atol=1e-12)
    # Without the close neighbour, orientation + attraction take over.
    d2 = desired_direction(np.delete(x, 1, axis=0), np.delete(h, 1, axis=0), p)
    assert d2[0, 1] > 0.5


def test_orientation_aligns_group() -> None:
    p = ZoneParams(r_r=0.0, r_o=50.0, r_a=50.0, **DET)  # orientation only, all in range
    x, h = _random_state(3, (), 30, box=5.0)
    _, vs = simulate_zone(p, x, h, dt=0.1, steps=20)
    assert metrics.polarization(vs[0]) < 0.5
    assert metrics.polarization(vs[-1]) > 0.999


def test_attraction_pulls_pair_together() -> None:
    p = ZoneParams(r_r=1.0, r_o=1.0, r_a=30.0, speed=1.0, **DET)  # attraction only
    x = np.array([[0.0, 0.0], [10.0, 0.0]])
    h = np.array([[0.0, 1.0], [0.0, -1.0]])  # both moving sideways
    xs, _ = simulate_zone(p, x, h, dt=0.1, steps=40)
    gap = np.linalg.norm(xs[:, 1] - xs[:, 0], axis=-1)
    assert gap[-1] < 3.0 < gap[0]
    # Beyond r_a nobody is attracted: headings stay.
    _, vs = simulate_zone(ZoneParams(r_a=5.0, r_o=1.0, **DET), x, h, dt=0.1, steps=10)
    np.testing.assert_allclose(vs[-1], 2.0 * h)


def test_informed_agents_steer_to_goal() -> None:
    p = ZoneParams(omega=50.0, r_o=5.0, **DET)
    x, h = _random_state(4, (), 10)
    goal = np.array([40.0, 0.0])
    informed = np.zeros(10, dtype=bool)
    informed[:3] = True
    d = desired_direction(x, h, p, goal, informed)
    to_goal = (goal - x) / np.linalg.norm(goal - x, axis=-1, keepdims=True)
    assert (np.einsum("ik,ik->i", d[:3], to_goal[:3]) > 0.99).all()
    # Informed agents reach the goal in a full run; uninformed ones ignore it.
    rng = np.random.default_rng(0)
    q = ZoneParams.naterop(9.0, omega=50.0, informed_fraction=1.0)
    xs, _ = simulate_zone(q, x, h, dt=0.1, steps=300, goal=goal, rng=rng)
    assert np.linalg.norm(xs[-1] - goal, axis=-1).min() < 5.0
    xs, _ = simulate_zone(ZoneParams(**DET), x, h, dt=0.1, steps=300, goal=goal)
    assert np.linalg.norm(xs[-1] - goal, axis=-1).min() > 5.0


def test_lambda_nearest_limits_who_counts() -> None:
    # Agent 0 at the origin; agent 1 close, heading up; agents 2, 3 farther, heading down.
    x = np.array([[0.0, 0.0], [2.0, 0.0], [4.0, 0.0], [-4.0, 0.0]])
    h = np.array([[1.0, 0.0], [0.0, 1.0], [0.0, -1.0], [0.0, -1.0]])
    base = dict(r_r=1.0, r_o=10.0, r_a=10.0, **DET)
    np.testing.assert_allclose(
        desired_direction(x, h, ZoneParams(**base, n_neighbors=1))[0], [0, 1]
    )
    np.testing.assert_allclose(desired_direction(x, h, ZoneParams(**base))[0], [0, -1])
    rho = np.linalg.norm(x[:, None] - x[None], axis=-1)
    np.fill_diagonal(rho, np.inf)
    mask = neighbor_mask(rho, 2)
    assert (mask.sum(-1) == 2).all() and not mask.diagonal().any()


def test_seeded_determinism() -> None:
    p = ZoneParams.naterop(5.0)
    x, h = _random_state(5, (), 16)
    goal = np.array([20.0, 0.0])
    a = simulate_zone(
        p, x, np.zeros_like(h), dt=0.1, steps=30, goal=goal, rng=np.random.default_rng(7)
    )
    b = simulate_zone(
        p, x, np.zeros_like(h), dt=0.1, steps=30, goal=goal, rng=np.random.default_rng(7)
    )
    c = simulate_zone(
        p, x, np.zeros_like(h), dt=0.1, steps=30, goal=goal, rng=np.random.default_rng(8)
    )
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    assert not np.allclose(a[0], c[0])


def test_batched_equals_one_by_one() -> None:
    p = ZoneParams.naterop(9.0, n_neighbors=5)
    x, h = _random_state(6, (3,), 12)
    rng = np.random.default_rng(2)
    ap = draw_agent_params(p, rng, (3, 12))
    informed = draw_informed(p, rng, (3, 12))
    goal = np.array([[10.0, 0.0], [0.0, 10.0], [-5.0, -5.0]])
    xb, hb = x, h
    for _ in range(15):
        xb, hb = zone_step(xb, hb, p, dt=0.1, goal=goal, informed=informed, agent_params=ap)
    for i in range(3):
        xi, hi = x[i], h[i]
        api = ZoneAgentParams(*(a[i] for a in ap))
        for _ in range(15):
            xi, hi = zone_step(
                xi, hi, p, dt=0.1, goal=goal[i], informed=informed[i], agent_params=api
            )
        np.testing.assert_allclose(xb[i], xi, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(hb[i], hi, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"r_r": -1.0}, "r_r"),
        ({"r_o": 0.5}, "r_o"),
        ({"r_o": 20.0}, "r_o"),
        ({"r_a": 0.5, "r_o": 0.5, "r_r": 1.0}, "r_a"),
        ({"speed": 0.0}, "speed"),
        ({"max_turn": 4.0}, "max_turn"),
        ({"omega": float("nan")}, "omega"),
        ({"informed_fraction": 1.5}, "informed_fraction"),
        ({"param_spread": -0.1}, "param_spread"),
        ({"n_neighbors": 0}, "n_neighbors"),
        ({"n_neighbors": 2.5}, "n_neighbors"),
    ],
)
def test_invalid_params(kwargs: dict, field: str) -> None:
    with pytest.raises(ValueError, match=rf"ZoneParams\.{field}"):
        ZoneParams(**kwargs)


def test_rng_required_and_counts() -> None:
    x, h = _random_state(0, (), 5)
    with pytest.raises(ValueError, match="rng"):
        simulate_zone(ZoneParams(), x, h, dt=0.1, steps=2)
    with pytest.raises(ValueError, match="rng"):
        simulate_zone(ZoneParams(**DET), x, np.zeros_like(x), dt=0.1, steps=2)
    assert informed_count(ZoneParams(), 64) == 13
    mask = draw_informed(ZoneParams(), np.random.default_rng(0), (4, 64))
    assert (mask.sum(-1) == 13).all()


@pytest.mark.parametrize("d", [2, 3])
def test_coincident_agents_finite(d: int) -> None:
    x = np.zeros((4, d))
    h = np.zeros((4, d))
    h[:, 0] = 1.0
    xs, vs = simulate_zone(ZoneParams(**DET), x, h, dt=0.1, steps=5, goal=np.ones(d))
    assert np.isfinite(xs).all() and np.isfinite(vs).all()
    np.testing.assert_allclose(np.linalg.norm(vs, axis=-1), 2.0)
    x2, _ = _random_state(1, (), 6, d)
    x2[1] = x2[0]
    d_hat = desired_direction(x2, np.tile(h[:1], (6, 1)), ZoneParams(**DET))
    assert np.isfinite(d_hat).all()


def test_reproduction_quick() -> None:
    from swarm_envs.papers.naterop.zone import CONFIGURATIONS, run

    res = run(quick=True)
    assert set(res["verdict"]) == {name for name, _ in CONFIGURATIONS}
    for rows in res["tables"].values():
        assert [r["r_o"] for r in rows] == [r for _, r in CONFIGURATIONS]
        for r in rows:
            for key in ("polarization", "angular_momentum", "angular_momentum_raw", "expanse"):
                assert r[key] is not None and math.isfinite(r[key])
            assert 0.0 <= r["polarization"] <= 1.0
            assert r["verdict"] in {"reproduced", "partly reproduced", "not reproduced"}


def test_polarization_trend_with_orientation_radius() -> None:
    """Table 3's main trend, small: the r_o = 13 group is more polarized than r_o = 2."""
    rng = np.random.default_rng(0)
    n = 32
    side = math.sqrt(3 * n)
    x0 = rng.uniform(-side / 2, side / 2, (n, 2))
    ang = rng.uniform(0, 2 * np.pi, n)
    v0 = np.stack([np.cos(ang), np.sin(ang)], axis=-1)
    pol = {}
    for r_o in (2.0, 13.0):
        _, vs = simulate_zone(
            ZoneParams.naterop(r_o), x0, v0, dt=0.1, steps=300, rng=np.random.default_rng(1)
        )
        pol[r_o] = float(metrics.polarization(vs[-100:]).mean())
    assert pol[13.0] > 0.9 > 0.5 > pol[2.0]
