"""Large swarms: the H-stable preset, density-preserving starts, relative goal distances."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from swarm_envs.config import SwarmConfig, load_swarm_config
from swarm_envs.envs.common import draw_starts
from swarm_envs.envs.cores.cutoff.core import (
    CutoffSwarmNavCore,
    density_preserving_radius,
    use_cutoff_core,
)
from swarm_envs.envs.cores.numpy import SwarmNavCore
from swarm_envs.physics import SocialPotentialParams

PRESET = SocialPotentialParams.large_swarm()
NAV = SocialPotentialParams.navigation()
BALL = {2: math.pi, 3: 4.0 * math.pi / 3.0}


# --------------------------------------------------------------------------- H-stability


def transform(p: SocialPotentialParams, k: np.ndarray, dim: int) -> np.ndarray:
    """``Û(k)``, the Fourier transform of the pair potential ``U(ρ) = C_r e^{−ρ/l_r} −
    C_a e^{−ρ/l_a}``, by quadrature of its radial integral (no closed form used):
    ``2π ∫ U(r) J_0(kr) r dr`` in 2-D, ``4π ∫ U(r) sin(kr)/(kr) r² dr`` in 3-D."""
    from scipy.special import j0

    r = np.linspace(0.0, 60.0 * max(p.l_a, p.l_r), 200_001)
    u = p.C_r * np.exp(-r / p.l_r) - p.C_a * np.exp(-r / p.l_a)
    kr = k[:, None] * r[None]
    if dim == 2:
        f = 2.0 * np.pi * u * j0(kr) * r
    else:
        f = 4.0 * np.pi * u * np.sinc(kr / np.pi) * r * r
    return np.trapezoid(f, r, axis=-1)


@pytest.mark.parametrize("dim", [2, 3])
def test_preset_is_h_stable_with_margin(dim: int) -> None:
    """C·l^d ≥ 2 with l < 1, and the potential's Fourier transform is positive at every
    k (the H-stability argument), where the navigation set's is negative at k = 0."""
    pytest.importorskip("scipy")
    assert PRESET.range_ratio < 1
    index = PRESET.h_stability if dim == 2 else PRESET.h_stability_3d
    assert index == pytest.approx(PRESET.amplitude_ratio * PRESET.range_ratio**dim)
    assert index >= 2.0
    k = np.concatenate([[0.0], np.geomspace(1e-3, 200.0, 60)])
    u_hat = transform(PRESET, k, dim)
    assert (u_hat > 0).all()
    closed = (2.0 * np.pi if dim == 2 else 8.0 * np.pi) * (
        PRESET.C_r * PRESET.l_r**dim - PRESET.C_a * PRESET.l_a**dim
    )
    assert u_hat[0] == pytest.approx(closed, rel=1e-6)  # ω-weighted (C_r l_r^d − C_a l_a^d)
    assert transform(NAV, k[:1], dim)[0] < 0  # the navigation set: catastrophic
    assert NAV.h_stability < 1 and NAV.h_stability_3d < 1


def test_preset_keeps_the_task_meaningful() -> None:
    """The analytic controller's largest sink force fits the default action bound, the
    shipped yaml uses the preset, and the repulsion is shorter-ranged than attraction."""
    cfg = SwarmConfig()
    assert cfg.u_max >= PRESET.C_g / PRESET.l_g
    assert PRESET.C_g > 0 and PRESET.C_o > 0 and PRESET.beta > 0
    assert PRESET.l_r < PRESET.l_a
    yaml = load_swarm_config("large_swarm")
    assert yaml.physics == PRESET
    assert yaml.u_max >= yaml.physics.C_g / yaml.physics.l_g
    assert yaml.init_density is not None and yaml.goal_distance_scale == "relative"


def passive_state(
    physics: SocialPotentialParams, n: int, dim: int, steps: int, density: float = 0.3
) -> tuple[float, float, float]:
    """``(mean NND, density from the expanse, mean substeps)`` after ``steps`` passive
    steps of ``dt = 0.1`` from a start at ``density`` (the density of a uniform ball of
    the same expanse, ``R = expanse (d + 1)/d``)."""
    cfg = SwarmConfig(n_agents=n, dim=dim, physics=physics, init_density=density, max_substeps=1000)
    core = (CutoffSwarmNavCore if n >= 500 else SwarmNavCore)(cfg)
    core.reset(np.random.default_rng(0))
    zero = np.zeros((1, n, dim))
    subs = []
    for _ in range(steps):
        *_, stats = core.step(zero)
        subs.append(stats["substeps"][0])
    radius = stats["expanse"][0] * (dim + 1) / dim
    return (
        float(stats["nearest_neighbor_distance"][0]),
        n / (BALL[dim] * radius**dim),
        float(np.mean(subs)),
    )


def bounded(states: list[tuple[float, float, float]]) -> bool:
    """The H-stability criterion on swarms of growing N: the spacing stays near the
    pair potential's minimum scale and the density stays bounded."""
    nnd = [s[0] for s in states]
    density = [s[1] for s in states]
    return min(nnd) > 0.8 * max(nnd) and min(nnd) > 1.0 and max(density) < 0.6


@pytest.mark.parametrize("dim", [2, 3])
def test_preset_spacing_and_density_stay_bounded_as_n_grows(dim: int) -> None:
    """Passive swarms of 50, 200 and 800 agents for 10 time units: the preset keeps
    its spacing (NND ≈ 1.5) and density, in one substep per step nearly always; the
    navigation set (C·l^d < 1) fails the same criterion."""
    states = [passive_state(PRESET, n, dim, steps=100) for n in (50, 200, 800)]
    assert bounded(states), states
    assert max(s[2] for s in states) < 1.3
    home = 10 / (BALL[dim] * 1.5**dim)  # the navigation set's default start density
    collapsing = [passive_state(NAV, n, dim, steps=60, density=home) for n in (50, 200)]
    assert not bounded(collapsing), collapsing
    assert min(s[2] for s in collapsing) > 2.0  # a stiffer state: more substeps


@pytest.mark.slow
@pytest.mark.parametrize("dim", [2, 3])
def test_preset_stays_bounded_up_to_ten_thousand_agents(dim: int) -> None:
    states = [passive_state(PRESET, n, dim, steps=100) for n in (100, 1000, 10_000)]
    assert bounded(states), states


# --------------------------------------------------------------------------- starts


@pytest.mark.parametrize("dim", [2, 3])
def test_init_density_sets_the_radius_law(dim: int) -> None:
    """``R = (N/(ω_d n))^{1/d}``: ∝ N^{1/d}, the draws fill that ball, and the density
    of N = 10 in radius 1.5 reproduces density_preserving_radius."""
    density = 0.3
    radii = {}
    for n in (10, 1000, 100_000):
        cfg = SwarmConfig(n_agents=n, dim=dim, init_density=density)
        radii[n] = cfg.start_radius
        assert radii[n] == pytest.approx((n / (BALL[dim] * density)) ** (1 / dim))
    assert radii[100_000] / radii[1000] == pytest.approx(100 ** (1 / dim))
    cfg = SwarmConfig(n_agents=2000, dim=dim, init_density=density)
    x, _, _ = draw_starts(cfg, np.random.default_rng(0), 2)
    r = np.linalg.norm(x, axis=-1)
    assert r.max() <= cfg.start_radius
    half = 0.5 * cfg.start_radius
    inner = (r <= half).sum(axis=-1) / (BALL[dim] * half**dim)
    np.testing.assert_allclose(inner, density, rtol=0.25)
    default = 10 / (BALL[dim] * 1.5**dim)
    big = SwarmConfig(n_agents=5000, dim=dim, init_density=default)
    assert big.start_radius == pytest.approx(density_preserving_radius(5000, dim))
    assert SwarmConfig(n_agents=5000, dim=dim).start_radius == 1.5  # None: init_radius


def test_relative_goal_distances_start_at_the_start_disc() -> None:
    base = dict(n_agents=5000, init_density=0.3, goal_distance_min=8.0, goal_distance_max=12.0)
    rel = SwarmConfig(**base, goal_distance_scale="relative")
    _, _, goal = draw_starts(rel, np.random.default_rng(0), 200)
    beyond = np.linalg.norm(goal, axis=-1) - rel.start_radius
    assert beyond.min() >= 8.0 and beyond.max() <= 12.0 and beyond.max() - beyond.min() > 3
    absolute = SwarmConfig(**base)
    assert absolute.goal_distance_scale == "absolute"
    x_a, v_a, g_a = draw_starts(absolute, np.random.default_rng(0), 200)
    x_r, v_r, g_r = draw_starts(rel, np.random.default_rng(0), 200)
    np.testing.assert_array_equal(x_a, x_r)  # the same draws, only the distance moves
    np.testing.assert_array_equal(v_a, v_r)
    np.testing.assert_allclose(
        np.linalg.norm(g_r, axis=-1) - np.linalg.norm(g_a, axis=-1), rel.start_radius
    )
    small = SwarmConfig(goal_distance_scale="relative")  # from init_radius 1.5
    _, _, g = draw_starts(small, np.random.default_rng(1), 50)
    assert np.linalg.norm(g, axis=-1).min() >= 9.5


def test_start_options_are_validated() -> None:
    for bad in (0.0, -1.0, math.nan, math.inf, "dense", True):
        with pytest.raises(ValueError, match="init_density"):
            SwarmConfig(init_density=bad)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"init_density \(0.3\) and init_radius"):
        SwarmConfig(init_density=0.3, init_radius=4.0)
    with pytest.raises(ValueError, match="init_density must be None with dynamics='lagrangian'"):
        SwarmConfig(init_density=0.3, dynamics="lagrangian")
    with pytest.raises(ValueError, match=r"goal_distance_scale must be one of \('absolute'"):
        SwarmConfig(goal_distance_scale="edge")
    with pytest.raises(ValueError, match="init_density"):
        load_swarm_config("large_swarm", {"init_density": -2.0})
    cfg = load_swarm_config("large_swarm", {"init_density": None, "init_radius": 4.0})
    assert cfg.start_radius == 4.0


@pytest.mark.parametrize("n", [10, 100_000])
def test_one_yaml_for_ten_and_a_hundred_thousand_agents(n: int) -> None:
    """The same file: the start density and the goal's distance beyond the start disc
    do not depend on N; one step runs on the core picked for N, in few substeps."""
    cfg = load_swarm_config("large_swarm", {"n_agents": n})
    assert cfg.n_agents / (math.pi * cfg.start_radius**2) == pytest.approx(cfg.init_density)
    core = (CutoffSwarmNavCore if use_cutoff_core(cfg) else SwarmNavCore)(cfg)
    assert use_cutoff_core(cfg) == (n > 1000)
    core.reset(np.random.default_rng(0))
    beyond = np.linalg.norm(core.goal, axis=-1) - cfg.start_radius
    assert 8.0 <= beyond.min() and beyond.max() <= 12.0
    *_, stats = core.step(np.zeros((1, n, 2)))
    assert all(np.isfinite(v).all() for v in stats.values())
    assert 1 <= stats["substeps"][0] <= 4
    assert stats["nearest_neighbor_distance"][0] > 0.5


def test_config_replace_keeps_the_density() -> None:
    cfg = load_swarm_config("large_swarm")
    bigger = dataclasses.replace(cfg, n_agents=8 * cfg.n_agents)
    assert bigger.start_radius == pytest.approx(cfg.start_radius * math.sqrt(8))
