"""``physics.simulate`` dispatches on the parameter type to each model's simulator."""

from __future__ import annotations

import numpy as np
import pytest

from swarm_envs.physics import (
    LagrangianParams,
    PiecewiseParams,
    ZoneParams,
    random_swarm,
    simulate,
    simulate_lagrangian,
    simulate_piecewise,
    simulate_zone,
)

CASES = [
    (ZoneParams(), simulate_zone),
    (PiecewiseParams(), simulate_piecewise),
    (LagrangianParams(r=0.1), simulate_lagrangian),
]


@pytest.mark.parametrize(("params", "own"), CASES, ids=lambda c: type(c).__name__)
def test_simulate_equals_the_models_own_simulator(params, own):
    x0, v0 = random_swarm(np.random.default_rng(0), 8, radius=5.0, speed=1.0)
    goal = np.array([20.0, 0.0])
    got = simulate(params, x0, v0, dt=0.05, steps=6, goal=goal, rng=np.random.default_rng(3))
    want = own(params, x0, v0, dt=0.05, steps=6, goal=goal, rng=np.random.default_rng(3))
    for a, b in zip(got, want, strict=True):
        assert a.shape == (7, 8, 2)
        np.testing.assert_array_equal(a, b)


def test_unknown_parameter_type_names_the_known_ones():
    x0 = np.zeros((3, 2))
    with pytest.raises(ValueError, match="expected one of SocialPotentialParams, ZoneParams"):
        simulate(object(), x0, x0, dt=0.1, steps=1)


def test_control_and_integrator_are_social_potential_only():
    x0, v0 = random_swarm(np.random.default_rng(0), 4, radius=5.0, speed=1.0)
    with pytest.raises(ValueError, match="apply to SocialPotentialParams only"):
        simulate(PiecewiseParams(), x0, v0, dt=0.1, steps=1, control=np.zeros_like(x0))
    with pytest.raises(ValueError, match="apply to SocialPotentialParams only"):
        simulate(PiecewiseParams(), x0, v0, dt=0.1, steps=1, integrator="velocity_verlet")
