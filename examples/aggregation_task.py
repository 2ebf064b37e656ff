"""Aggregation: a user's own task in one file, outside the package.

Aggregation is the swarm-robotics benchmark of gathering without a place to gather at
(Şahin 2005; Gauci et al. 2014, "Self-organized aggregation without computation"): the
swarm starts as two separate groups and must merge into one compact cluster anywhere.
Here the expanse ``E`` (the mean distance of the members from their centroid,
``info["expanse"]``) measures it; the task succeeds once ``E ≤ TARGET_EXPANSE``.

Importing this file registers the task ``"aggregation"`` (and the Gymnasium id
``examples/SwarmAggregation-v0``); it is also a PettingZoo module
(``parallel_env``, ``env``, ``raw_env``, ``vec_env``). Train it with
``swarm-train --config examples/aggregation_task.yaml``, whose ``plugins:`` names this
file, or from Python::

    import swarm_envs.plugins
    swarm_envs.plugins.load_plugin("examples/aggregation_task.py")
    env = gymnasium.make("examples/SwarmAggregation-v0")

Everything below is a function over the array namespace ``xp`` (numpy or torch), so the
numpy, cut-off and compiled torch cores all execute it; the C step refuses the task (it
does not write the centroid feature) and the env falls back with a warning.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from swarm_envs import metrics
from swarm_envs.config import SwarmConfig
from swarm_envs.envs.common import uniform_starts
from swarm_envs.envs.task import (
    REWARD_TERMS,
    FeatureInputs,
    Frame,
    ObservationFeature,
    RewardInputs,
    RewardTerm,
)
from swarm_envs.swarm_nav_v0 import task_functions
from swarm_envs.tasks import TaskSpec, register_task

#: The task succeeds once the members' expanse is at most this (world units).
TARGET_EXPANSE = 1.0
#: The distance between the two groups' centres at the start.
SEPARATION = 8.0


def contraction(r: RewardInputs) -> Any:
    """``(E_{t−1} − E_t) / E_0``: this step's reduction of the expanse, over its start."""
    start = r.xp.clip(r.start["expanse"], 1e-6, None)
    return (r.prev["expanse"] - r.stats["expanse"]) / start


def gathered(f: Frame, cfg: SwarmConfig, xp: Any) -> Any:
    """1.0 where the members' expanse is at most :data:`TARGET_EXPANSE`."""
    expanse = metrics.expanse(f.x, f.members)
    return xp.astype(expanse <= TARGET_EXPANSE, f.x[..., 0, 0])


def centroid_offset(s: FeatureInputs, cfg: SwarmConfig, xp: Any) -> Any:
    """Each agent's offset to the members' centroid, ``(r_c − r_i) / obs_goal_scale``."""
    if s.members is None:
        centre = xp.mean_agents(s.x)
    else:
        w = xp.astype(s.members, s.x)
        centre = (
            xp.sum_agents(s.x * w[..., None]) / xp.clip(xp.sum(w, axis=-1), 1.0, None)[..., None]
        )
    return (centre[:, None, :] - s.x) / cfg.obs_goal_scale


def two_groups(
    cfg: SwarmConfig, rng: np.random.Generator, n: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The start law: the default start disc's agents split in two halves whose discs lie
    :data:`SEPARATION` apart along a random direction; the goal (unused) at the origin."""
    x, v, _ = uniform_starts(cfg, rng, n)
    axis = rng.standard_normal((n, 1, cfg.dim))
    axis /= np.maximum(np.linalg.norm(axis, axis=-1, keepdims=True), 1e-12)
    side = np.where(np.arange(cfg.n_agents) % 2 == 0, 0.5, -0.5)[None, :, None]
    return x + SEPARATION * side * axis, v, np.zeros((n, cfg.dim))


_SHIPPED = {t.name: t for t in REWARD_TERMS}

AGGREGATION = register_task(
    TaskSpec(
        name="aggregation",
        doc="two groups merge into one cluster anywhere: the members' expanse at most "
        f"{TARGET_EXPANSE:g} (the goal is unused)",
        reward_terms=(
            RewardTerm(
                "contraction",
                1.0,
                "(E_{t−1} − E_t)/E_0: the reduction of the expanse E, over its start value",
                contraction,
                weight=10.0,
            ),
            _SHIPPED["success"],
            _SHIPPED["collision"],
            dataclasses.replace(_SHIPPED["effort"], weight=0.02),
            _SHIPPED["time"],
        ),
        features=(
            ObservationFeature(
                "centroid_offset",
                "(r_c − r_i)/obs_goal_scale: the offset to the members' centroid",
                centroid_offset,
                width=lambda cfg: cfg.dim,
            ),
        ),
        success=gathered,
        success_doc=f"the members' expanse is at most {TARGET_EXPANSE:g}",
        start=two_groups,
        defaults={"n_agents": 8, "init_radius": 1.0, "max_steps": 150},
        env_id="examples/SwarmAggregation-v0",
        module=__name__,
    )
)

parallel_env, raw_env, env, vec_env = task_functions("aggregation", __name__)
