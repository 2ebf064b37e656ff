"""The physics' public interface: batching, dtypes, 3-D, coincident agents, bad input, control.

Coincident and extreme separations, bad input (a ``ValueError`` that names the problem
and the allowed range; docs/testing.md), and docs/design.md's interface
(``(..., N, d)`` arrays, frozen parameter dataclass, ``simulate`` returning ``steps + 1``
states).
"""

from __future__ import annotations

import dataclasses
import math
import re
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
import pytest

from swarm_envs.physics import (
    INTEGRATORS,
    SocialPotentialParams,
    energy,
    forces,
    pair_geometry,
    pair_potential,
    potential_energy,
    random_swarm,
    simulate,
    step,
    uniform_ball,
    verlet_step,
)
from swarm_envs.physics.integrators import implicit_damping_step

FIELDS = [f.name for f in dataclasses.fields(SocialPotentialParams)]
POSITIVE_FIELDS = {"l_a", "l_r", "l_o", "l_g", "m"}  # strictly positive; the rest >= 0
FULL = SocialPotentialParams(C_o=0.7, beta=0.4, C_g=3.0, l_g=2.0, m=1.5)


@contextmanager
def strict_numerics() -> Iterator[None]:
    """Fail on any warning and on divide-by-zero, invalid or overflow floating point events.

    Underflow (``exp(−1e6/l_r) → 0``) is the correct result and is allowed.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with np.errstate(divide="raise", invalid="raise", over="raise", under="ignore"):
            yield


# --------------------------------------------------------------------------- parameters


def test_defaults_are_the_papers_and_params_are_frozen() -> None:
    p = SocialPotentialParams()
    assert (p.C_a, p.C_r, p.l_a, p.l_r, p.C_o, p.l_o, p.beta, p.m) == (
        1.0,
        1.2,
        1.0,
        0.2,
        0.1,
        1.5,
        0.1,
        1.0,
    )
    assert p.C_g == 0.0
    assert p.range_ratio == pytest.approx(0.2)
    assert p.amplitude_ratio == pytest.approx(1.2)
    assert p.h_stability == pytest.approx(0.048)
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.C_a = 2.0  # type: ignore[misc]
    nav = SocialPotentialParams.navigation()
    assert (nav.C_g, nav.l_g, nav.C_o, nav.beta, nav.C_r) == (15.0, 5.0, 0.7, 1.0, 1.0)


def test_params_accept_numpy_and_int_scalars_as_float() -> None:
    p = SocialPotentialParams(C_a=np.float32(0.5), C_r=2, m=np.int64(3))
    assert type(p.C_a) is float and type(p.C_r) is float and type(p.m) is float
    assert (p.C_a, p.C_r, p.m) == (0.5, 2.0, 3.0)
    # Zero is allowed exactly for the amplitudes and β.
    SocialPotentialParams(C_a=0.0, C_r=0.0, C_o=0.0, beta=0.0, C_g=0.0)


BAD_VALUES: list[Any] = [-1.0, -1e-300, math.nan, math.inf, -math.inf, "1.0", None, True, [1.0]]


@pytest.mark.parametrize("name", FIELDS)
@pytest.mark.parametrize("bad", BAD_VALUES, ids=repr)
def test_invalid_parameter_raises_naming_field_and_range(name: str, bad: Any) -> None:
    allowed = "(0, inf)" if name in POSITIVE_FIELDS else "[0, inf)"
    with pytest.raises(ValueError) as info:
        SocialPotentialParams(**{name: bad})
    message = str(info.value)
    assert re.search(rf"\b{name}\b", message), message
    assert allowed in message, message


@pytest.mark.parametrize("name", sorted(POSITIVE_FIELDS))
def test_zero_length_or_mass_raises(name: str) -> None:
    with pytest.raises(ValueError, match=rf"{name}.*\(0, inf\)"):
        SocialPotentialParams(**{name: 0.0})


# --------------------------------------------------------------------------- bad input

X2 = np.random.default_rng(0).normal(size=(5, 2))


@pytest.mark.parametrize("dt", [0.0, -0.1, math.nan, math.inf, "0.1", None])
def test_simulate_invalid_dt_raises(dt: Any) -> None:
    with pytest.raises(ValueError, match=r"dt.*\(0, inf\)"):
        simulate(FULL, X2, np.zeros_like(X2), dt=dt, steps=3)


@pytest.mark.parametrize("steps", [-1, 1.5, "10", None, True, math.nan])
def test_simulate_invalid_steps_raises(steps: Any) -> None:
    with pytest.raises(ValueError, match=r"steps.*>= 0"):
        simulate(FULL, X2, np.zeros_like(X2), dt=0.1, steps=steps)


@pytest.mark.parametrize("name", ["rk4", "Velocity_Verlet", "", "euler"])
def test_simulate_unknown_integrator_raises(name: str) -> None:
    with pytest.raises(ValueError, match="integrator must be one of") as info:
        simulate(FULL, X2, np.zeros_like(X2), dt=0.1, steps=3, integrator=name)
    for known in INTEGRATORS:
        assert known in str(info.value)


def test_simulate_rejects_other_parameter_types() -> None:
    with pytest.raises(ValueError, match="SocialPotentialParams"):
        simulate({"C_a": 1.0}, X2, np.zeros_like(X2), dt=0.1, steps=3)  # type: ignore[arg-type]


BAD_SHAPES = {
    "d=1": (5, 1),
    "d=4": (5, 4),
    "1-D": (5,),
    "scalar": (),
}


@pytest.mark.parametrize("shape", list(BAD_SHAPES.values()), ids=list(BAD_SHAPES))
def test_bad_state_shapes_raise(shape: tuple[int, ...]) -> None:
    x = np.zeros(shape)
    for call in (
        lambda: forces(x, x, FULL),
        lambda: energy(x, x, FULL),
        lambda: potential_energy(x, FULL),
        lambda: simulate(FULL, x, x, dt=0.1, steps=2),
    ):
        with pytest.raises(ValueError, match=r"\(\.\.\., N, d\)"):
            call()


@pytest.mark.parametrize("v_shape", [(5, 3), (4, 2), (2, 5, 2), (5,)])
def test_mismatched_velocity_shape_raises(v_shape: tuple[int, ...]) -> None:
    v = np.zeros(v_shape)
    for call in (
        lambda: forces(X2, v, FULL),
        lambda: energy(X2, v, FULL),
        lambda: simulate(FULL, X2, v, dt=0.1, steps=2),
    ):
        with pytest.raises(ValueError, match="velocities shape"):
            call()


@pytest.mark.parametrize("goal", [np.zeros(3), np.zeros(1), np.float64(0.5), np.zeros((2, 3))])
def test_simulate_goal_of_wrong_dimension_raises(goal: np.ndarray) -> None:
    with pytest.raises(ValueError, match="goal"):
        simulate(FULL, X2, np.zeros_like(X2), dt=0.1, steps=2, goal=goal)


@pytest.mark.parametrize("goal", [np.zeros(3), np.zeros(1), np.float64(0.5)], ids=["3", "1", "()"])
def test_forces_and_energy_goal_of_wrong_dimension_raises(goal: np.ndarray) -> None:
    """A 2-D swarm with a goal that is not a 2-vector must not be silently broadcast."""
    for call in (
        lambda: forces(X2, np.zeros_like(X2), FULL, goal),
        lambda: energy(X2, np.zeros_like(X2), FULL, goal),
    ):
        with pytest.raises(ValueError):
            call()


# --------------------------------------------------------------------------- batching


@pytest.mark.parametrize("dim", [2, 3])
def test_batched_forces_and_energy_equal_per_swarm(dim: int) -> None:
    rng = np.random.default_rng(1)
    x, v = random_swarm(rng, 7, dim=dim, radius=1.5, speed=0.5, batch_shape=(4, 3))
    goals = rng.normal(size=(4, 3, dim))
    f = forces(x, v, FULL, goals)
    e = energy(x, v, FULL, goals)
    assert f.shape == (4, 3, 7, dim)
    assert e.shape == (4, 3)
    for i, j in np.ndindex(4, 3):
        np.testing.assert_allclose(f[i, j], forces(x[i, j], v[i, j], FULL, goals[i, j]), atol=1e-13)
        assert e[i, j] == pytest.approx(
            float(energy(x[i, j], v[i, j], FULL, goals[i, j])), abs=1e-12
        )
    # A single goal broadcasts to every swarm.
    g = np.array([0.5] * dim)
    np.testing.assert_allclose(
        forces(x, v, FULL, g), forces(x, v, FULL, np.broadcast_to(g, goals.shape))
    )


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_batched_simulate_equals_per_swarm(integrator: str) -> None:
    rng = np.random.default_rng(2)
    x0, v0 = random_swarm(rng, 6, radius=1.5, speed=0.5, batch_shape=(4, 3))
    goals = rng.normal(size=(4, 3, 2))
    xs, vs = simulate(FULL, x0, v0, dt=0.02, steps=25, goal=goals, integrator=integrator)
    assert xs.shape == vs.shape == (26, 4, 3, 6, 2)
    for i, j in np.ndindex(4, 3):
        xi, vi = simulate(
            FULL, x0[i, j], v0[i, j], dt=0.02, steps=25, goal=goals[i, j], integrator=integrator
        )
        np.testing.assert_allclose(xs[:, i, j], xi, atol=1e-12)
        np.testing.assert_allclose(vs[:, i, j], vi, atol=1e-12)
    # The swarms really differ (otherwise the comparison proves little).
    assert np.abs(xs[-1, 0, 0] - xs[-1, 1, 1]).max() > 0.1


# --------------------------------------------------------------------------- dtypes and 3-D


@pytest.mark.parametrize("dim", [2, 3])
def test_float32_in_float32_out_close_to_float64(dim: int) -> None:
    rng = np.random.default_rng(3)
    x, v = random_swarm(rng, 8, dim=dim, radius=1.5, speed=0.5)
    x32, v32 = x.astype(np.float32), v.astype(np.float32)
    goal = np.full(dim, 0.5, dtype=np.float32)

    f32 = forces(x32, v32, FULL, goal)
    assert f32.dtype == np.float32
    np.testing.assert_allclose(f32, forces(x, v, FULL, goal), rtol=1e-4, atol=1e-5)

    e32 = energy(x32, v32, FULL, goal)
    assert e32.dtype == np.float32
    assert float(e32) == pytest.approx(float(energy(x, v, FULL, goal)), rel=1e-5, abs=1e-5)

    for integrator in INTEGRATORS:
        xs32, vs32 = simulate(FULL, x32, v32, dt=0.02, steps=50, goal=goal, integrator=integrator)
        xs64, vs64 = simulate(FULL, x, v, dt=0.02, steps=50, goal=goal, integrator=integrator)
        assert xs32.dtype == vs32.dtype == np.float32
        np.testing.assert_allclose(xs32, xs64, atol=1e-4)
        np.testing.assert_allclose(vs32, vs64, atol=1e-4)


def test_float32_energy_with_plain_python_goal_stays_float32() -> None:
    """A goal given as a tuple of Python floats must not promote a float32 swarm."""
    rng = np.random.default_rng(4)
    x, v = random_swarm(rng, 5, radius=1.5, speed=0.5, dtype=np.float32)
    assert forces(x, v, FULL, (0.5, -0.5)).dtype == np.float32
    assert energy(x, v, FULL, (0.5, -0.5)).dtype == np.float32


def test_integer_input_becomes_float64() -> None:
    x = np.array([[0, 0], [1, 0], [0, 2]])
    assert forces(x, np.zeros_like(x), FULL).dtype == np.float64
    xs, _ = simulate(FULL, x, np.zeros_like(x), dt=0.1, steps=2)
    assert xs.dtype == np.float64


def test_three_dimensional_swarm_is_genuinely_3d() -> None:
    """Forces, energy and simulate work in 3-D, and a 3-D problem lying in a plane
    reproduces the 2-D result (the third coordinate is not ignored or mixed up)."""
    rng = np.random.default_rng(5)
    x2, v2 = random_swarm(rng, 6, radius=1.5, speed=0.5)
    goal2 = np.array([0.4, -0.2])
    # Embed the plane as (x, 0, y): tests that all three components are used consistently.
    embed = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    x3, v3, goal3 = x2 @ embed, v2 @ embed, goal2 @ embed
    np.testing.assert_allclose(
        forces(x3, v3, FULL, goal3), forces(x2, v2, FULL, goal2) @ embed, atol=1e-13
    )
    assert float(energy(x3, v3, FULL, goal3)) == pytest.approx(float(energy(x2, v2, FULL, goal2)))
    xs3, vs3 = simulate(FULL, x3, v3, dt=0.02, steps=40, goal=goal3)
    xs2, vs2 = simulate(FULL, x2, v2, dt=0.02, steps=40, goal=goal2)
    np.testing.assert_allclose(xs3, xs2 @ embed, atol=1e-12)
    np.testing.assert_allclose(vs3, vs2 @ embed, atol=1e-12)

    # A genuinely 3-D swarm: rotation invariance of energy and covariance of forces.
    x, v = random_swarm(rng, 6, dim=3, radius=1.5, speed=0.5)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    p = SocialPotentialParams(C_o=0.7, beta=0.4)
    np.testing.assert_allclose(forces(x @ q, v @ q, p), forces(x, v, p) @ q, atol=1e-12)
    assert float(energy(x @ q, v @ q, p)) == pytest.approx(float(energy(x, v, p)))
    assert np.abs(forces(x, v, p)[:, 2]).max() > 1e-3


# --------------------------------------------------------------------------- coincident agents


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("separation", [0.0, 1e-12, 1e6])
def test_coincident_and_extreme_separations_are_finite(dim: int, separation: float) -> None:
    rng = np.random.default_rng(6)
    x = rng.normal(size=(5, dim))
    x[1] = x[0]
    x[1, 0] += separation
    v = rng.normal(size=(5, dim))  # different velocities: exercises the alignment term
    goal = x[2].copy()  # an agent exactly on the goal
    with strict_numerics():
        f = forces(x, v, FULL, goal)
        e = energy(x, v, FULL, goal)
        xs, vs = simulate(FULL, x, v, dt=0.01, steps=10, goal=goal)
        xs_v, vs_v = simulate(
            FULL, x, v, dt=0.01, steps=10, goal=goal, integrator="velocity_verlet"
        )
    for arr in (f, e, xs, vs, xs_v, vs_v):
        assert np.all(np.isfinite(arr))


@pytest.mark.parametrize("separation", [0.0, 1e-12, 1e6])
def test_two_agent_pair_convention(separation: float) -> None:
    """Coincident pair: u_ij = 0 so no force, energy U(0) = C_r − C_a. Tiny separation: finite,
    antisymmetric, close to the ρ → 0 limit of the cohesion magnitude. Huge: zero."""
    p = SocialPotentialParams(C_o=0.0, beta=0.0)
    x = np.array([[0.3, -0.2], [0.3 + separation, -0.2]])
    v = np.zeros_like(x)
    with strict_numerics():
        f = forces(x, v, p)
        e = float(energy(x, v, p))
    np.testing.assert_allclose(f[0], -f[1], atol=1e-15)
    assert e == pytest.approx(float(pair_potential(np.array(separation), p)))
    if separation == 0.0:
        np.testing.assert_array_equal(f, 0.0)
        assert e == pytest.approx(p.C_r - p.C_a)
    elif separation == 1e-12:
        # Net repulsion at contact (negative: agent 0 is pushed away from agent 1 at +x).
        # 0.3 + 1e-12 − 0.3 is 1e-12 only to ~1e-4 relative, hence the tolerance.
        limit = p.C_a / p.l_a - p.C_r / p.l_r
        assert f[0, 0] == pytest.approx(limit, rel=1e-3)
    else:
        np.testing.assert_array_equal(f, 0.0)
        assert e == 0.0


# --------------------------------------------------------------------------- control


@pytest.mark.parametrize("integrator", INTEGRATORS)
@pytest.mark.parametrize("m", [1.0, 2.0])
def test_zero_control_equals_no_control(integrator: str, m: float) -> None:
    rng = np.random.default_rng(7)
    p = dataclasses.replace(FULL, m=m)
    x0, v0 = random_swarm(rng, 6, radius=1.5, speed=0.5)
    kwargs: dict[str, Any] = {
        "dt": 0.02,
        "steps": 30,
        "goal": np.zeros(2),
        "integrator": integrator,
    }
    ref = simulate(p, x0, v0, control=None, **kwargs)
    for control in (np.zeros_like(x0), np.zeros(2), lambda t, x, v: np.zeros_like(x)):
        got = simulate(p, x0, v0, control=control, **kwargs)
        np.testing.assert_array_equal(got[0], ref[0])
        np.testing.assert_array_equal(got[1], ref[1])
    np.testing.assert_array_equal(
        step(x0, v0, p, dt=0.02, control=np.zeros_like(x0))[1], step(x0, v0, p, dt=0.02)[1]
    )


@pytest.mark.parametrize("integrator", INTEGRATORS)
@pytest.mark.parametrize("m", [1.0, 2.5])
@pytest.mark.parametrize("dim", [2, 3])
def test_constant_control_gives_uniform_acceleration(integrator: str, m: float, dim: int) -> None:
    """N = 1, β = 0: v(t) = v0 + (u/m) t exactly for both schemes. Positions: Verlet is exact
    for constant acceleration; symplectic Euler gives x_n = x0 + n dt v0 + a dt² n(n+1)/2."""
    p = SocialPotentialParams(beta=0.0, C_o=0.9, m=m)
    u = np.array([[0.7, -1.3, 0.4][:dim]])
    a = u / m
    x0 = np.array([[0.1, 0.2, 0.3][:dim]])
    v0 = np.array([[-0.5, 0.25, 1.0][:dim]])
    dt, steps = 0.05, 40
    n = np.arange(steps + 1)[:, None, None]
    for control in (u, lambda t, x, v: u):
        xs, vs = simulate(p, x0, v0, dt=dt, steps=steps, control=control, integrator=integrator)
        np.testing.assert_allclose(vs, v0 + a * n * dt, atol=1e-12)
        if integrator == "velocity_verlet":
            expected = x0 + v0 * n * dt + 0.5 * a * (n * dt) ** 2
        else:
            expected = x0 + v0 * n * dt + a * dt**2 * n * (n + 1) / 2
        np.testing.assert_allclose(xs, expected, atol=1e-12)


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_callable_control_is_a_zero_order_hold(integrator: str) -> None:
    """The control function is called once per step with t = n dt and the state at the
    start of the step, and its value is held over the step: feeding the recorded values
    back as fixed per-step arrays reproduces the run."""
    rng = np.random.default_rng(8)
    x0, v0 = random_swarm(rng, 4, radius=1.0, speed=0.3)
    seen: list[tuple[float, np.ndarray, np.ndarray, np.ndarray]] = []

    def control(t: float, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        u = -0.5 * v + np.sin(t)
        seen.append((t, x.copy(), v.copy(), u))
        return u

    xs, vs = simulate(FULL, x0, v0, dt=0.1, steps=5, control=control, integrator=integrator)
    assert [t for t, *_ in seen] == pytest.approx([0.0, 0.1, 0.2, 0.3, 0.4])
    for (_, x_seen, v_seen, _), x_state, v_state in zip(seen, xs[:-1], vs[:-1], strict=True):
        np.testing.assert_array_equal(x_seen, x_state)
        np.testing.assert_array_equal(v_seen, v_state)
    x, v, f = x0, v0, forces(x0, v0, FULL)
    for n, (*_, u) in enumerate(seen):
        if integrator == "semi_implicit_euler":
            x, v = step(x, v, FULL, dt=0.1, control=u)
        elif integrator == "implicit_damping_euler":
            x, v = implicit_damping_step(x, v, FULL, dt=0.1, control=u)
        else:  # carry the passive force between steps, as simulate does
            x, v, f, _ = verlet_step(x, v, f, FULL, dt=0.1, control=u)
        np.testing.assert_allclose(x, xs[n + 1], atol=1e-14)
        np.testing.assert_allclose(v, vs[n + 1], atol=1e-14)


# --------------------------------------------------------------------------- step / simulate API


@pytest.mark.parametrize("m", [1.0, 2.0])
def test_step_matches_simulate_and_does_not_mutate(m: float) -> None:
    rng = np.random.default_rng(9)
    p = dataclasses.replace(FULL, m=m)
    x0, v0 = random_swarm(rng, 5, radius=1.5, speed=0.5)
    x_copy, v_copy = x0.copy(), v0.copy()
    goal = np.array([1.0, -1.0])
    u = rng.normal(size=x0.shape)
    x1, v1 = step(x0, v0, p, dt=0.03, goal=goal, control=u)
    xs, vs = simulate(p, x0, v0, dt=0.03, steps=1, goal=goal, control=u)
    np.testing.assert_array_equal(xs[1], x1)
    np.testing.assert_array_equal(vs[1], v1)
    # The defining formula of the scheme: v' = v + dt (F + u)/m, x' = x + dt v'.
    np.testing.assert_allclose(v1, v0 + 0.03 * (forces(x0, v0, p, goal) + u) / m, atol=1e-15)
    np.testing.assert_allclose(x1, x0 + 0.03 * v1, atol=1e-15)
    forces(x0, v0, p, goal)
    energy(x0, v0, p, goal)
    simulate(p, x0, v0, dt=0.03, steps=3, integrator="velocity_verlet")
    np.testing.assert_array_equal(x0, x_copy)
    np.testing.assert_array_equal(v0, v_copy)


@pytest.mark.parametrize("dim", [2, 3])
def test_precomputed_geometry_gives_the_same_forces_and_is_not_modified(dim: int) -> None:
    rng = np.random.default_rng(12)
    x, v = random_swarm(rng, 6, dim=dim, radius=1.5, speed=0.5, batch_shape=(2,))
    x[0, 1] = x[0, 0]  # a coincident pair: the floored distance must not leak into geometry
    goal = np.zeros(dim)
    geometry = pair_geometry(x)
    saved = ([c.copy() for c in geometry[0]], geometry[1].copy())
    np.testing.assert_array_equal(
        forces(x, v, FULL, goal, geometry=geometry), forces(x, v, FULL, goal)
    )
    np.testing.assert_array_equal(
        energy(x, v, FULL, goal, geometry=geometry), energy(x, v, FULL, goal)
    )
    for k in range(dim):
        np.testing.assert_array_equal(geometry[0][k], saved[0][k])
        # r_ij = r_j − r_i
        np.testing.assert_array_equal(geometry[0][k], x[..., None, :, k] - x[..., :, None, k])
    np.testing.assert_array_equal(geometry[1], saved[1])
    np.testing.assert_allclose(
        geometry[1], np.linalg.norm(x[..., None, :, :] - x[..., :, None, :], axis=-1), atol=1e-15
    )
    x1, v1 = step(x, v, FULL, dt=0.03, goal=goal, geometry=geometry)
    x2, v2 = step(x, v, FULL, dt=0.03, goal=goal)
    np.testing.assert_array_equal(x1, x2)
    np.testing.assert_array_equal(v1, v2)


@pytest.mark.parametrize("m", [1.0, 2.0])
def test_verlet_step_matches_simulate(m: float) -> None:
    rng = np.random.default_rng(13)
    p = dataclasses.replace(FULL, m=m)
    x0, v0 = random_swarm(rng, 5, radius=1.5, speed=0.5)
    goal = np.array([1.0, -1.0])
    u = rng.normal(size=x0.shape)
    xs, vs = simulate(
        p, x0, v0, dt=0.03, steps=3, goal=goal, control=u, integrator="velocity_verlet"
    )
    x, v, f = x0, v0, forces(x0, v0, p, goal)
    for n in range(3):
        v_prev = v
        x, v, f_new, geometry = verlet_step(x, v, f, p, dt=0.03, goal=goal, control=u)
        np.testing.assert_allclose(x, xs[n + 1], atol=1e-15)
        np.testing.assert_allclose(v, vs[n + 1], atol=1e-15)
        # Kick-drift-kick as documented, with the extrapolated velocity 2 v_½ − v_n.
        v_half = v_prev + 0.5 * 0.03 * (f + u) / m
        np.testing.assert_allclose(f_new, forces(x, 2.0 * v_half - v_prev, p, goal), atol=1e-14)
        np.testing.assert_allclose(v, v_half + 0.5 * 0.03 * (f_new + u) / m, atol=1e-14)
        np.testing.assert_allclose(geometry[1], pair_geometry(x)[1], atol=1e-15)
        f = f_new


def test_simulate_zero_steps_and_output_shapes() -> None:
    rng = np.random.default_rng(10)
    x0, v0 = random_swarm(rng, 5, dim=3, radius=1.0, speed=0.3, batch_shape=(2,))
    xs, vs = simulate(FULL, x0, v0, dt=0.1, steps=0)
    assert xs.shape == vs.shape == (1, 2, 5, 3)
    np.testing.assert_array_equal(xs[0], x0)
    np.testing.assert_array_equal(vs[0], v0)
    xs, vs = simulate(FULL, x0, v0, dt=0.1, steps=np.int64(7))
    assert xs.shape == (8, 2, 5, 3)


def test_initial_conditions_reproducible_and_inside_ball() -> None:
    a = random_swarm(np.random.default_rng(11), 50, dim=3, radius=2.0, speed=0.5)
    b = random_swarm(np.random.default_rng(11), 50, dim=3, radius=2.0, speed=0.5)
    c = random_swarm(np.random.default_rng(12), 50, dim=3, radius=2.0, speed=0.5)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    assert not np.array_equal(a[0], c[0])
    assert np.linalg.norm(a[0], axis=-1).max() <= 2.0
    assert np.linalg.norm(a[1], axis=-1).max() <= 0.5
    pts = uniform_ball(np.random.default_rng(13), (20000, 2), radius=1.0)
    # Uniform in the disk: P(|r| < 1/2) = 1/4.
    assert np.mean(np.linalg.norm(pts, axis=-1) < 0.5) == pytest.approx(0.25, abs=0.02)
    with pytest.raises(ValueError, match="n_agents"):
        random_swarm(np.random.default_rng(0), 0)
    with pytest.raises(ValueError, match="last dimension"):
        uniform_ball(np.random.default_rng(0), (3, 4), radius=1.0)
