"""No hidden process-wide side effects: making and stepping any core leaves the glibc
heap settings alone (the tuning is explicit: ``swarm_envs.tune_allocator``)."""

from __future__ import annotations

import subprocess
import sys

PROBE = """
import numpy as np
import swarm_envs
from swarm_envs._runtime import allocator
from swarm_envs.config import SwarmConfig
from swarm_envs.envs.backends import make_core, unsupported
for backend in ("numpy", "cutoff", "native", "torch"):
    cfg = SwarmConfig(n_agents=5, backend=backend)
    if unsupported(cfg, backend) is None:
        core = make_core(cfg, batch=2)
        core.reset(np.random.default_rng(0))
        core.step(np.zeros((2, 5, 2)))
env = swarm_envs.swarm_nav_v0.parallel_env(n_agents=4)
env.reset(seed=0)
print(allocator.allocator_tuned())
swarm_envs.tune_allocator()
print(allocator.allocator_tuned())
"""


def test_cores_do_not_tune_the_allocator_but_the_call_does():
    out = subprocess.run(
        [sys.executable, "-c", PROBE],
        capture_output=True,
        text=True,
        check=True,
        env={"PATH": "/usr/bin:/bin", "SWARM_ENVS_TORCH_COMPILE": "0"},
    )
    lines = out.stdout.split()
    assert lines[0] == "False"
    assert lines[1] in ("True", "False")  # True on Linux with glibc
    if sys.platform.startswith("linux"):
        assert lines[1] == "True"
