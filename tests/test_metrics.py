"""Tests of swarm_envs.metrics: hand-computed cases, invariances, batching, dtypes, edges."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from swarm_envs import metrics
from swarm_envs.physics import SocialPotentialParams, energy

# ----------------------------------------------------------------------------- fixtures

SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
CUBE = np.array([[i, j, k] for i in (0.0, 1.0) for j in (0.0, 1.0) for k in (0.0, 1.0)])

# name -> function of (x, v); every statistic returning shape (...)
STATS: dict[str, Callable[[np.ndarray, np.ndarray], np.ndarray]] = {
    "polarization": lambda x, v: metrics.polarization(v),
    "velocity_polarization": lambda x, v: metrics.velocity_polarization(v),
    "spherical_variance": lambda x, v: metrics.spherical_variance(v),
    "angular_momentum": metrics.angular_momentum,
    "velocity_angular_momentum": metrics.velocity_angular_momentum,
    "raw_angular_momentum": metrics.raw_angular_momentum,
    "nearest_neighbor_distance": lambda x, v: metrics.nearest_neighbor_distance(x),
    "expanse": lambda x, v: metrics.expanse(x),
    "packing_density": lambda x, v: metrics.packing_density(x),
    "fraction_within": lambda x, v: metrics.fraction_within(x, np.zeros(x.shape[-1]), 1.0),
    "total_energy": lambda x, v: metrics.total_energy(x, v, SocialPotentialParams()),
}
# statistics that do not depend on where the origin is
TRANSLATION_INVARIANT = [k for k in STATS if k != "fraction_within"]


def ring(n: int, radius: float = 1.0, omega: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """``n`` agents on a circle of ``radius`` rotating rigidly at angular speed ``omega``."""
    theta = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    x = radius * np.stack([np.cos(theta), np.sin(theta)], axis=-1)
    v = omega * radius * np.stack([-np.sin(theta), np.cos(theta)], axis=-1)
    return x, v


def random_rotation(rng: np.random.Generator, d: int) -> np.ndarray:
    """A random orthogonal matrix (rotations and reflections alike)."""
    q, r = np.linalg.qr(rng.standard_normal((d, d)))
    return q * np.sign(np.diag(r))


def random_state(seed: int, shape: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.uniform(-3.0, 3.0, shape), rng.standard_normal(shape)


# ------------------------------------------------------------------- loop references


def ref_nnd(x: np.ndarray) -> float:
    n = len(x)
    if n == 1:
        return 0.0
    return float(
        np.mean([min(np.linalg.norm(x[i] - x[j]) for j in range(n) if j != i) for i in range(n)])
    )


def ref_cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    if len(a) == 2:
        return np.array(a[0] * b[1] - a[1] * b[0])
    return np.cross(a, b)


def ref_angular(x: np.ndarray, v: np.ndarray, unit_r: bool, unit_v: bool) -> float:
    rc = x.mean(axis=0)
    total = 0.0
    for xi, vi in zip(x, v, strict=True):
        r = xi - rc
        if unit_r:
            r = r / np.linalg.norm(r)
        if unit_v:
            vi = vi / np.linalg.norm(vi)
        total = total + ref_cross(r, vi)
    return float(np.linalg.norm(np.atleast_1d(total)) / len(x))


# ------------------------------------------------------------------- hand-computed cases


def test_centroid() -> None:
    np.testing.assert_allclose(metrics.centroid(SQUARE), [0.5, 0.5])
    np.testing.assert_allclose(metrics.centroid(CUBE), [0.5, 0.5, 0.5])
    assert metrics.centroid(np.zeros((3, 4, 5, 2))).shape == (3, 4, 2)


@pytest.mark.parametrize("d", [2, 3])
def test_polarization_aligned_and_opposite(d: int) -> None:
    e = np.eye(d)[0]
    aligned = np.array([1.0, 2.0, 0.5, 7.0])[:, None] * e  # same heading, different speeds
    assert metrics.polarization(aligned) == pytest.approx(1.0)
    assert metrics.spherical_variance(aligned) == pytest.approx(0.0)
    assert metrics.velocity_polarization(aligned) == pytest.approx(10.5 / 4)
    opposite = np.stack([e, -3.0 * e])
    assert metrics.polarization(opposite) == pytest.approx(0.0)
    assert metrics.spherical_variance(opposite) == pytest.approx(1.0)
    assert metrics.velocity_polarization(opposite) == pytest.approx(1.0)  # |1 − 3| / 2


def test_polarization_perpendicular_headings() -> None:
    v = np.array([[2.0, 0.0], [0.0, 5.0]])
    assert metrics.polarization(v) == pytest.approx(np.sqrt(2) / 2)
    assert metrics.velocity_polarization(v) == pytest.approx(np.hypot(2.0, 5.0) / 2)
    v3 = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    assert metrics.polarization(v3) == pytest.approx(np.sqrt(3) / 3)


def test_velocity_polarization_equals_polarization_for_unit_speeds() -> None:
    rng = np.random.default_rng(1)
    v = rng.standard_normal((5, 17, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    np.testing.assert_allclose(metrics.velocity_polarization(v), metrics.polarization(v))


def test_ring_rotating_rigidly() -> None:
    for omega in (0.7, -2.0):  # either sense of rotation
        x, v = ring(12, radius=2.0, omega=omega)
        assert metrics.angular_momentum(x, v) == pytest.approx(1.0)
        assert metrics.velocity_angular_momentum(x, v) == pytest.approx(abs(omega) * 2.0)
        assert metrics.raw_angular_momentum(x, v) == pytest.approx(abs(omega) * 4.0)
        assert metrics.polarization(v) == pytest.approx(0.0, abs=1e-12)
        assert metrics.spherical_variance(v) == pytest.approx(1.0)
        assert metrics.expanse(x) == pytest.approx(2.0)
        assert metrics.nearest_neighbor_distance(x) == pytest.approx(4.0 * np.sin(np.pi / 12))


def test_counter_rotating_halves_cancel() -> None:
    x, v = ring(8)
    v[::2] *= -1.0  # alternate agents go the other way round
    assert metrics.angular_momentum(x, v) == pytest.approx(0.0, abs=1e-12)
    assert metrics.raw_angular_momentum(x, v) == pytest.approx(0.0, abs=1e-12)


def test_translating_or_expanding_swarm_has_no_angular_momentum() -> None:
    x, _ = ring(10, radius=3.0)
    for v in (np.tile([1.0, 2.0], (10, 1)), 0.5 * x):  # translation, radial expansion
        assert metrics.angular_momentum(x, v) == pytest.approx(0.0, abs=1e-12)
        assert metrics.velocity_angular_momentum(x, v) == pytest.approx(0.0, abs=1e-12)
        assert metrics.raw_angular_momentum(x, v) == pytest.approx(0.0, abs=1e-12)


def test_ring_in_3d_tilted_plane() -> None:
    rng = np.random.default_rng(2)
    x2, v2 = ring(9, radius=1.5, omega=3.0)
    q = random_rotation(rng, 3)
    x = np.concatenate([x2, np.zeros((9, 1))], axis=-1) @ q.T + rng.uniform(-5, 5, 3)
    v = np.concatenate([v2, np.zeros((9, 1))], axis=-1) @ q.T
    assert metrics.angular_momentum(x, v) == pytest.approx(1.0)
    assert metrics.velocity_angular_momentum(x, v) == pytest.approx(4.5)
    assert metrics.raw_angular_momentum(x, v) == pytest.approx(6.75)
    assert metrics.expanse(x) == pytest.approx(1.5)


def test_square_and_cube_distances() -> None:
    assert metrics.nearest_neighbor_distance(SQUARE) == pytest.approx(1.0)
    assert metrics.expanse(SQUARE) == pytest.approx(np.sqrt(2) / 2)
    assert metrics.packing_density(SQUARE) == pytest.approx(np.sqrt(2) / 8)
    assert metrics.nearest_neighbor_distance(CUBE) == pytest.approx(1.0)
    assert metrics.expanse(CUBE) == pytest.approx(np.sqrt(3) / 2)
    assert metrics.packing_density(CUBE) == pytest.approx(np.sqrt(3) / 16)


def test_nnd_uneven_spacing() -> None:
    x = np.array([[0.0, 0.0], [1.0, 0.0], [4.0, 0.0]])
    assert metrics.nearest_neighbor_distance(x) == pytest.approx((1.0 + 1.0 + 3.0) / 3)


def test_expanse_is_not_the_extracted_eq6() -> None:
    # The extracted eq. 6, mean ||r_i| − |r_c||, would give 0 for a ring centred at the
    # origin; the text's definition (mean distance to the centre) gives the radius.
    x, _ = ring(6, radius=2.5)
    assert metrics.expanse(x) == pytest.approx(2.5)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("d", [2, 3])
def test_against_loop_references(seed: int, d: int) -> None:
    x, v = random_state(seed, (11, d))
    assert metrics.nearest_neighbor_distance(x) == pytest.approx(ref_nnd(x))
    assert metrics.angular_momentum(x, v) == pytest.approx(ref_angular(x, v, True, True))
    assert metrics.velocity_angular_momentum(x, v) == pytest.approx(ref_angular(x, v, True, False))
    assert metrics.raw_angular_momentum(x, v) == pytest.approx(ref_angular(x, v, False, False))
    unit = v / np.linalg.norm(v, axis=-1, keepdims=True)
    assert metrics.polarization(v) == pytest.approx(np.linalg.norm(unit.mean(axis=0)))
    expanse = np.mean(np.linalg.norm(x - x.mean(axis=0), axis=-1))
    assert metrics.expanse(x) == pytest.approx(expanse)


def test_planar_3d_equals_2d() -> None:
    x, v = random_state(3, (4, 2, 9, 2))
    x3 = np.concatenate([x, np.full((*x.shape[:-1], 1), 2.0)], axis=-1)
    v3 = np.concatenate([v, np.zeros((*v.shape[:-1], 1))], axis=-1)
    for name, f in STATS.items():
        if name in ("fraction_within", "total_energy"):
            continue
        np.testing.assert_allclose(f(x3, v3), f(x, v), rtol=1e-12, atol=1e-12, err_msg=name)


def test_total_energy_wraps_physics() -> None:
    x, v = random_state(4, (3, 7, 2))
    p = SocialPotentialParams.navigation()
    goal = np.array([1.0, -2.0])
    np.testing.assert_allclose(metrics.total_energy(x, v, p), energy(x, v, p))
    np.testing.assert_allclose(metrics.total_energy(x, v, p, goal), energy(x, v, p, goal))
    assert metrics.total_energy(x, v, p).shape == (3,)
    # two agents at rest a distance 1 apart: φ = U(1) = C_r e^{-1/l_r} − C_a e^{-1/l_a}
    p = SocialPotentialParams()
    two = np.array([[0.0, 0.0], [1.0, 0.0]])
    expected = 1.2 * np.exp(-5.0) - np.exp(-1.0)
    assert metrics.total_energy(two, np.zeros_like(two), p) == pytest.approx(expected)


def test_fraction_within() -> None:
    x = np.array([[0.0, 0.0], [1.0, 0.0], [3.0, 0.0], [0.0, -0.5]])
    assert metrics.fraction_within(x, [0.0, 0.0], 1.0) == pytest.approx(0.75)  # boundary in
    assert metrics.fraction_within(x, [0.0, 0.0], 0.0) == pytest.approx(0.25)
    assert metrics.fraction_within(x, [3.0, 0.0], 0.1) == pytest.approx(0.25)
    assert metrics.fraction_within(x, [100.0, 0.0], np.inf) == pytest.approx(1.0)
    # per-batch goals and radii broadcast against (..., d) and (...)
    xb = np.stack([x, x])
    goals = np.array([[0.0, 0.0], [3.0, 0.0]])
    np.testing.assert_allclose(metrics.fraction_within(xb, goals, 1.0), [0.75, 0.25])
    np.testing.assert_allclose(metrics.fraction_within(xb, [0.0, 0.0], [1.0, 0.0]), [0.75, 0.25])
    with pytest.raises(ValueError, match="radius"):
        metrics.fraction_within(x, [0.0, 0.0], -1.0)
    with pytest.raises(ValueError, match="radius"):
        metrics.fraction_within(x, [0.0, 0.0], np.nan)


# ------------------------------------------------------------------- first passage time


def test_first_passage_time_scalar_series() -> None:
    d = np.array([5.0, 3.0, 0.8, 0.2, 0.9])
    assert metrics.first_passage_time(d, 0.5, 1.0) == pytest.approx(1.0)
    assert metrics.first_passage_time(d, 0.5, 0.2) == pytest.approx(1.5)  # inclusive
    assert metrics.first_passage_time(d, 0.5, 5.0) == 0.0
    assert metrics.first_passage_time(d, 0.5, 3.0, below=False) == 0.0
    assert metrics.first_passage_time(-d, 0.5, -1.0, below=False) == pytest.approx(1.0)
    never = metrics.first_passage_time(d, 0.5, 0.1)
    assert np.isinf(never) and never > 0
    assert metrics.first_passage_time(d, 0.5, 6.0, below=False) == np.inf
    assert metrics.first_passage_time(np.array([np.nan, 2.0, 0.0]), 1.0, 1.0) == 2.0


def test_first_passage_time_batched_and_dtypes() -> None:
    values = np.array([[3.0, 3.0, 0.0], [2.0, 3.0, 0.0], [0.5, 3.0, 0.0]], dtype=np.float32)
    t = metrics.first_passage_time(values, 0.25, 1.0)
    assert t.dtype == np.float32 and t.shape == (3,)
    np.testing.assert_array_equal(t, np.array([0.5, np.inf, 0.0], dtype=np.float32))
    thresholds = np.array([2.0, 3.0, -1.0])  # one threshold per column
    np.testing.assert_array_equal(
        metrics.first_passage_time(values, 1.0, thresholds), [1, 0, np.inf]
    )
    counts = np.array([0, 1, 3, 2])  # integer series -> float64 times
    t = metrics.first_passage_time(counts, 2.0, 3, below=False)
    assert t.dtype == np.float64 and t == 4.0
    with pytest.raises(ValueError, match="dt"):
        metrics.first_passage_time(counts, 0.0, 1)
    with pytest.raises(ValueError, match="T >= 1"):
        metrics.first_passage_time(np.zeros((0, 3)), 1.0, 1.0)


def test_first_passage_time_navigation_uses() -> None:
    # Three agents moving at unit speed along x toward a goal at the origin, radius 0.5.
    dt, goal, radius = 0.5, np.zeros(2), 0.5
    x0 = np.array([[-2.0, 0.0], [-4.0, 0.0], [-6.0, 0.0]])
    ts = np.arange(21) * dt
    xs = x0[None] + ts[:, None, None] * np.array([1.0, 0.0])  # (T, N, d)
    # response time: first member within the radius (agent 0 at |x| = 0.5 at t = 1.5)
    first = np.linalg.norm(xs - goal, axis=-1).min(axis=-1)
    assert metrics.first_passage_time(first, dt, radius) == pytest.approx(1.5)
    # centroid (starts at −4) within the radius at t = 3.5
    centre = np.linalg.norm(metrics.centroid(xs) - goal, axis=-1)
    assert metrics.first_passage_time(centre, dt, radius) == pytest.approx(3.5)
    # all agents within the radius together: never (they pass the goal one by one)
    frac = metrics.fraction_within(xs, goal, radius)
    assert frac.shape == (21,)
    assert metrics.first_passage_time(frac, dt, 1.0, below=False) == np.inf
    assert metrics.first_passage_time(frac, dt, 1 / 3, below=False) == pytest.approx(1.5)


# ------------------------------------------------------------------- batching and dtypes


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("name", list(STATS))
def test_batch_equals_one_by_one(name: str, d: int) -> None:
    f = STATS[name]
    x, v = random_state(5, (3, 4, 6, d))
    batched = f(x, v)
    assert batched.shape == (3, 4)
    single = np.array([[f(x[a, b], v[a, b]) for b in range(4)] for a in range(3)])
    np.testing.assert_allclose(batched, single, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("name", list(STATS))
def test_float32_preserved(name: str) -> None:
    x, v = random_state(6, (2, 5, 3))
    x32, v32 = x.astype(np.float32), v.astype(np.float32)
    out = STATS[name](x32, v32)
    assert out.dtype == np.float32, name
    assert out.shape == (2,)
    np.testing.assert_allclose(out, STATS[name](x, v), rtol=1e-4, atol=1e-5)
    assert STATS[name](x, v).dtype == np.float64


def test_integer_input_becomes_float64() -> None:
    x = np.array([[0, 0], [1, 0], [1, 1], [0, 1]])
    assert metrics.nearest_neighbor_distance(x).dtype == np.float64
    assert metrics.polarization(x).dtype == np.float64
    assert metrics.angular_momentum(x, x).dtype == np.float64
    assert metrics.centroid(x).dtype == np.float64


def test_unbatched_returns_0d_array() -> None:
    x, v = random_state(7, (5, 2))
    for name, f in STATS.items():
        out = f(x, v)
        assert isinstance(out, np.ndarray) and out.shape == (), name


# ------------------------------------------------------------------- degenerate inputs


@pytest.mark.parametrize("d", [2, 3])
def test_all_zero_is_finite(d: int) -> None:
    x = np.zeros((2, 5, d))
    v = np.zeros((2, 5, d))
    for name, f in STATS.items():
        assert np.all(np.isfinite(f(x, v))), name
    np.testing.assert_array_equal(metrics.polarization(v), 0.0)
    np.testing.assert_array_equal(metrics.spherical_variance(v), 1.0)
    np.testing.assert_array_equal(metrics.angular_momentum(x, v), 0.0)
    np.testing.assert_array_equal(metrics.nearest_neighbor_distance(x), 0.0)
    np.testing.assert_array_equal(metrics.expanse(x), 0.0)


def test_resting_agents_contribute_zero_heading() -> None:
    v = np.array([[1.0, 0.0], [0.0, 0.0], [0.0, 0.0], [2.0, 0.0]])
    assert metrics.polarization(v) == pytest.approx(0.5)
    assert metrics.spherical_variance(v) == pytest.approx(0.5)
    x, vr = ring(4)
    vr[1] = 0.0
    assert metrics.angular_momentum(x, vr) == pytest.approx(0.75)


def test_coincident_agents() -> None:
    x = np.array([[0.0, 0.0], [0.0, 0.0], [3.0, 4.0]])
    v = np.array([[1.0, 0.0], [0.0, 1.0], [0.0, 0.0]])
    assert metrics.nearest_neighbor_distance(x) == pytest.approx(5.0 / 3)
    for name, f in STATS.items():
        assert np.isfinite(f(x, v)), name
    stack = np.zeros((4, 3))
    assert metrics.nearest_neighbor_distance(stack) == 0.0


def test_agent_at_centre_contributes_nothing() -> None:
    # A rotating ring plus an agent at the centre moving sideways: that agent has no r̂_ic,
    # so the unit form is 8/9, also after a translation that leaves its r_ic at rounding level.
    x, v = ring(8)
    x = np.concatenate([x, [[0.0, 0.0]]])
    v = np.concatenate([v, [[1.0, 0.0]]])
    for offset in (0.0, 0.3, 12.345, 1000.1, 1e5 / 3):
        for dtype in (np.float64, np.float32):
            xs, vs = (x + offset).astype(dtype), v.astype(dtype)
            assert metrics.angular_momentum(xs, vs) == pytest.approx(8 / 9, rel=1e-5)
            assert metrics.velocity_angular_momentum(xs, vs) == pytest.approx(8 / 9, rel=1e-5)


@pytest.mark.parametrize("d", [2, 3])
def test_single_agent(d: int) -> None:
    rng = np.random.default_rng(8)
    x, v = rng.standard_normal((1, d)), rng.standard_normal((1, d))
    assert metrics.nearest_neighbor_distance(x) == 0.0
    assert metrics.expanse(x) == 0.0
    assert metrics.packing_density(x) == 0.0
    assert metrics.polarization(v) == pytest.approx(1.0)
    assert metrics.polarization(np.zeros((1, d))) == 0.0
    assert metrics.velocity_polarization(v) == pytest.approx(np.linalg.norm(v))
    assert metrics.angular_momentum(x, v) == 0.0
    assert metrics.raw_angular_momentum(x, v) == 0.0
    np.testing.assert_allclose(metrics.centroid(x), x[0])
    assert metrics.nearest_neighbor_distance(np.zeros((3, 1, d))).shape == (3,)


def test_bad_shapes_raise() -> None:
    with pytest.raises(ValueError, match="N >= 1"):
        metrics.expanse(np.zeros((0, 2)))
    with pytest.raises(ValueError, match="d in"):
        metrics.polarization(np.zeros((5, 4)))
    with pytest.raises(ValueError, match="d in"):
        metrics.nearest_neighbor_distance(np.zeros(3))
    with pytest.raises(ValueError, match="shape"):
        metrics.angular_momentum(np.zeros((5, 2)), np.zeros((4, 2)))


# ------------------------------------------------------------------- invariances


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("seed", [10, 11])
def test_translation_invariance(seed: int, d: int) -> None:
    x, v = random_state(seed, (2, 8, d))
    shift = np.random.default_rng(seed).uniform(-50.0, 50.0, d)
    for name in TRANSLATION_INVARIANT:
        f = STATS[name]
        np.testing.assert_allclose(f(x + shift, v), f(x, v), rtol=1e-9, atol=1e-9, err_msg=name)


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("seed", [20, 21])
def test_rotation_invariance(seed: int, d: int) -> None:
    x, v = random_state(seed, (2, 8, d))
    q = random_rotation(np.random.default_rng(seed), d)
    goal = np.zeros(d)  # the origin is fixed by q, so fraction_within is invariant too
    for name, f in STATS.items():
        np.testing.assert_allclose(
            f(x @ q.T, v @ q.T), f(x, v), rtol=1e-9, atol=1e-12, err_msg=name
        )
    np.testing.assert_allclose(
        metrics.fraction_within(x @ q.T, goal, 2.0), metrics.fraction_within(x, goal, 2.0)
    )


def test_scaling() -> None:
    x, v = random_state(30, (3, 7, 2))
    a = 2.5
    np.testing.assert_allclose(metrics.expanse(a * x), a * metrics.expanse(x))
    np.testing.assert_allclose(
        metrics.nearest_neighbor_distance(a * x), a * metrics.nearest_neighbor_distance(x)
    )
    np.testing.assert_allclose(
        metrics.velocity_polarization(a * v), a * metrics.velocity_polarization(v)
    )
    np.testing.assert_allclose(
        metrics.raw_angular_momentum(a * x, a * v), a * a * metrics.raw_angular_momentum(x, v)
    )
    # the unit forms ignore each agent's speed and the swarm's size
    speeds = np.random.default_rng(30).uniform(0.1, 10.0, (3, 7, 1))
    np.testing.assert_allclose(metrics.polarization(speeds * v), metrics.polarization(v))
    np.testing.assert_allclose(
        metrics.angular_momentum(a * x, speeds * v), metrics.angular_momentum(x, v)
    )
    np.testing.assert_allclose(
        metrics.velocity_angular_momentum(a * x, a * v),
        a * metrics.velocity_angular_momentum(x, v),
    )


# ------------------------------------------------------------------- properties


def swarms(max_n: int = 8) -> st.SearchStrategy[tuple[np.ndarray, np.ndarray]]:
    """Random (x, v) pairs shaped (B, N, d) with moderate finite entries, zeros included."""

    @st.composite
    def build(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray]:
        shape = (
            draw(st.integers(1, 3)),
            draw(st.integers(1, max_n)),
            draw(st.sampled_from([2, 3])),
        )
        dtype = draw(st.sampled_from([np.float32, np.float64]))
        elements = st.floats(-1e3, 1e3, width=32)
        x = draw(arrays(dtype, shape, elements=elements))
        v = draw(arrays(dtype, shape, elements=elements))
        return x, v

    return build()


@settings(max_examples=60, deadline=None)
@given(swarms())
def test_unit_forms_bounded_and_finite(state: tuple[np.ndarray, np.ndarray]) -> None:
    x, v = state
    for name, f in STATS.items():
        out = f(x, v)
        assert out.shape == x.shape[:-2] and out.dtype == x.dtype, name
        assert np.all(np.isfinite(out)), name
    for out in (
        metrics.polarization(v),
        metrics.spherical_variance(v),
        metrics.angular_momentum(x, v),
        metrics.fraction_within(x, np.zeros(x.shape[-1]), 10.0),
    ):
        assert np.all((out >= 0) & (out <= 1))
    for name in ("velocity_polarization", "velocity_angular_momentum", "raw_angular_momentum"):
        assert np.all(STATS[name](x, v) >= 0), name
    np.testing.assert_allclose(
        metrics.polarization(v) + metrics.spherical_variance(v), 1.0, rtol=1e-6
    )


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 9), st.sampled_from([2, 3]))
def test_nnd_bounds(seed: int, n: int, d: int) -> None:
    x, _ = random_state(seed, (n, d))
    nnd = metrics.nearest_neighbor_distance(x)
    assert nnd == pytest.approx(ref_nnd(x))
    # every agent's nearest neighbour is no farther than the farthest pair
    diam = np.max(np.linalg.norm(x[:, None] - x[None], axis=-1))
    assert 0.0 <= nnd <= diam + 1e-12
