"""Fig. 11 of Mabrouk & McInnes: the statistics about the goal on hand-built swarms, the
exact decay law of the angular momentum about G under linear friction, and a short real
run of the self-propelled mill."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from swarm_envs.papers.claims import VERDICTS
from swarm_envs.papers.mabrouk_mcinnes import RunSetup, fig11_reproduction
from swarm_envs.papers.mabrouk_mcinnes.claims import fig11_mill_claims
from swarm_envs.papers.mabrouk_mcinnes.mill import (
    fig11_decay_law,
    fig11_self_propelled,
    goal_angular_momentum,
    goal_mean_radius,
    goal_tangential_speed,
    mill_params,
    rotating_start,
)
from swarm_envs.physics import SocialPotentialParams, simulate

G = np.array([20.0, 15.0])


def _ring(radius: float, speed: float, n: int = 12, sense: float = 1.0):
    theta = np.linspace(0.0, 2 * np.pi, n, endpoint=False) + 0.3
    radial = np.stack([np.cos(theta), np.sin(theta)], axis=-1)
    tangent = sense * np.stack([-np.sin(theta), np.cos(theta)], axis=-1)
    return G + radius * radial, speed * tangent, radial


@pytest.mark.parametrize(("radius", "speed"), [(0.27, 0.8), (2.0, 1.5), (5.0, 0.1)])
def test_ring_about_goal_has_l_equal_r_s_and_tangential_speed_s(radius: float, speed: float):
    x, v, radial = _ring(radius, speed)
    assert goal_angular_momentum(x, v, G) == pytest.approx(radius * speed, rel=1e-12)
    assert goal_tangential_speed(x, v, G) == pytest.approx(speed, rel=1e-12)
    assert goal_mean_radius(x, G) == pytest.approx(radius, rel=1e-12)
    # Clockwise: both change sign.
    xc, vc, _ = _ring(radius, speed, sense=-1.0)
    assert goal_angular_momentum(xc, vc, G) == pytest.approx(-radius * speed, rel=1e-12)
    assert goal_tangential_speed(xc, vc, G) == pytest.approx(-speed, rel=1e-12)
    # Moving radially (expanding): no rotation about G.
    assert abs(goal_angular_momentum(x, speed * radial, G)) < 1e-12
    assert abs(goal_tangential_speed(x, speed * radial, G)) < 1e-12


def test_goal_statistics_batch_shapes_agent_on_goal_and_bad_input():
    x, v, _ = _ring(1.0, 2.0, n=8)
    xb, vb = np.stack([x, x]), np.stack([v, -v])
    np.testing.assert_allclose(goal_angular_momentum(xb, vb, G), [2.0, -2.0], rtol=1e-12)
    np.testing.assert_allclose(goal_tangential_speed(xb, vb, G), [2.0, -2.0], rtol=1e-12)
    # An agent on G contributes 0 (no NaN): 8 ring agents plus one at G.
    x9, v9 = np.vstack([x, G]), np.vstack([v, [[1.0, 1.0]]])
    assert goal_tangential_speed(x9, v9, G) == pytest.approx(2.0 * 8 / 9, rel=1e-12)
    with pytest.raises(ValueError, match="positions"):
        goal_angular_momentum(np.zeros((4, 3)), np.zeros((4, 3)), G)
    with pytest.raises(ValueError, match="velocities"):
        goal_tangential_speed(x, v[:3], G)
    with pytest.raises(ValueError, match="goal"):
        goal_angular_momentum(x, v, (1.0, float("nan")))


def test_rotating_start_is_a_rigid_rotation_about_the_centroid():
    rng = np.random.default_rng(3)
    x0 = rng.normal(size=(2, 10, 2))
    v = rotating_start(x0, np.zeros_like(x0), 0.5)
    rel = x0 - x0.mean(axis=-2, keepdims=True)
    np.testing.assert_allclose((rel * v).sum(axis=-1), 0.0, atol=1e-15)  # tangential
    np.testing.assert_allclose(np.linalg.norm(v, axis=-1), 0.5 * np.linalg.norm(rel, axis=-1))
    np.testing.assert_allclose(v.sum(axis=-2), 0.0, atol=1e-14)  # no net momentum


@pytest.mark.parametrize("beta", [1.0, 0.1])
def test_angular_momentum_about_goal_decays_exactly_under_linear_friction(beta: float):
    """Pair forces and the sink are central: one semi-implicit Euler step multiplies L_G
    by 1 − β dt/m, to round-off, also for a swarm started with a rotation."""
    rng = np.random.default_rng(7)
    x0 = rng.uniform(-2, 2, size=(3, 12, 2))
    v0 = rotating_start(x0, rng.normal(scale=0.1, size=x0.shape), 0.5)
    params = replace(SocialPotentialParams.navigation(), beta=beta)
    dt, steps = 0.05, 200
    xs, vs = simulate(params, x0, v0, dt=dt, steps=steps, goal=G)
    lg = goal_angular_momentum(xs, vs, G)
    pred = lg[0] * (1.0 - beta * dt / params.m) ** np.arange(steps + 1)[:, None]
    scale = (np.linalg.norm(x0 - G, axis=-1) * np.linalg.norm(v0, axis=-1)).mean(-1)
    assert np.abs(lg - pred).max(axis=0).max() < 1e-13 * scale.min()
    assert np.all(np.abs(lg[0]) > 0.1)  # a real rotation, not a trivially small L_G


def test_decay_law_function_reports_the_law_to_round_off():
    setup = RunSetup(seeds=2)
    result = fig11_decay_law(setup=setup, duration=8.0, n_agents=10)
    assert [c["beta"] for c in result["cases"]] == [1.0, 0.1, 1.0]
    for case in result["cases"]:
        assert case["max_relative_error"] < 1e-6
        assert case["max_deviation_over_scale"] < 1e-12
        np.testing.assert_allclose(
            case["decay_rate_measured_per_seed"], case["decay_rate_expected"], rtol=1e-6
        )
        assert case["decay_rate_expected"] == pytest.approx(
            -math.log(1 - case["beta"] * setup.dt) / setup.dt
        )
        assert len(case["abs_L_per_seed"]) == 2
        assert len(case["abs_L_per_seed"][0]) == len(result["t"])
    (law,) = result["claims"]
    assert law["holds"] and not law["paper_form"]


def test_self_propelled_swarm_reaches_the_sink_and_holds_a_centred_mill():
    """A short real run (2 seeds, 160 time units): the Rayleigh term keeps the rotation
    that linear friction drains; the swarm ends in a mill centred on G."""
    result = fig11_self_propelled(setup=RunSetup(seeds=2), duration=160.0, snapshot_times=(0.0,))
    assert mill_params().cruise_speed == pytest.approx(1.0)
    hold = result["hold"]
    assert all(math.isfinite(a) for a in result["arrival_per_seed"])
    assert min(hold["tangential_speed_over_v0_min"]) > 0.5
    assert min(hold["L_G_over_R_v0_min"]) > 0.5
    assert max(hold["centroid_distance_over_R_max"]) < 0.25
    assert min(hold["milling_min"]) > 0.8
    # The held statistics are consistent: L_G ≈ R̄·v_t for a mill whose agents all
    # circle G (equal only for a single ring).
    for lg, r, vt in zip(
        hold["goal_angular_momentum"], hold["mean_radius"], hold["tangential_speed"], strict=True
    ):
        assert np.sign(lg) == np.sign(vt)
        assert 0.5 < lg / (r * vt) < 1.5
    counted = [c for c in result["claims"] if c["paper_form"]]
    assert len(counted) == 4 and all(c["holds"] for c in counted)
    assert result["verdict"] == "reproduced"


def test_mill_claims_fail_when_the_mill_is_off_centre_or_stops():
    good = {
        "tangential_speed_over_v0_min": [0.8, 0.8],
        "L_G_over_R_v0_min": [0.9, 0.9],
        "centroid_distance_over_R_max": [0.01, 0.01],
        "centroid_distance_max": [0.003, 0.003],
        "milling_min": [0.97, 0.97],
    }
    kw = {"goal_radius": 1.0, "duration": 100.0, "hold_from": 75.0}
    claims = fig11_mill_claims([30.0, 40.0], good, [0.1, 0.7], **kw)
    assert [c["holds"] for c in claims] == [True, True, True, True, False]
    assert [c["paper_form"] for c in claims] == [True, True, True, True, False]
    circling = good | {"centroid_distance_over_R_max": [0.01, 0.9], "milling_min": [0.97, 0.15]}
    held = [c["holds"] for c in fig11_mill_claims([30.0, 40.0], circling, [0.1, 0.7], **kw)]
    assert held[2:4] == [False, False]
    stopped = good | {"tangential_speed_over_v0_min": [0.8, -0.1]}
    assert not fig11_mill_claims([30.0, math.inf], stopped, [0.1, 0.7], **kw)[1]["holds"]
    assert not fig11_mill_claims([30.0, math.inf], good, [0.1, 0.7], **kw)[0]["holds"]


def test_fig11_reproduction_quick_structure():
    setup = RunSetup.quick()
    result = fig11_reproduction(
        setup=setup, duration=4.0, snapshot_times=(0.0, 2.0), decay_duration=2.0, n_agents=6
    )
    assert {"linear_friction", "decay_law", "self_propelled"} <= set(result)
    parts = {c["part"] for c in result["claims"]}
    assert parts == {"linear_friction", "decay_law", "self_propelled"}
    for c in result["claims"]:
        assert c["paper_form"] == (c["part"] == "linear_friction")
    assert result["verdict"] in VERDICTS
    assert result["self_propelled_verdict"] in VERDICTS
    assert np.asarray(result["self_propelled"]["snapshots"]["positions_seed0"]).shape == (2, 6, 2)
