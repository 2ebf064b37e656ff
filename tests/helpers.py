"""Helpers shared by the env tests: strict warnings, global random generator snapshots,
and seeded rollouts of the batched cores compared with each other."""

from __future__ import annotations

import contextlib
import dataclasses
import random
import warnings
from collections.abc import Iterator
from typing import Any

import numpy as np
import torch

from swarm_envs.config import SwarmConfig
from swarm_envs.envs.task import STAT_KEYS

RngStates = tuple[Any, Any, torch.Tensor]


def rng_states() -> RngStates:
    """The global generators' states: numpy's legacy one, Python's and torch's."""
    return np.random.get_state(), random.getstate(), torch.get_rng_state()  # noqa: NPY002


def assert_same_rng_states(a: RngStates, b: RngStates) -> None:
    (np_a, py_a, torch_a), (np_b, py_b, torch_b) = a, b
    assert np_a[0] == np_b[0]
    assert np.array_equal(np_a[1], np_b[1])
    assert np_a[2:] == np_b[2:]
    assert py_a == py_b
    assert torch.equal(torch_a, torch_b)


#: The only warning allowed under :func:`strict_warnings`: ``render_mode="human"`` on a
#: headless machine (the checkers construct the env in every render mode).
NO_WINDOW = ".*could not open a window"


@contextlib.contextmanager
def strict_warnings() -> Iterator[None]:
    """Every warning is an error, except our own headless-window notice."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", message=NO_WINDOW, category=UserWarning)
        yield


# ---------------------------------------------------------------- batched cores
#: Tolerances of a batched core against the numpy core, per state dtype.
CORE_TOL = {np.float32: dict(rtol=2e-4, atol=2e-4), np.float64: dict(rtol=1e-9, atol=1e-9)}


def rollout(core, seed: int, steps: int, reset_every: int = 0, few: bool = False) -> list[tuple]:
    """Observations, rewards, flags and stats of a seeded rollout with random actions.

    Every ``reset_every`` steps, swarms whose episode ended or whose index is even are
    reset on their own (the VecEnv's partial reset). With ``few``, one swarm in 16 (a
    different one each time) instead of the even ones: the torch core's sub-batch reset.
    """
    rng = np.random.default_rng(seed)
    core.reset(rng)
    out = [(core.observe(), None, None, None, core.stats())]
    shape = (core.batch, core.cfg.n_agents, core.cfg.dim)
    actions = np.random.default_rng(seed + 1)
    for n in range(steps):
        a = actions.uniform(-1.2, 1.2, shape).astype(np.float32)
        reward, terminated, truncated, stats = core.step(a)
        # Copies: SwarmNavCore keeps two of these arrays as prev_distance/prev_arrived
        # and a partial reset writes into them.
        stats = {key: value.copy() for key, value in stats.items()}
        out.append((core.observe(), reward, terminated, truncated, stats))
        if reset_every and (n + 1) % reset_every == 0:
            picked = np.arange(core.batch) % (16 if few else 2) == (n % 16 if few else 0)
            which = terminated | truncated | picked
            core.reset(rng, which=which)
            out.append((core.observe(), None, None, None, core.stats()))
    return out


def assert_same_rollout(ours: list[tuple], ref: list[tuple], tol: dict) -> None:
    assert len(ours) == len(ref)
    for (obs, rew, term, trunc, stats), (obs_r, rew_r, term_r, trunc_r, stats_r) in zip(
        ours, ref, strict=True
    ):
        assert obs.dtype == np.float32 and obs.shape == obs_r.shape
        np.testing.assert_allclose(obs, obs_r, **tol)
        if rew is not None:
            assert rew.dtype == rew_r.dtype and rew.shape == rew_r.shape
            np.testing.assert_allclose(rew, rew_r, **tol)
            np.testing.assert_array_equal(term, term_r)
            np.testing.assert_array_equal(trunc, trunc_r)
        assert list(stats) == list(STAT_KEYS)
        for key in STAT_KEYS:
            assert stats[key].dtype == stats_r[key].dtype, key
            scale = max(1.0, float(np.abs(stats_r[key]).max()))
            np.testing.assert_allclose(
                stats[key], stats_r[key], err_msg=key, **tol, equal_nan=False
            )
            assert np.abs(stats[key] - stats_r[key]).max() <= tol["atol"] * scale * 10


CORE_CONFIGS = {
    "default": dict(n_agents=10),
    "padding_3d_goal_physics": dict(
        n_agents=4, dim=3, goal_in_physics=True, collision_radius=1.0, max_steps=25
    ),
    "single_agent": dict(n_agents=1),
    "no_neighbours_heavy": dict(
        n_agents=6, n_neighbors=0, physics={"m": 2.0, "C_o": 0.0}, success_fraction=0.5
    ),
    "instant_success": dict(
        n_agents=5, goal_distance_min=0.0, goal_distance_max=0.0, goal_radius=50.0
    ),
}


def make_config(overrides: dict) -> SwarmConfig:
    overrides = dict(overrides)
    physics = overrides.pop("physics", None)
    cfg = SwarmConfig(**overrides)
    if physics:
        cfg = dataclasses.replace(cfg, physics=dataclasses.replace(cfg.physics, **physics))
    return cfg


# ---------------------------------------------------------------- agent statuses
def status_perturbations() -> dict:
    """Each kind of perturbation that needs statuses in the cores, with the statuses its
    rollouts must go through (``{kind: (Perturbations, {status, ...})}``)."""
    from swarm_envs.envs.task.agent_status import ABSENT, FAILED, FROZEN
    from swarm_envs.perturbations import Perturbations

    return {
        "removed": (
            Perturbations(failed_fraction=0.4, failure_mode="removed", failure_time=[0, 4]),
            {ABSENT},
        ),
        "frozen": (
            Perturbations(failed_fraction=0.4, failure_mode="frozen", failure_time=[0, 4]),
            {FROZEN},
        ),
        "passive": (
            Perturbations(failed_fraction=0.4, failure_mode="passive", failure_time=[0, 4]),
            {FAILED},
        ),
        "joining": (
            Perturbations(absent_fraction=0.2, join_fraction=0.3, join_time=[1, 5]),
            {ABSENT},
        ),
    }


def status_rollout(core, n_agents: int, dim: int, steps: int, dtype=np.float64):
    """Observations, step results and statistics of a seeded rollout of ``core`` (ended
    swarms reset as the VecEnv resets them), and the statuses its agents went through."""
    batch = core.batch
    rng = np.random.default_rng(0)
    core.reset(rng)
    seen = set(np.unique(core.status).tolist())
    out = [(core.observe(), None, core.stats())]
    actions = np.random.default_rng(1).uniform(-1, 1, (steps, batch, n_agents, dim))
    for a in actions.astype(dtype):
        reward, terminated, truncated, stats = core.step(a)
        out.append((core.observe(), (reward, terminated, truncated), stats))
        seen |= set(np.unique(core.status).tolist())
        core.reset(rng, which=terminated | truncated)
        out.append((core.observe(), None, core.stats()))
    return out, seen


def assert_same_status_rollout(got: list, want: list, tol: dict) -> None:
    """Two :func:`status_rollout` records agree: observations, rewards and statistics to
    ``tol``, the episode ends exactly, every statistic of ``STAT_KEYS`` in order."""
    from swarm_envs.envs.task import STAT_KEYS

    assert len(got) == len(want)
    for t, ((obs, step, stats), (ref_obs, ref_step, ref_stats)) in enumerate(
        zip(got, want, strict=True)
    ):
        np.testing.assert_allclose(obs, ref_obs, **tol, err_msg=f"observations at {t}")
        if step is not None:
            np.testing.assert_allclose(step[0], ref_step[0], **tol, err_msg=f"reward at {t}")
            np.testing.assert_array_equal(step[1], ref_step[1], err_msg=f"terminated at {t}")
            np.testing.assert_array_equal(step[2], ref_step[2], err_msg=f"truncated at {t}")
        assert list(stats) == list(STAT_KEYS)
        for key in STAT_KEYS:
            np.testing.assert_allclose(stats[key], ref_stats[key], **tol, err_msg=f"{key} at {t}")


def mill_about_goal(n_agents: int, dim: int) -> Any:
    """The mill task with a self-propelled swarm started about its goal (goal within 1
    of the start's centre, arrival radius 2, fast start): agents inside and outside the
    arrival radius, circling or not, for comparing the statistics about the goal."""
    from swarm_envs.tasks import task_config

    return task_config(
        "mill",
        n_agents=n_agents,
        dim=dim,
        goal_distance_min=0.0,
        goal_distance_max=1.0,
        goal_radius=2.0,
        init_speed=1.0,
        max_steps=6,
    )


def count_kept(monkeypatch: Any) -> list[int]:
    """Spy on ``SwarmNavCore.keep``: the list it returns gets the number of rows each
    call keeps (the call still shrinks the core)."""
    from swarm_envs.envs.cores.numpy import SwarmNavCore

    kept: list[int] = []
    keep = SwarmNavCore.keep

    def counting_keep(self: SwarmNavCore, rows: np.ndarray) -> None:
        kept.append(len(rows))
        keep(self, rows)

    monkeypatch.setattr(SwarmNavCore, "keep", counting_keep)
    return kept
