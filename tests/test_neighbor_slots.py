"""Swarm size and neighbour slots: padding that is never silent, and one agent alone."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from swarm_envs import config, swarm_nav_v0
from swarm_envs.config import DEFAULT_N_NEIGHBORS, SwarmConfig
from swarm_envs.envs.task import observation_size
from swarm_envs.envs.task.observation import block_size, own_size


@pytest.fixture(autouse=True)
def _fresh_warnings(monkeypatch):
    monkeypatch.setattr(config, "_WARNED_SLOTS", set())


def test_more_slots_than_other_agents_warn_once_naming_the_empty_ones():
    with pytest.warns(UserWarning, match=r"n_neighbors=50 with n_agents=5: .* 46 of its 50"):
        cfg = SwarmConfig(n_agents=5, n_neighbors=50)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        SwarmConfig(n_agents=5, n_neighbors=50)  # once per (n_agents, n_neighbors)
    # the layout is kept (one layout for every swarm size), the extra slots empty
    env = swarm_nav_v0.parallel_env(n_agents=5, n_neighbors=50, backend="numpy")
    obs, _ = env.reset(seed=0)
    assert obs["agent_0"].shape == (observation_size(cfg),)
    slots = obs["agent_0"][own_size(cfg) :].reshape(50, block_size(cfg))
    assert (slots[:4] != 0).any(axis=1).all() and (slots[4:] == 0).all()


@pytest.mark.parametrize("n_agents", [1, 2, 4, 7, 10])
def test_the_default_slots_and_a_compact_observation_are_quiet(n_agents):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        SwarmConfig(n_agents=n_agents)  # the default's slots, padded where N - 1 < 6
        SwarmConfig(n_agents=n_agents, n_neighbors=max(n_agents - 1, 0))
        SwarmConfig(n_agents=n_agents, n_neighbors=DEFAULT_N_NEIGHBORS)


def test_one_agent_is_single_agent_navigation():
    env = swarm_nav_v0.parallel_env(n_agents=1, backend="numpy")
    obs, _ = env.reset(seed=0)
    assert env.agents == ["agent_0"]
    assert (obs["agent_0"][4:] == 0).all()  # every neighbour slot is padding
    _, reward, _, _, info = env.step({"agent_0": np.ones(2, np.float32)})
    assert np.isfinite(reward["agent_0"])
    assert info["agent_0"]["nearest_neighbor_distance"] == 0.0
    assert info["agent_0"]["collisions"] == 0.0
