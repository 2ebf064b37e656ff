"""One sweep trial: a pure function of its plain-data spec.

A trial's random start comes from ``numpy.random.SeedSequence(spec["entropy"])``
(:func:`trial_seed`), so the same spec gives the same row in any process, on either
engine.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from swarm_envs.config import SwarmConfig, config_from_mapping
from swarm_envs.physics import random_swarm, simulate
from train.sweep.config import RelaxSetup
from train.sweep.measures import RELAX_STATISTICS, TASKS

__all__ = ["run_trial", "trial_seed"]


def trial_seed(entropy: Sequence[int]) -> int:
    """The integer seed of a trial: ``SeedSequence(entropy)``'s first 63-bit word.

    >>> trial_seed([0, 1]) == trial_seed([0, 1]) != trial_seed([0, 2])
    True
    """
    state = np.random.SeedSequence([int(e) for e in entropy]).generate_state(1, np.uint64)
    return int(state[0]) >> 1


def _sample_indices(steps: int, samples: int) -> np.ndarray:
    """``samples`` evenly spaced step indices in ``[0, steps]``, the end always included."""
    return np.unique(np.rint(np.linspace(0, steps, min(samples, steps + 1))).astype(np.int64))


def _relax(setup: Mapping[str, Any], seed: int) -> dict[str, float]:
    rs = config_from_mapping(RelaxSetup, setup)
    rng = np.random.default_rng(seed)
    x0, v0 = random_swarm(rng, rs.n_agents, dim=rs.dim, radius=rs.init_radius, speed=rs.init_speed)
    xs, vs = simulate(rs.physics, x0, v0, dt=rs.dt, steps=rs.steps, integrator=rs.integrator)
    idx = _sample_indices(rs.steps, rs.samples)
    x, v = xs[idx], vs[idx]
    out: dict[str, float] = {}
    for name, fn in RELAX_STATISTICS.items():
        series = np.asarray(fn(x, v, rs.physics), dtype=np.float64)
        out[f"final_{name}"] = float(series[-1])
        out[f"time_mean_{name}"] = float(series.mean())
    return out


def _navigate(setup: Mapping[str, Any], seed: int) -> dict[str, Any]:
    from agents import make_controller
    from train.evaluate import FINAL_KEYS, run_episodes

    cfg = config_from_mapping(SwarmConfig, setup["env"])
    policy = make_controller(setup["policy"], cfg, seed=seed)
    batch = run_episodes(policy, cfg, 1, seed, name="sweep", record_episode=False)
    success = bool(batch.success[0])
    length = int(batch.lengths[0])
    out: dict[str, Any] = {
        "return": float(batch.returns[0]),
        "success": float(success),
        "time_to_goal": length * cfg.dt if success else None,
        "episode_length": float(length),
        "collisions": float(batch.collisions[0]),
        "control_effort": float(batch.effort[0]),
    }
    for k in FINAL_KEYS:
        out[f"final_{k}"] = float(batch.final[k][0])
    return out


def run_trial(spec: Mapping[str, Any]) -> dict[str, Any]:
    """Run one trial: a pure function of its spec.

    ``spec`` is one of :meth:`~train.sweep.config.SweepConfig.trial_specs`. Returns the
    row ``{"index", <grid keys>, "seed", <measures>}`` of plain Python values (floats,
    ints, ``None`` for a missing time to goal).
    """
    seed = trial_seed(spec["entropy"])
    if spec["task"] == "relax":
        measures = _relax(spec["setup"], seed)
    elif spec["task"] == "navigate":
        measures = _navigate(spec["setup"], seed)
    else:
        raise ValueError(f"task must be one of {TASKS}, got {spec['task']!r}")
    return {"index": int(spec["index"]), **spec["point"], "seed": int(spec["seed"]), **measures}
