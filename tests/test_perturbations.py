"""Agents that fail, join and are absent, and noise: the reference semantics.

The ``perturbations`` config section and ``observe_status`` (their validation and YAML
round trip), the physics of the agent statuses on the numpy core (frozen agents stay
put, absent and removed agents exert no force and cost no substeps, failed agents'
actions do nothing, joining agents appear at their start at rest), statistics over the
members, determinism per seed, and the host-side action and observation noise.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest
import yaml

from swarm_envs import metrics, swarm_nav_v0
from swarm_envs.config import SwarmConfig, as_dict, config_from_mapping
from swarm_envs.envs.backends import make_core
from swarm_envs.envs.cores.numpy import SwarmNavCore
from swarm_envs.envs.task import layer as layer_module  # draws every core's starts
from swarm_envs.envs.task.agent_status import (
    ABSENT,
    ACTIVE,
    FAILED,
    FROZEN,
    masks,
    perturb_actions,
    perturb_observations,
)
from swarm_envs.envs.task.observation import OBS_BOUND, block_size
from swarm_envs.perturbations import FAILURE_MODES, Perturbations

# --------------------------------------------------------------------------- helpers


def numpy_core(batch: int = 1, **fields: Any) -> Any:
    """The numpy core of a config (with its perturbations, as ``make_core`` wraps it)."""
    return make_core(SwarmConfig(backend="numpy", **fields), batch=batch)


def fix_starts(monkeypatch: pytest.MonkeyPatch, x: np.ndarray, v: np.ndarray, goal: np.ndarray):
    """Make every reset start the swarms at ``x, v`` ``(N, d)`` with goal ``goal`` ``(d,)``
    (drawing nothing from the generator)."""

    def starts(cfg: SwarmConfig, rng: np.random.Generator, n: int):
        return (
            np.repeat(x[None], n, axis=0),
            np.repeat(v[None], n, axis=0),
            np.repeat(goal[None], n, axis=0),
        )

    monkeypatch.setattr(layer_module, "draw_starts", starts)


def actions(seed: int, shape: tuple[int, ...], steps: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [rng.uniform(-1.0, 1.0, shape) for _ in range(steps)]


def member_stats(core: Any) -> dict[str, np.ndarray]:
    """The group statistics of each swarm computed directly on its members' states."""
    cfg = core.cfg
    out: dict[str, list[float]] = {k: [] for k in EXPECTED_KEYS}
    status = np.asarray(core.status)
    for b in range(core.batch):
        m = masks(status[b]).mobile
        present = masks(status[b]).present
        x, v, goal = core.x[b], core.v[b], core.goal[b]
        gd = np.linalg.norm(goal - x, axis=-1)
        rho = np.linalg.norm(x[:, None] - x[None], axis=-1)
        rho[~(present[:, None] & present[None])] = np.inf
        np.fill_diagonal(rho, np.inf)
        nearest = rho.min(axis=-1)
        nearest[~np.isfinite(nearest)] = 0.0
        close = (rho < cfg.collision_radius) & (m[:, None] | m[None])
        arrived = (gd <= cfg.arrival_radius)[m]
        out["polarization"].append(float(metrics.polarization(v[m])))
        out["angular_momentum"].append(float(metrics.angular_momentum(x[m], v[m])))
        out["expanse"].append(float(metrics.expanse(x[m])))
        out["nearest_neighbor_distance"].append(float(nearest[m].mean()))
        out["fraction_arrived"].append(float(arrived.mean()))
        out["collisions"].append(float(np.count_nonzero(close) // 2))
        out["centroid_distance"].append(float(np.linalg.norm(x[m].mean(axis=0) - goal)))
        out["mean_goal_distance"].append(float(gd[m].mean()))
        success = arrived.mean() >= cfg.success_fraction - 1e-9
        out["success"].append(float(success))
    return {k: np.array(v) for k, v in out.items()}


EXPECTED_KEYS = (
    "polarization",
    "angular_momentum",
    "expanse",
    "nearest_neighbor_distance",
    "fraction_arrived",
    "collisions",
    "centroid_distance",
    "mean_goal_distance",
    "success",
)


def assert_member_stats(core: Any, stats: dict[str, np.ndarray]) -> None:
    expected = member_stats(core)
    for key in EXPECTED_KEYS:
        np.testing.assert_allclose(stats[key], expected[key], rtol=1e-9, atol=1e-12, err_msg=key)


# --------------------------------------------------------------------------- config

FIELDS = [f.name for f in dataclasses.fields(Perturbations)]

#: Bad values per field, each with (part of) the message's statement of what is allowed.
BAD_VALUES = [
    *[
        (name, value, allowed)
        for name in ("failed_fraction", "absent_fraction", "join_fraction", "neighbor_dropout")
        for value, allowed in (
            (-0.1, r"must be in \[0, 1\)"),
            (1.0, r"must be in \[0, 1\)"),
            (math.nan, r"must be finite and in \[0, 1\)"),
            ("0.1", r"must be a real number in \[0, 1\)"),
            (True, r"must be a real number in \[0, 1\)"),
            ([0.1, 1.5], r"must be in \[0, 1\)"),
            ([0.1, 0.2, 0.3], r"must be a number or a range \[low, high\]"),
            ([0.2, 0.1], r"range \[low, high\] needs low <= high"),
        )
    ],
    *[
        (name, value, allowed)
        for name in ("obs_noise", "action_noise")
        for value, allowed in (
            (-1.0, r"must be in \[0, inf\)"),
            (math.inf, r"must be finite and in \[0, inf\)"),
            ([0.5, 0.1], r"range \[low, high\] needs low <= high"),
            ([-0.1, 0.1], r"must be in \[0, inf\)"),
        )
    ],
    ("failure_time", -1, r"must be in \[0, inf\)"),
    ("failure_time", 1.5, r"must be an integer >= 0"),
    ("failure_time", True, r"must be an integer >= 0"),
    ("failure_time", [5, 2], r"range \[low, high\] needs low <= high"),
    ("failure_time", [0, 2.5], r"must be an integer >= 0"),
    ("join_time", 0, r"must be in \[1, inf\)"),
    ("join_time", 2.5, r"must be an integer >= 1"),
    ("join_time", [0, 3], r"must be in \[1, inf\)"),
    ("join_time", [4, 3], r"range \[low, high\] needs low <= high"),
    ("failure_mode", "broken", r"must be one of \('passive', 'removed', 'frozen'\)"),
    ("failure_mode", None, r"must be one of \('passive', 'removed', 'frozen'\)"),
]


def test_every_field_has_bad_values_checked():
    assert {name for name, _, _ in BAD_VALUES} == set(FIELDS)


@pytest.mark.parametrize(("name", "value", "allowed"), BAD_VALUES)
def test_a_bad_value_is_refused_naming_the_key_and_what_is_allowed(name, value, allowed):
    with pytest.raises(ValueError, match=rf"^Perturbations\.{name} {allowed}"):
        Perturbations(**{name: value})
    # from a mapping (YAML) and from env keywords: the section in front
    section = rf"^perturbations: Perturbations\.{name} {allowed}"
    with pytest.raises(ValueError, match=section):
        config_from_mapping(SwarmConfig, {"perturbations": {name: value}})
    with pytest.raises(ValueError, match=section):
        swarm_nav_v0.parallel_env(perturbations={name: value})


def test_an_unknown_key_is_refused_with_the_allowed_keys():
    with pytest.raises(ValueError, match=r"unknown config key 'perturbations\.fail_fraction'"):
        config_from_mapping(SwarmConfig, {"perturbations": {"fail_fraction": 0.1}})


@pytest.mark.parametrize(
    "fractions",
    [
        dict(failed_fraction=0.5, absent_fraction=0.5),
        dict(failed_fraction=0.4, absent_fraction=0.3, join_fraction=0.3),
        dict(failed_fraction=[0.0, 0.6], join_fraction=[0.0, 0.4]),  # the highs count
        dict(absent_fraction=0.9, join_fraction=[0.05, 0.1]),
    ],
)
def test_fractions_that_can_leave_no_agent_are_refused(fractions):
    with pytest.raises(ValueError, match=r"failed_fraction \+ absent_fraction \+ join_fraction"):
        Perturbations(**fractions)
    with pytest.raises(ValueError, match=r"^perturbations: .*must stay below 1"):
        config_from_mapping(SwarmConfig, {"perturbations": fractions})


def test_fractions_just_below_one_are_allowed():
    p = Perturbations(failed_fraction=[0.1, 0.3], absent_fraction=0.3, join_fraction=0.39)
    assert p.bounds("failed_fraction") == (0.1, 0.3)


PHYSICAL = [
    dict(failed_fraction=0.2, failure_mode="frozen"),
    dict(failed_fraction=0.2, failure_mode="removed"),
    dict(absent_fraction=0.2),
    dict(join_fraction=[0.0, 0.2]),
]


@pytest.mark.parametrize("dynamics", ["zone", "piecewise"])
@pytest.mark.parametrize("p", PHYSICAL)
def test_agents_leaving_the_physics_need_the_social_potential(dynamics, p):
    with pytest.raises(ValueError, match=r"perturbations: .*dynamics='social_potential'"):
        SwarmConfig(dynamics=dynamics, perturbations=Perturbations(**p))
    with pytest.raises(ValueError, match=r"perturbations: .*integrator='semi_implicit_euler'"):
        SwarmConfig(integrator="velocity_verlet", perturbations=Perturbations(**p))


@pytest.mark.parametrize("dynamics", ["zone", "piecewise"])
def test_other_models_take_passive_failures_and_noise(dynamics):
    p = Perturbations(failed_fraction=0.3, obs_noise=0.1, action_noise=0.1, neighbor_dropout=0.2)
    cfg = SwarmConfig(dynamics=dynamics, observe_status=True, perturbations=p)
    assert not cfg.perturbations.needs_masks
    # a failure mode without failures takes nobody out of the physics
    SwarmConfig(dynamics=dynamics, perturbations=Perturbations(failure_mode="removed"))


def test_observe_status_must_be_a_bool():
    with pytest.raises(ValueError, match=r"observe_status must be true or false"):
        config_from_mapping(SwarmConfig, {"observe_status": 1})


def test_the_section_round_trips_through_yaml():
    p = Perturbations(
        failed_fraction=[0.1, 0.2],
        failure_mode="frozen",
        failure_time=[3, 9],
        absent_fraction=0.1,
        join_fraction=[0.0, 0.2],
        join_time=7,
        obs_noise=[0.0, 0.1],
        action_noise=0.05,
        neighbor_dropout=[0.1, 0.3],
    )
    cfg = SwarmConfig(n_agents=20, observe_status=True, perturbations=p)
    text = yaml.safe_dump(as_dict(cfg))
    back = config_from_mapping(SwarmConfig, yaml.safe_load(text))
    assert back == cfg
    assert back.perturbations.failure_time == (3, 9) and back.perturbations.join_time == 7
    assert isinstance(back.perturbations.join_time, int)


def test_the_properties_say_what_is_perturbed():
    assert not Perturbations().any and not Perturbations().needs_masks
    assert not Perturbations(failure_mode="frozen", failure_time=4, join_time=3).any
    passive = Perturbations(failed_fraction=[0.0, 0.1])
    assert passive.any and passive.fails_agents and not passive.needs_masks
    for mode in FAILURE_MODES[1:]:
        assert Perturbations(failed_fraction=0.1, failure_mode=mode).needs_masks
    assert Perturbations(join_fraction=0.1).joins and Perturbations(join_fraction=0.1).needs_masks
    assert Perturbations(neighbor_dropout=0.1).any


# --------------------------------------------------------------------------- physics


def test_a_frozen_agent_stays_where_it_failed_at_rest_while_the_others_move():
    core = numpy_core(
        batch=2,
        n_agents=6,
        max_steps=40,
        perturbations=Perturbations(failed_fraction=0.34, failure_mode="frozen", failure_time=3),
    )
    core.reset(np.random.default_rng(0))
    frozen_at: np.ndarray | None = None
    for t, a in enumerate(actions(1, (2, 6, 2), 20), start=1):
        x_before = core.x.copy()
        _, terminated, truncated, _ = core.step(a)
        assert not (terminated | truncated).any()
        status = core.status
        if t < 3:
            assert (status == ACTIVE).all()
            continue
        frozen = status == FROZEN
        assert (frozen.sum(axis=-1) == 2).all()  # ⌊0.34 · 6⌋ per swarm
        if frozen_at is None:
            frozen_at = core.x.copy()
            assert (np.abs(frozen_at - x_before)[frozen] > 0).any()  # it moved until then
        np.testing.assert_array_equal(core.x[frozen], frozen_at[frozen])
        np.testing.assert_array_equal(core.v[frozen], 0.0)
        assert (np.linalg.norm(core.x - x_before, axis=-1)[~frozen] > 0).all()


def test_a_frozen_agent_still_acts_on_the_others_and_a_removed_one_does_not():
    # The same draws (who fails, when) in both modes: the others' paths differ.
    paths = {}
    for mode in ("frozen", "removed"):
        core = numpy_core(
            n_agents=6,
            max_steps=40,
            perturbations=Perturbations(failed_fraction=0.34, failure_mode=mode, failure_time=0),
        )
        core.reset(np.random.default_rng(0))
        for a in actions(1, (1, 6, 2), 10):
            core.step(a)
        paths[mode] = (core.x.copy(), core.status.copy())
    (x_frozen, s_frozen), (x_removed, s_removed) = paths["frozen"], paths["removed"]
    np.testing.assert_array_equal(s_frozen == FROZEN, s_removed == ABSENT)
    others = s_frozen == ACTIVE
    assert np.abs(x_frozen[others] - x_removed[others]).max() > 1e-3


def _starts(n: int, seed: int = 5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.uniform(-1.5, 1.5, (n, 2)), rng.uniform(-0.5, 0.5, (n, 2)), np.array([4.0, 1.0])


@pytest.mark.parametrize("kind", ["absent", "removed"])
def test_an_agent_out_of_the_physics_exerts_no_force_and_costs_no_substeps(monkeypatch, kind):
    # Five agents with one absent (or removed from the start) against the four-agent swarm
    # of the same starts. The one out of the physics sits right next to another agent,
    # where a pair in the physics needs many substeps: here it changes nothing.
    p = {
        "absent": Perturbations(absent_fraction=0.2),
        "removed": Perturbations(failed_fraction=0.2, failure_mode="removed", failure_time=0),
    }[kind]
    stiff = dataclasses.replace(SwarmConfig().physics, C_r=4.0, l_r=0.05)  # κ(0) = 1600
    common = dict(
        dt=0.1,
        max_steps=100,
        goal_in_physics=True,
        collision_radius=0.3,
        n_neighbors=4,
        physics=stiff,
    )
    x, v, goal = _starts(5)
    fix_starts(monkeypatch, x, v, goal)
    five = numpy_core(n_agents=5, perturbations=p, **common)
    five.reset(np.random.default_rng(2))
    (out,) = np.flatnonzero(five.status[0] == ABSENT)
    keep = np.arange(5) != out
    near = (out + 1) % 5
    x[out] = x[near] + 1e-3  # packed against another agent
    v[out] = 3.0  # and fast: any trace of it would show
    five.reset(np.random.default_rng(2))  # the same draws: the same agent out
    assert five.status[0, out] == ABSENT

    fix_starts(monkeypatch, x[keep], v[keep], goal)
    four = numpy_core(n_agents=4, **common)
    four.reset(np.random.default_rng(2))
    fix_starts(monkeypatch, x, v, goal)
    whole = numpy_core(n_agents=5, **common)  # the same five in the physics
    whole.reset(np.random.default_rng(2))

    assert_stats_close(five.stats(), four.stats())
    np.testing.assert_allclose(five.observe()[:, keep], four.observe(), rtol=1e-6, atol=1e-7)
    # the packed pair in the physics costs substeps
    assert whole.step(np.zeros((1, 5, 2)))[3]["substeps"][0] > 1
    for a in actions(3, (1, 5, 2), 15):
        _, _, _, s5 = five.step(a)
        _, _, _, s4 = four.step(a[:, keep])
        np.testing.assert_allclose(five.x[:, keep], four.x, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(five.v[:, keep], four.v, rtol=1e-12, atol=1e-12)
        np.testing.assert_array_equal(five.x[:, out], x[None, out])  # it stays out
        assert_stats_close(s5, s4)
        np.testing.assert_allclose(five.observe()[:, keep], four.observe(), rtol=1e-6, atol=1e-7)


def assert_stats_close(ours: dict, theirs: dict) -> None:
    assert list(ours) == list(theirs)
    for key in ours:
        np.testing.assert_allclose(ours[key], theirs[key], rtol=1e-10, atol=1e-12, err_msg=key)


def test_a_removed_agent_leaves_the_physics_when_it_fails(monkeypatch):
    # After the removal the others move as a swarm without it, from the state then.
    p = Perturbations(failed_fraction=0.2, failure_mode="removed", failure_time=4)
    common = dict(dt=0.05, max_steps=100, goal_in_physics=True)
    x, v, goal = _starts(5, seed=11)
    fix_starts(monkeypatch, x, v, goal)
    five = numpy_core(n_agents=5, perturbations=p, **common)
    five.reset(np.random.default_rng(4))
    steps = actions(6, (1, 5, 2), 12)
    for a in steps[:4]:
        five.step(a)
    (out,) = np.flatnonzero(five.status[0] == ABSENT)
    keep = np.arange(5) != out
    fix_starts(monkeypatch, five.x[0, keep].copy(), five.v[0, keep].copy(), goal)
    four = numpy_core(n_agents=4, **common)
    four.reset(np.random.default_rng(0))
    assert_stats_close(
        {k: v for k, v in five.stats().items() if k != "substeps"},
        {k: v for k, v in four.stats().items() if k != "substeps"},
    )
    for a in steps[4:]:
        _, _, _, s5 = five.step(a)
        _, _, _, s4 = four.step(a[:, keep])
        np.testing.assert_allclose(five.x[:, keep], four.x, rtol=1e-12, atol=1e-12)
        assert_stats_close(s5, s4)


def test_an_undone_step_stays_flagged_when_another_swarm_changes_statuses(monkeypatch):
    # Swarm 0 has a packed pair that needs more substeps than allowed: its step is undone
    # and truncated. In the same step an agent of swarm 1 freezes, which measures that
    # swarm again: swarm 0's report of its undone step must survive that.
    rng = np.random.default_rng(5)
    x = rng.uniform(-1.5, 1.5, (2, 5, 2))
    x[0, 1] = x[0, 0] + 1e-3
    goal = np.array([[4.0, 1.0], [4.0, 1.0]])
    monkeypatch.setattr(
        layer_module, "draw_starts", lambda cfg, rng, n: (x.copy(), np.zeros_like(x), goal)
    )
    stiff = dataclasses.replace(SwarmConfig().physics, C_r=4.0, l_r=0.05)
    fields = dict(n_agents=5, dt=0.1, max_substeps=2, on_unstable="truncate", physics=stiff)
    p = Perturbations(failed_fraction=0.2, failure_mode="frozen", failure_time=1)
    reports = []
    for perturbations in (Perturbations(), p):
        core = numpy_core(batch=2, perturbations=perturbations, **fields)
        core.reset(np.random.default_rng(0))
        _, _, truncated, stats = core.step(np.zeros((2, 5, 2)))
        reports.append((truncated, stats))
    (truncated, plain), (_, stats) = reports
    assert truncated.tolist() == [True, False] and plain["unstable"].tolist() == [1.0, 0.0]
    assert (core.status[1] == FROZEN).any()
    assert stats["unstable"].tolist() == [1.0, 0.0] and stats["substeps"][0] == 0.0
    assert_stats_close({k: v[:1] for k, v in stats.items()}, {k: v[:1] for k, v in plain.items()})


def test_a_passively_failed_agent_ignores_its_actions_but_keeps_its_physics():
    p = Perturbations(failed_fraction=0.4, failure_mode="passive", failure_time=0)
    runs = []
    for scale in (0.0, 1.0):
        core = numpy_core(batch=2, n_agents=5, max_steps=50, perturbations=p)
        core.reset(np.random.default_rng(0))
        failed = core.status == FAILED
        assert (failed.sum(axis=-1) == 2).all()
        x0 = core.x.copy()
        rewards = []
        for a in actions(1, (2, 5, 2), 10):
            a = np.where(failed[..., None], scale * np.sign(a), a)  # only failed agents differ
            rewards.append(core.step(a)[0])
        runs.append((core.x.copy(), np.array(rewards)))
        assert (np.linalg.norm(core.x - x0, axis=-1)[failed] > 0).all()  # it still moves
    np.testing.assert_array_equal(runs[0][0], runs[1][0])
    np.testing.assert_array_equal(runs[0][1], runs[1][1])  # no effort charged either
    # ...while an active agent's action does change the paths
    core = numpy_core(batch=2, n_agents=5, max_steps=50, perturbations=p)
    core.reset(np.random.default_rng(0))
    for a in actions(1, (2, 5, 2), 10):
        core.step(np.where(failed[..., None], 0.0, -a))
    assert np.abs(core.x - runs[0][0]).max() > 1e-3


def test_a_joining_agent_appears_at_its_start_at_rest_at_its_join_step():
    p = Perturbations(join_fraction=0.34, join_time=[2, 6])
    core = numpy_core(batch=3, n_agents=6, max_steps=50, perturbations=p)
    core.reset(np.random.default_rng(7))
    start = core.x.copy()
    join_at = core.schedule.join_at.copy()
    joining = join_at > 0
    assert (joining.sum(axis=-1) == 2).all()
    assert (core.status[joining] == ABSENT).all() and (core.status[~joining] == ACTIVE).all()
    for t, a in enumerate(actions(8, (3, 6, 2), 8), start=1):
        _, _, _, stats = core.step(a)
        now = joining & (join_at == t)
        waiting = joining & (join_at > t)
        assert (core.status[now] == ACTIVE).all() and (core.status[waiting] == ABSENT).all()
        np.testing.assert_array_equal(core.x[now], start[now])
        np.testing.assert_array_equal(core.v[now], 0.0)
        np.testing.assert_array_equal(core.x[waiting], start[waiting])
        assert_member_stats(core, stats)  # the newcomers count from their join step
        # the others see them from then on: real slots = present others (up to k)
        obs = core.observe()
        present = (core.status != ABSENT).sum(axis=-1)
        mask_col = 2 * 2 + 2 * 2 + np.arange(core.cfg.n_neighbors) * block_size(core.cfg)
        real = obs[..., mask_col].sum(axis=-1)
        for b in range(3):
            here = core.status[b] != ABSENT
            expected = min(present[b] - 1, core.cfg.n_neighbors)
            np.testing.assert_array_equal(real[b, here], expected)
    assert (join_at <= 8).all()  # every join happened within the rollout


def test_the_statistics_count_the_members_only(monkeypatch):
    # Three agents at the goal, a frozen one far away: all members arrived, success.
    n = 4
    goal = np.array([3.0, 0.0])
    x = goal + np.array([[0.1, 0.0], [-0.1, 0.0], [0.0, 0.1], [0.0, 0.0]])
    v = np.zeros((n, 2))
    fix_starts(monkeypatch, x, v, goal)
    p = Perturbations(failed_fraction=0.25, failure_mode="frozen", failure_time=0)
    cfg = dict(n_agents=n, goal_radius=0.5, success_fraction=1.0, max_steps=20)
    core = numpy_core(perturbations=p, **cfg)
    core.reset(np.random.default_rng(0))
    (frozen,) = np.flatnonzero(core.status[0] == FROZEN)
    x[frozen] = [-8.0, 5.0]
    core.reset(np.random.default_rng(0))
    assert core.status[0, frozen] == FROZEN
    stats = core.stats()
    assert stats["fraction_arrived"][0] == 1.0 and stats["success"][0] == 1.0
    assert_member_stats(core, stats)
    _, terminated, _, stats = core.step(np.zeros((1, n, 2)))
    assert terminated[0] and stats["success"][0] == 1.0
    # the same swarm with every agent a member has not succeeded
    plain = numpy_core(**cfg)
    plain.reset(np.random.default_rng(0))
    assert plain.stats()["fraction_arrived"][0] == 0.75 and plain.stats()["success"][0] == 0.0


@pytest.mark.parametrize("mode", FAILURE_MODES)
def test_the_statistics_over_members_match_the_metrics_on_the_members(mode):
    # Through failures, joins and absences, every step's statistics are those of the
    # members' states (the metrics on that subset); collisions over present pairs.
    p = Perturbations(
        failed_fraction=0.25,
        failure_mode=mode,
        failure_time=[0, 6],
        absent_fraction=0.15,
        join_fraction=0.2,
        join_time=[1, 6],
    )
    core = numpy_core(
        batch=3, n_agents=10, max_steps=8, collision_radius=0.6, goal_radius=2.0, perturbations=p
    )
    rng = np.random.default_rng(3)
    core.reset(rng)
    assert_member_stats(core, core.stats())
    seen = set()
    for a in actions(4, (3, 10, 2), 14):
        _, terminated, truncated, stats = core.step(a)
        assert_member_stats(core, stats)
        seen |= set(np.unique(core.status).tolist())
        ended = terminated | truncated
        if ended.any():
            core.reset(rng, which=ended)
            assert_member_stats(core, core.stats())
    assert seen >= {ACTIVE, ABSENT, {"passive": FAILED, "frozen": FROZEN, "removed": ABSENT}[mode]}


def test_statuses_change_nothing_for_a_swarm_where_every_agent_stays_active():
    # observe_status alone: the same physics and statistics, the flags all 1.
    cfg = SwarmConfig(n_agents=7, backend="numpy", observe_status=True, max_steps=50)
    plain = dataclasses.replace(cfg, observe_status=False)
    ours, ref = SwarmNavCore(cfg, batch=2), SwarmNavCore(plain, batch=2)
    for c in (ours, ref):
        c.reset(np.random.default_rng(0))
    ours.set_status(np.zeros((2, 7), np.int8), rows=np.ones(2, bool), start=True)
    k, d = cfg.n_neighbors, cfg.dim
    for a in actions(1, (2, 7, 2), 6):
        r1, *_, s1 = ours.step(a)
        r2, *_, s2 = ref.step(a)
        np.testing.assert_allclose(r1, r2, rtol=1e-10, atol=1e-12)
        assert_stats_close(s1, s2)
        obs = ours.observe().reshape(2, 7, -1)
        slots = obs[..., 2 * d :].reshape(2, 7, k, 2 * d + 2)
        np.testing.assert_array_equal(slots[..., -1], slots[..., -2])  # status = mask (1s)
        np.testing.assert_array_equal(
            slots[..., :-1].reshape(2, 7, -1), ref.observe()[..., 2 * d :]
        )


# --------------------------------------------------------------------------- determinism

EVERYTHING = SwarmConfig(
    n_agents=10,
    max_steps=6,
    backend="numpy",
    observe_status=True,
    perturbations=Perturbations(
        failed_fraction=[0.1, 0.3],
        failure_mode="frozen",
        failure_time=[0, 4],
        absent_fraction=[0.0, 0.2],
        join_fraction=0.2,
        join_time=[1, 4],
        obs_noise=[0.05, 0.2],
        action_noise=[0.1, 0.3],
        neighbor_dropout=[0.1, 0.4],
    ),
)


def _rollout(cfg: SwarmConfig, seed: int, steps: int = 15) -> list[tuple[np.ndarray, ...]]:
    core = make_core(cfg, batch=3)
    rng = np.random.default_rng(seed)
    core.reset(rng)
    out = [(core.observe(), core.status.copy())]
    for a in actions(seed + 100, (3, cfg.n_agents, cfg.dim), steps):
        reward, terminated, truncated, stats = core.step(a)
        out.append((core.observe(), core.status.copy(), reward, stats["energy"]))
        ended = terminated | truncated
        if ended.any():
            core.reset(rng, which=ended)
            out.append((core.observe(), core.status.copy()))
    return out


def test_the_same_seed_gives_the_same_rollout_and_another_seed_another():
    first, again, other = _rollout(EVERYTHING, 0), _rollout(EVERYTHING, 0), _rollout(EVERYTHING, 1)
    assert len(first) == len(again)
    for a, b in zip(first, again, strict=True):
        for u, w in zip(a, b, strict=True):
            np.testing.assert_array_equal(u, w)
    assert not np.array_equal(first[0][0], other[0][0])
    assert any(not np.array_equal(a[1], b[1]) for a, b in zip(first, other, strict=False))


def test_observations_are_stable_between_steps():
    # The noise is drawn once per step: repeated calls return the same values.
    core = make_core(EVERYTHING, batch=2)
    core.reset(np.random.default_rng(0))
    np.testing.assert_array_equal(core.observe(), core.observe())
    core.step(np.zeros((2, 10, 2)))
    obs = core.observe()
    np.testing.assert_array_equal(obs, core.observe())
    np.testing.assert_array_equal(core.observe(np.array([False, True])), obs[1:])


def test_swarms_reset_a_few_at_a_time_from_the_start_get_their_own_observations():
    # Resetting the batch in parts from the first reset (as ES does, one block per
    # candidate) gives each part the observations a whole reset from the same
    # generator gives it.
    core = make_core(EVERYTHING, batch=4)
    for half in (np.arange(4) < 2, np.arange(4) >= 2):
        core.reset(np.random.default_rng(5), which=half)
    whole = make_core(EVERYTHING, batch=2)
    whole.reset(np.random.default_rng(5))
    obs = core.observe()
    assert obs.shape[0] == 4
    np.testing.assert_array_equal(obs[:2], whole.observe())
    np.testing.assert_array_equal(obs[2:], whole.observe())


# --------------------------------------------------------------------------- noise


def _observations(seed: int = 0, batch: int = 4) -> tuple[SwarmConfig, np.ndarray]:
    """Real observations with status flags (some neighbours failed, some padding)."""
    cfg = SwarmConfig(
        n_agents=6,
        n_neighbors=7,
        backend="numpy",
        observe_status=True,
        perturbations=Perturbations(failed_fraction=0.34, failure_mode="frozen"),
    )
    core = make_core(cfg, batch=batch)
    core.reset(np.random.default_rng(seed))
    return cfg, core.observe()


def _perturb(cfg: SwarmConfig, obs: np.ndarray, sigma, dropout, seed: int = 1):
    b = obs.shape[0]
    return perturb_observations(
        obs,
        dim=cfg.dim,
        block=block_size(cfg),
        n_slots=cfg.n_neighbors,
        sigma=np.broadcast_to(np.asarray(sigma, float), (b,)),
        dropout=np.broadcast_to(np.asarray(dropout, float), (b,)),
        rng=np.random.default_rng(seed),
        bound=OBS_BOUND,
    )


def _slots(cfg: SwarmConfig, obs: np.ndarray) -> np.ndarray:
    b, n, _ = obs.shape
    return obs[..., 2 * cfg.dim :].reshape(b, n, cfg.n_neighbors, block_size(cfg))


def test_dropped_slots_read_as_padding_and_the_rest_is_untouched():
    cfg, obs = _observations()
    out = _perturb(cfg, obs, sigma=0.0, dropout=0.5)
    np.testing.assert_array_equal(out[..., : 2 * cfg.dim], obs[..., : 2 * cfg.dim])
    ours, theirs = _slots(cfg, out), _slots(cfg, obs)
    kept = (ours == theirs).all(axis=-1)
    dropped = (ours == 0).all(axis=-1)
    assert (kept | dropped).all()
    real = theirs[..., 2 * cfg.dim] > 0
    share = (dropped & ~kept)[real].mean()
    assert 0.3 < share < 0.7  # about half of the real slots dropped


def test_noise_spares_the_flags_padding_and_dropped_slots_and_respects_the_bound():
    cfg, obs = _observations()
    d = cfg.dim
    out = _perturb(cfg, obs, sigma=0.3, dropout=0.4)
    ours, theirs = _slots(cfg, out), _slots(cfg, obs)
    flags = ours[..., 2 * d :]
    assert set(np.unique(flags)) <= {0.0, 1.0}
    empty = ours[..., 2 * d] == 0  # padding or dropped: all zeros, noise-free
    np.testing.assert_array_equal(ours[empty], 0.0)
    np.testing.assert_array_equal(flags[~empty], theirs[..., 2 * d :][~empty])
    assert (ours[~empty][..., : 2 * d] != theirs[~empty][..., : 2 * d]).all()
    assert np.abs(out).max() <= OBS_BOUND
    loud = _perturb(cfg, obs, sigma=100.0, dropout=0.0)
    assert np.abs(loud).max() == OBS_BOUND  # clipped at the bound
    np.testing.assert_array_equal(_slots(cfg, loud)[..., 2 * d :], theirs[..., 2 * d :])


def test_observation_noise_has_its_swarms_standard_deviation():
    cfg, obs = _observations(batch=3)
    obs = np.repeat(obs, 200, axis=1)  # many agents' own features, none near the bound
    obs[..., : 2 * cfg.dim] = 0.0
    out = _perturb(cfg, obs, sigma=[0.0, 0.05, 0.2], dropout=0.0)
    own = out[..., : 2 * cfg.dim].reshape(3, -1)
    np.testing.assert_array_equal(own[0], 0.0)
    for b, sigma in ((1, 0.05), (2, 0.2)):
        assert abs(own[b].std() / sigma - 1) < 0.05
        assert abs(own[b].mean()) < 0.05 * sigma


def test_no_noise_draws_nothing():
    cfg, obs = _observations()
    rng = np.random.default_rng(5)
    state = rng.bit_generator.state
    out = perturb_observations(
        obs,
        dim=2,
        block=block_size(cfg),
        n_slots=cfg.n_neighbors,
        sigma=np.zeros(obs.shape[0]),
        dropout=np.zeros(obs.shape[0]),
        rng=rng,
        bound=OBS_BOUND,
    )
    np.testing.assert_array_equal(out, obs)
    a = np.random.default_rng(0).uniform(-1, 1, (2, 5, 2))
    status = np.zeros((2, 5), np.int8)
    np.testing.assert_array_equal(perturb_actions(a, status, np.zeros(2), rng), a)
    assert rng.bit_generator.state == state


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_actions_of_agents_that_do_not_act_are_zero_and_noise_is_clipped(dtype):
    rng = np.random.default_rng(0)
    a = rng.uniform(-1, 1, (3, 2000, 2)).astype(dtype)
    status = rng.choice([ACTIVE, FAILED, FROZEN, ABSENT], size=(3, 2000)).astype(np.int8)
    sigma = np.array([0.0, 0.1, 5.0])
    out = perturb_actions(a, status, sigma, np.random.default_rng(1))
    assert out.dtype == dtype and out.shape == a.shape
    idle = status != ACTIVE
    np.testing.assert_array_equal(out[idle], 0.0)
    np.testing.assert_array_equal(out[0][~idle[0]], a[0][~idle[0]])  # σ = 0: untouched
    assert np.abs(out).max() <= 1.0
    quiet = (out[1] - a[1])[~idle[1]]
    inside = np.abs(a[1][~idle[1]]) < 0.6  # far from the clip: the noise itself
    assert abs(quiet[inside].std() / 0.1 - 1) < 0.15
    assert (np.abs(out[2][~idle[2]]) == 1.0).mean() > 0.5  # loud noise: mostly clipped


@pytest.mark.parametrize("backend", ["native", "torch", "cutoff"])
def test_every_status_backend_keeps_an_undone_steps_flag_as_numpy_does(monkeypatch, backend):
    # The numpy test above, on each other core that takes statuses: swarm 0's undone,
    # truncated step stays reported while swarm 1 is measured again for its frozen agent.
    from swarm_envs.envs import backends

    if backends.unsupported(SwarmConfig(backend=backend), backend) is not None:
        pytest.skip(f"{backend} cannot run here")
    if backend == "torch":
        monkeypatch.setenv("SWARM_ENVS_TORCH_COMPILE", "0")
    rng = np.random.default_rng(5)
    x = rng.uniform(-1.5, 1.5, (2, 5, 2))
    x[0, 1] = x[0, 0] + 1e-3
    goal = np.array([[4.0, 1.0], [4.0, 1.0]])
    starts = lambda cfg, rng, n: (x.copy(), np.zeros_like(x), goal)  # noqa: E731
    monkeypatch.setattr(layer_module, "draw_starts", starts)
    stiff = dataclasses.replace(SwarmConfig().physics, C_r=4.0, l_r=0.05)
    fields = dict(n_agents=5, dt=0.1, max_substeps=2, on_unstable="truncate", physics=stiff)
    p = Perturbations(failed_fraction=0.2, failure_mode="frozen", failure_time=1)
    results = {}
    for name in ("numpy", backend):
        core = make_core(SwarmConfig(backend=name, perturbations=p, **fields), batch=2)
        assert core.backend == name
        core.reset(np.random.default_rng(0))
        _, _, truncated, stats = core.step(np.zeros((2, 5, 2)))
        results[name] = (truncated.tolist(), stats["unstable"].tolist(), core.status.copy())
    assert results[backend][0] == results["numpy"][0] == [True, False]
    assert results[backend][1] == results["numpy"][1] == [1.0, 0.0]
    np.testing.assert_array_equal(results[backend][2], results["numpy"][2])
