"""A swarm that needs many substeps per step says so once, with cause and remedy."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from swarm_envs.config import SwarmConfig
from swarm_envs.envs import backends, stiffness
from swarm_envs.envs.stiffness import STIFF_SUBSTEPS, STIFF_WINDOW, StiffSwarmWarning

#: Dense and with a long step: about 11 substeps per step of the default physics.
STIFF = SwarmConfig(n_agents=60, init_density=4.0, dt=0.25, max_steps=1000)
#: The default navigation swarm: one or two substeps per step.
SANE = SwarmConfig(n_agents=30, max_steps=1000)


def _run(cfg: SwarmConfig, backend: str, steps: int) -> tuple[list, float]:
    options = {"compile": False} if backend == "torch" else {}  # the same host-side watch
    core = backends._core_class(backend)(cfg, batch=2, **options)
    core.reset(np.random.default_rng(0))
    total = 0.0
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(steps):
            total += float(core.step(np.zeros((2, cfg.n_agents, cfg.dim)))[3]["substeps"].mean())
    return [w for w in caught if issubclass(w.category, StiffSwarmWarning)], total / steps


@pytest.fixture(autouse=True)
def _fresh_warnings(monkeypatch):
    monkeypatch.setattr(stiffness, "_WARNED", set())


# (the torch core runs the same watch on its host statistics: see the quiet test; its
# plain substep loop is too slow on the CPU for two windows of a stiff swarm here)
@pytest.mark.parametrize("backend", ["numpy", "native"])
def test_a_stiff_swarm_warns_once_with_cause_and_remedy(backend):
    if backends.unsupported(STIFF, backend) is not None:
        pytest.skip(backends.unsupported(STIFF, backend))
    caught, mean = _run(STIFF, backend, 2 * STIFF_WINDOW + 5)
    assert mean > STIFF_SUBSTEPS
    assert len(caught) == 1  # two windows over the threshold, one warning
    message = str(caught[0].message)
    for part in (
        "substeps per step",
        "nearest-neighbour distance",
        "not H-stable",
        "large_swarm()",
        "lower dt",
        "backend=",
    ):
        assert part in message, (part, message)


@pytest.mark.parametrize("backend", ["numpy", "torch", "native"])
def test_a_sane_swarm_stays_quiet(backend):
    if backends.unsupported(SANE, backend) is not None:
        pytest.skip(backends.unsupported(SANE, backend))
    caught, mean = _run(SANE, backend, STIFF_WINDOW + 5)
    assert mean < STIFF_SUBSTEPS
    assert caught == []


def test_the_warning_comes_once_per_config_across_cores():
    first, _ = _run(STIFF, "numpy", STIFF_WINDOW)
    again, _ = _run(STIFF, "numpy", STIFF_WINDOW)
    assert len(first) == 1 and again == []


def test_a_stiff_lagrangian_swarm_is_told_of_its_own_tolerance():
    cfg = SwarmConfig(dynamics="lagrangian")
    stats = {"nearest_neighbor_distance": np.array([0.3]), "expanse": np.array([1.0])}
    message = stiffness.stiff_message(cfg, stats, 0, 9.0, STIFF_WINDOW)
    for part in ("step_tol=", "lagrangian.step_tol", "lagrangian.r", "lower dt"):
        assert part in message, (part, message)
    assert "H-stable" not in message  # the social potential's cause is not this model's
