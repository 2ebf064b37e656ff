"""CutoffSwarmNavCore: the dense core's interface and trajectory, without (B, N, N) arrays."""

from __future__ import annotations

import dataclasses
import pickle

import numpy as np
import pytest

from swarm_envs.config import SwarmConfig
from swarm_envs.envs.common import SwarmUnstableError
from swarm_envs.envs.cores.cutoff import core as cutoff_core
from swarm_envs.envs.cores.cutoff.core import (
    CUTOFF_MIN_AGENTS,
    DEFAULT_CUTOFF_SPEED,
    DEFAULT_CUTOFF_TOL,
    CutoffSwarmNavCore,
    density_preserving_radius,
)
from swarm_envs.envs.cores.numpy import SwarmNavCore
from swarm_envs.envs.task import OBS_BOUND, STAT_KEYS
from swarm_envs.physics import SocialPotentialParams, forces
from swarm_envs.physics.cutoff import cutoff_radius, force_error_bound

TINY = 1e-12  # cut-off tolerance at which no pair of a small swarm is dropped


def run_both(
    cfg: SwarmConfig,
    batch: int,
    steps: int,
    seed: int = 0,
    ties_at_start: bool = False,
    **cutoff_kwargs: float,
) -> float:
    """Step both cores with the same actions and resets; the largest difference seen.

    ``ties_at_start``: agents start at equal distances, where either core may order
    equally near neighbours differently: the first observations are compared as sets.
    """
    dense = SwarmNavCore(cfg, batch=batch)
    cut = CutoffSwarmNavCore(cfg, batch=batch, **cutoff_kwargs)
    rng_d, rng_c = np.random.default_rng(seed), np.random.default_rng(seed)
    dense.reset(rng_d)
    cut.reset(rng_c)
    assert rng_d.bit_generator.state == rng_c.bit_generator.state  # the same draws
    obs_d, obs_c = dense.observe(), cut.observe()
    if ties_at_start:
        k, d = cfg.n_neighbors, 2 * cfg.dim + 1
        obs_d = np.sort(obs_d[..., 2 * cfg.dim :].reshape(batch, -1, k, d), axis=-2)
        obs_c = np.sort(obs_c[..., 2 * cfg.dim :].reshape(batch, -1, k, d), axis=-2)
    worst = max(
        np.abs(obs_d - obs_c).max(),
        max(np.abs(dense.stats()[k] - cut.stats()[k]).max() for k in STAT_KEYS),
    )
    actions = np.random.default_rng(seed + 1)
    n, d = cfg.n_agents, cfg.dim
    for t in range(steps):
        a = actions.uniform(-1.2, 1.2, (batch, n, d))  # some clipped
        if t % 7 == 3:
            a[:] = 0.0  # the passive path (no control)
        out_d, out_c = dense.step(a), cut.step(a)
        for arr_d, arr_s in zip(out_d[:3], out_c[:3], strict=True):
            worst = max(worst, np.abs(arr_d.astype(float) - arr_s.astype(float)).max())
        for k in STAT_KEYS:
            worst = max(worst, np.abs(out_d[3][k] - out_c[3][k]).max())
        worst = max(
            worst,
            np.abs(dense.x - cut.x).max(),
            np.abs(dense.v - cut.v).max(),
            np.abs(dense.observe() - cut.observe()).max(),
        )
        np.testing.assert_array_equal(dense.t, cut.t)
        if t == steps // 2 and batch > 1:  # a partial reset, as the vector env does
            which = np.arange(batch) % 2 == 0
            dense.reset(rng_d, which)
            cut.reset(rng_c, which)
    return float(worst)


@pytest.mark.parametrize("integrator", ["semi_implicit_euler", "velocity_verlet"])
@pytest.mark.parametrize("goal_in_physics", [False, True])
def test_follows_the_dense_trajectory(integrator: str, goal_in_physics: bool) -> None:
    cfg = SwarmConfig(
        n_agents=50,
        integrator=integrator,
        goal_in_physics=goal_in_physics,
        init_radius=2.0,
        collision_radius=0.2,
    )
    assert run_both(cfg, batch=3, steps=30, cutoff_tol=TINY) < 1e-9


def test_follows_the_dense_trajectory_3d_float32() -> None:
    cfg = SwarmConfig(n_agents=30, dim=3, n_neighbors=4, init_radius=1.0)
    dense = SwarmNavCore(cfg, batch=2, dtype=np.float32)
    cut = CutoffSwarmNavCore(cfg, batch=2, dtype=np.float32, cutoff_tol=TINY)
    dense.reset(np.random.default_rng(3))
    cut.reset(np.random.default_rng(3))
    a = np.random.default_rng(4).uniform(-1, 1, (2, 30, 3))
    for _ in range(10):
        dense.step(a)
        cut.step(a)
    assert cut.x.dtype == np.float32
    np.testing.assert_allclose(cut.x, dense.x, atol=1e-4)
    for k, value in cut.stats().items():
        np.testing.assert_allclose(value, dense.stats()[k], rtol=1e-4, atol=1e-4, err_msg=k)


def test_collisions_and_padding_match_dense() -> None:
    """A crowded start (many collisions) and fewer agents than neighbour slots."""
    crowded = SwarmConfig(n_agents=40, init_radius=0.4, collision_radius=0.15)
    assert run_both(crowded, batch=2, steps=5, cutoff_tol=TINY) < 1e-9
    cut = CutoffSwarmNavCore(crowded, cutoff_tol=TINY)
    cut.reset(np.random.default_rng(0))
    assert cut.stats()["collisions"][0] > 10
    few = SwarmConfig(n_agents=3, n_neighbors=6)
    assert run_both(few, batch=2, steps=4, cutoff_tol=TINY) < 1e-9
    one = SwarmConfig(n_agents=1)
    assert run_both(one, batch=2, steps=3, cutoff_tol=TINY) < 1e-12


def test_coincident_start_gives_no_nan() -> None:
    """All agents start on one point (init_radius = 0): no NaN, and the dense result."""
    cfg = SwarmConfig(n_agents=12, init_radius=0.0, collision_radius=0.05)
    core = CutoffSwarmNavCore(cfg, batch=2)
    core.reset(np.random.default_rng(0))
    stats = core.stats()
    assert stats["collisions"][0] == 66 and stats["nearest_neighbor_distance"][0] == 0.0
    assert np.isfinite(core.observe()).all()
    assert all(np.isfinite(value).all() for value in stats.values())
    assert run_both(cfg, batch=2, steps=5, ties_at_start=True, cutoff_tol=TINY) < 1e-9


def test_collision_count_is_exact_with_a_wide_collision_radius() -> None:
    cfg = SwarmConfig(n_agents=60, init_radius=4.0, collision_radius=6.0)
    cut = CutoffSwarmNavCore(cfg, cutoff_tol=0.5)  # r_c < collision_radius
    assert cut.cutoff < cfg.collision_radius
    cut.reset(np.random.default_rng(2))
    x = cut.x[0]
    rho = np.linalg.norm(x[:, None] - x[None], axis=-1)
    assert cut.stats()["collisions"][0] == np.triu(rho < 6.0, 1).sum()


def test_interface_shapes_and_dtypes() -> None:
    cfg = SwarmConfig(n_agents=12, n_neighbors=3)
    core = CutoffSwarmNavCore(cfg, batch=4)
    assert core.cfg is cfg and core.batch == 4
    assert core.x.shape == core.v.shape == (4, 12, 2) and core.goal.shape == (4, 2)
    assert core.t.shape == (4,) and core.obs_dim == 4 + 3 * 5
    core.reset(np.random.default_rng(0))
    obs = core.observe()
    assert obs.shape == (4, 12, core.obs_dim) and obs.dtype == np.float32
    assert np.abs(obs).max() <= OBS_BOUND
    reward, terminated, truncated, stats = core.step(np.zeros((4, 12, 2), np.float32))
    assert reward.shape == terminated.shape == truncated.shape == (4,)
    assert terminated.dtype == truncated.dtype == np.bool_
    assert tuple(stats) == STAT_KEYS and all(s.shape == (4,) for s in stats.values())
    assert core.stats().keys() == stats.keys()
    np.testing.assert_array_equal(core.t, 1)
    core.step(np.zeros(4 * 12 * 2))  # flat actions are reshaped like the dense core's


def test_reset_draws_like_the_dense_core() -> None:
    cfg = SwarmConfig(n_agents=20, dim=3)
    dense, cut = SwarmNavCore(cfg, batch=3), CutoffSwarmNavCore(cfg, batch=3)
    for which in (None, np.array([False, True, True]), np.zeros(3, bool)):
        rd, rs = np.random.default_rng(9), np.random.default_rng(9)
        dense.reset(rd, which)
        cut.reset(rs, which)
        assert rd.bit_generator.state == rs.bit_generator.state
        np.testing.assert_array_equal(dense.x, cut.x)
        np.testing.assert_array_equal(dense.v, cut.v)
        np.testing.assert_array_equal(dense.goal, cut.goal)


def test_cutoff_error_per_step_within_the_bound() -> None:
    """At the default tolerance, the passive force differs from the dense one within the bound."""
    n = 400
    cfg = SwarmConfig(n_agents=n, init_radius=density_preserving_radius(n))
    core = CutoffSwarmNavCore(cfg)
    assert core.cutoff == pytest.approx(cutoff_radius(cfg.physics, DEFAULT_CUTOFF_TOL))
    core.reset(np.random.default_rng(0))
    a = np.random.default_rng(1).uniform(-1, 1, (1, n, 2))
    for _ in range(3):
        core.step(a)
    x, v = core.x, core.v
    w = float(np.linalg.norm(v[0, :, None] - v[0, None], axis=-1).max())
    carried = core._f_passive  # the passive force at (x, v), carried to the next step
    err = np.linalg.norm(carried - forces(x, v, cfg.physics), axis=-1)
    bound = force_error_bound(cfg.physics, core.cutoff, speed=w, n_agents=n)
    assert 0 < err.max() <= bound


def test_cutoff_follows_a_replaced_config() -> None:
    core = CutoffSwarmNavCore(SwarmConfig())
    first = core.cutoff
    core.cfg = dataclasses.replace(core.cfg, max_steps=7)  # as the PettingZoo env does
    assert core.cutoff == first
    core.cfg = dataclasses.replace(core.cfg, physics=dataclasses.replace(core.cfg.physics, l_o=3.0))
    assert core.cutoff > first


def test_density_preserving_radius() -> None:
    assert density_preserving_radius(10) == pytest.approx(1.5)
    assert density_preserving_radius(100_000) == pytest.approx(150.0)
    assert density_preserving_radius(80, dim=3) == pytest.approx(3.0)
    assert density_preserving_radius(40, radius=2.0, agents=10) == pytest.approx(4.0)
    with pytest.raises(ValueError, match="n_agents"):
        density_preserving_radius(0)
    with pytest.raises(ValueError, match="dim"):
        density_preserving_radius(10, dim=4)


def test_constants() -> None:
    assert isinstance(CUTOFF_MIN_AGENTS, int) and CUTOFF_MIN_AGENTS > 10
    assert DEFAULT_CUTOFF_TOL > 0 and DEFAULT_CUTOFF_SPEED >= 0


def test_invalid_input_raises() -> None:
    cfg = SwarmConfig(n_agents=5)
    for bad in (0.0, -1.0, np.nan):
        with pytest.raises(ValueError, match="cutoff_tol"):
            CutoffSwarmNavCore(cfg, cutoff_tol=bad)
    with pytest.raises(ValueError, match="cutoff_speed"):
        CutoffSwarmNavCore(cfg, cutoff_speed=-1.0)
    for batch in (0, 1.5, True):
        with pytest.raises(ValueError, match="batch"):
            CutoffSwarmNavCore(cfg, batch=batch)  # type: ignore[arg-type]
    core = CutoffSwarmNavCore(cfg)
    with pytest.raises(ValueError, match="before reset"):
        core.step(np.zeros((1, 5, 2)))
    core.reset(np.random.default_rng(0))
    with pytest.raises(ValueError, match="shape"):
        core.step(np.zeros((1, 4, 2)))
    with pytest.raises(ValueError, match="finite"):
        core.step(np.full((1, 5, 2), np.nan))
    if "dynamics" in {f.name for f in dataclasses.fields(SwarmConfig)}:
        with pytest.raises(ValueError, match="social_potential"):
            CutoffSwarmNavCore(dataclasses.replace(cfg, dynamics="zone"))


def test_large_swarm_step() -> None:
    """20,000 agents at the default start density: one step, no (N, N) array."""
    n = 20_000
    cfg = SwarmConfig(n_agents=n, init_radius=density_preserving_radius(n))
    core = CutoffSwarmNavCore(cfg)
    core.reset(np.random.default_rng(0))
    reward, *_, stats = core.step(np.random.default_rng(1).uniform(-1, 1, (1, n, 2)))
    obs = core.observe()
    assert obs.shape == (1, n, core.obs_dim) and np.isfinite(obs).all()
    assert np.isfinite(reward).all() and all(np.isfinite(s).all() for s in stats.values())
    assert 0.3 < stats["nearest_neighbor_distance"][0] < 0.6  # ≈ 0.5 / √1.41 for a Poisson cloud


def test_look_ahead_neighbour_search_changes_nothing(monkeypatch) -> None:
    """From KNN_AHEAD_MIN_AGENTS agents the k-NN runs in a worker during the pair pass:
    the same observations and statistics, through partial resets and a pickle."""
    cfg = SwarmConfig(n_agents=60, init_radius=3.0, n_neighbors=5)
    actions = np.random.default_rng(1).uniform(-1, 1, (2, 60, 2))

    def run(threshold: int) -> tuple[list, CutoffSwarmNavCore]:
        monkeypatch.setattr(cutoff_core, "KNN_AHEAD_MIN_AGENTS", threshold)
        core = CutoffSwarmNavCore(cfg, batch=2)
        rng = np.random.default_rng(0)
        core.reset(rng)
        out = []
        for t in range(12):
            core.step(actions)
            out.append((core.observe(), core.stats()))
            if t == 5:
                core.reset(rng, np.array([True, False]))
        return out, core

    lazy, _ = run(10**9)
    ahead, core = run(1)
    for (obs_l, stats_l), (obs_a, stats_a) in zip(lazy, ahead, strict=True):
        np.testing.assert_array_equal(obs_a, obs_l)
        for key in STAT_KEYS:
            np.testing.assert_array_equal(stats_a[key], stats_l[key])
    core._neighbors.clear()
    core._start_knn()  # in flight, as between the pair pass and the statistics of a step
    clone = pickle.loads(pickle.dumps(core))
    np.testing.assert_array_equal(clone.observe(), core.observe())


# --------------------------------------------------------------------------- step-size control


def substep_counts(cfg: SwarmConfig, batch: int, steps: int) -> np.ndarray:
    """The dense core's substeps per step and swarm ``(steps, B)`` (the reference)."""
    core = SwarmNavCore(cfg, batch=batch)
    core.reset(np.random.default_rng(0))
    a = np.random.default_rng(1).uniform(-1.0, 1.0, (batch, cfg.n_agents, cfg.dim))
    return np.array([core.step(a)[3]["substeps"] for _ in range(steps)])


@pytest.mark.parametrize("integrator", ["semi_implicit_euler", "velocity_verlet"])
@pytest.mark.parametrize("goal_in_physics", [False, True])
@pytest.mark.parametrize("pair_pass", ["auto", "numpy"])
def test_follows_the_dense_substeps(
    integrator: str, goal_in_physics: bool, pair_pass: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A config that needs several substeps per step, different ones per swarm: the
    cut-off core takes the dense core's substeps and follows its trajectory (no pair
    dropped), through a partial reset; with the compiled pair pass where numba imports,
    and with the numpy one."""
    if pair_pass == "numpy":
        monkeypatch.setenv("SWARM_ENVS_NUMBA", "0")
    cfg = SwarmConfig(
        n_agents=40,
        dt=0.3,
        integrator=integrator,
        goal_in_physics=goal_in_physics,
        init_radius=1.2,
    )
    counts = substep_counts(cfg, batch=3, steps=12)
    assert counts.min() >= 3 and len(np.unique(counts)) > 1  # several, and they vary
    assert run_both(cfg, batch=3, steps=12, cutoff_tol=TINY) < 1e-9


def test_substeps_at_the_default_cutoff_within_its_error() -> None:
    """The H-stable preset at its start (close pairs: several substeps), default cut-off:
    one step from the same state takes the dense core's substeps, and the velocities
    differ by at most what the dropped forces can give over ``dt``."""
    n = 300
    cfg = SwarmConfig(
        n_agents=n, physics=SocialPotentialParams.large_swarm(), init_density=0.6, dt=0.2
    )
    dense, cut = SwarmNavCore(cfg), CutoffSwarmNavCore(cfg)
    dense.reset(np.random.default_rng(4))
    cut.reset(np.random.default_rng(4))
    x = dense.x[0]  # the density hypothesis of the bound: n ω ρ² ≥ agents within ρ ≥ r_c
    rho = np.sort(np.linalg.norm(x[:, None] - x[None], axis=-1), axis=-1)[:, 1:]
    density = float((np.arange(1, n) / (np.pi * np.maximum(rho, cut.cutoff) ** 2)).max())
    a = np.random.default_rng(5).uniform(-1, 1, (1, n, 2))
    out_d, out_c = dense.step(a), cut.step(a)
    assert out_d[3]["substeps"][0] >= 2
    np.testing.assert_array_equal(out_c[3]["substeps"], out_d[3]["substeps"])
    # The largest relative speed of the step (its end) bounds the alignment's speed.
    w = float(np.linalg.norm(dense.v[0, :, None] - dense.v[0, None], axis=-1).max())
    bound = force_error_bound(cfg.physics, cut.cutoff, speed=w, n_agents=n, density=density, dim=2)
    err = np.linalg.norm(cut.v - dense.v, axis=-1).max()
    assert 0 < err <= cfg.dt * bound / cfg.physics.m


def test_unstable_step_raises_or_truncates_like_the_dense_core() -> None:
    """More substeps needed than max_substeps: SwarmUnstableError naming the cap, or
    (truncate) that swarm put back to its state before the step, as the dense core."""
    base = SwarmConfig(n_agents=30, init_radius=0.3, dt=0.2, max_substeps=2)
    core = CutoffSwarmNavCore(base, batch=2)
    core.reset(np.random.default_rng(0))
    with pytest.raises(SwarmUnstableError, match="max_substeps=2"):
        core.step(np.zeros((2, 30, 2)))
    cfg = dataclasses.replace(base, on_unstable="truncate")
    assert run_both(cfg, batch=2, steps=3, cutoff_tol=TINY) < 1e-9
    core = CutoffSwarmNavCore(cfg, batch=2)
    core.reset(np.random.default_rng(0))
    x0, v0 = core.x.copy(), core.v.copy()
    reward, terminated, truncated, stats = core.step(np.zeros((2, 30, 2)))
    np.testing.assert_array_equal(stats["unstable"], [1.0, 1.0])
    np.testing.assert_array_equal(stats["substeps"], [0.0, 0.0])
    assert truncated.all() and not terminated.any() and (reward == 0).all()
    np.testing.assert_array_equal(core.x, x0)
    np.testing.assert_array_equal(core.v, v0)


@pytest.mark.parametrize("on_unstable", ["raise", "truncate"])
@pytest.mark.parametrize("speed", [1e150, np.nan])
def test_diverged_state_is_caught_without_a_neighbour_search(
    on_unstable: str, speed: float
) -> None:
    """A swarm that diverges (far beyond MAX_SPAN, or NaN): SwarmUnstableError, or
    truncated and put back; the other swarm steps on as if alone, and the cell list
    never sees the diverged one."""
    cfg = SwarmConfig(n_agents=20, on_unstable=on_unstable, max_substeps=1)
    core = CutoffSwarmNavCore(cfg, batch=2)
    core.reset(np.random.default_rng(0))
    core.v[1, 0] = speed
    x0, v0 = core.x.copy(), core.v.copy()
    a = np.zeros((2, 20, 2))
    if on_unstable == "raise":
        with pytest.raises(SwarmUnstableError, match="NaN or infinite"):
            core.step(a)
        return
    *_, truncated, stats = core.step(a)
    np.testing.assert_array_equal(stats["unstable"], [0.0, 1.0])
    np.testing.assert_array_equal(truncated, [False, True])
    np.testing.assert_array_equal(core.x[1], x0[1])
    np.testing.assert_array_equal(core.v[1], v0[1])
    assert np.isfinite(core.observe()[0]).all()  # swarm 1 keeps the state it was given
    ref = CutoffSwarmNavCore(cfg, batch=1)  # swarm 0 as if alone
    ref.reset(np.random.default_rng(0))
    ref.x[0], ref.v[0], ref.goal[0] = x0[0], v0[0], core.goal[0]
    ref._after_reset(np.arange(1), np.random.default_rng(0))
    ref.step(a[:1])
    np.testing.assert_allclose(core.x[0], ref.x[0], rtol=0, atol=1e-12)
