"""SwarmNavCore.keep: a core shrunk to some of its swarms steps them as the whole batch
would have, bit for bit (evolution strategies' rollouts shrink to the live episodes)."""

from __future__ import annotations

import numpy as np
import pytest

from swarm_envs.config import SwarmConfig
from swarm_envs.envs.cores.numpy import SwarmNavCore

ROW_EXACT = ["social_potential", "zone", "lagrangian"]


def _config(dynamics: str, **kw: object) -> SwarmConfig:
    return SwarmConfig(dynamics=dynamics, n_agents=5, max_steps=40, **kw)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    "dynamics, task",
    [(d, "navigation") for d in ROW_EXACT]
    + [("social_potential", "informed"), ("zone", "informed")],
)
def test_kept_swarms_step_as_in_the_whole_batch(dynamics, task):
    cfg = _config(dynamics, task=task)
    whole, shrunk = SwarmNavCore(cfg, batch=6), SwarmNavCore(cfg, batch=6)
    for core in (whole, shrunk):
        core.reset(np.random.default_rng(3))
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (12, 6, cfg.n_agents, cfg.dim))
    for a in actions[:4]:
        whole.step(a), shrunk.step(a)
    rows = np.array([4, 1, 2])
    shrunk.keep(rows)
    assert shrunk.batch == 3 and shrunk.x.shape[0] == 3
    np.testing.assert_array_equal(shrunk.observe(), whole.observe()[rows])
    for a in actions[4:]:
        full = whole.step(a)
        part = shrunk.step(a[rows])
        for f, p in zip(full[:3], part[:3], strict=True):
            assert np.asarray(p).tobytes() == np.asarray(f)[rows].tobytes()
        for key, value in full[3].items():
            assert part[3][key].tobytes() == value[rows].tobytes(), key
        assert shrunk.x.tobytes() == whole.x[rows].tobytes()
        assert shrunk.v.tobytes() == whole.v[rows].tobytes()
        assert shrunk.observe().tobytes() == whole.observe()[rows].tobytes()
    shrunk.reset(np.random.default_rng(1))  # a shrunk core goes on with new episodes
    assert np.all(shrunk.t == 0)


def test_keep_refuses_a_model_whose_step_reads_the_whole_batch():
    core = SwarmNavCore(_config("piecewise"), batch=4)
    core.reset(np.random.default_rng(0))
    with pytest.raises(ValueError, match="does not declare that it steps each swarm"):
        core.keep(np.array([0, 2]))
