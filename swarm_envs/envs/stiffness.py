"""Saying once that a swarm has become stiff: many substeps per step, and why.

The step-size control integrates each step of ``dt`` in as many substeps as the state's
stiffness needs (:mod:`swarm_envs.physics.integrators`), so a dense swarm stays finite
but every step costs several force evaluations. Each core feeds the ``substeps``
statistic of its steps to a :class:`StiffnessWatch`; when a swarm has taken more than
:data:`STIFF_SUBSTEPS` substeps per step on average over :data:`STIFF_WINDOW`
consecutive steps (the core's steps, across its episodes), it warns once per config
(:class:`StiffSwarmWarning`) with the cause (the substeps, the swarm's nearest-
neighbour distance and density against the repulsion length, whether the parameters are
H-stable) and the remedies. The count itself is the ``substeps`` statistic, in every
step's ``info``.
"""

from __future__ import annotations

import math
import warnings
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from swarm_envs.config import SwarmConfig

__all__ = ["STIFF_SUBSTEPS", "STIFF_WINDOW", "StiffSwarmWarning", "StiffnessWatch"]

#: Mean substeps per step (over an episode) above which a swarm counts as stiff: each
#: step then costs more than 8 force evaluations instead of 1.
STIFF_SUBSTEPS = 8.0

#: The consecutive steps over which the mean is taken: long enough that a stiff start
#: relaxing in a few steps does not count, short enough to say it early in a run.
STIFF_WINDOW = 100

_WARNED: set[str] = set()


class StiffSwarmWarning(UserWarning):
    """A swarm needs many substeps per step (see :mod:`swarm_envs.envs.stiffness`)."""


class StiffnessWatch:
    """The substeps of each swarm over the last steps; warns once per config when a
    swarm averages more than :data:`STIFF_SUBSTEPS` per step over :data:`STIFF_WINDOW`
    consecutive steps (module docstring). One add per step."""

    def __init__(self, cfg: SwarmConfig, batch: int) -> None:
        self.cfg = cfg
        self._key = repr(cfg)
        self._total = np.zeros(batch)
        self._steps = 0
        self._done = False

    def keep(self, rows: np.ndarray) -> None:
        """Watch the swarms ``rows`` only (a core shrinking its batch)."""
        self._total = self._total[rows]

    def observe(self, stats: dict[str, np.ndarray]) -> None:
        """Count a step's ``substeps`` statistic; every :data:`STIFF_WINDOW` steps, judge
        the window and start a new one."""
        if self._done:
            return
        self._total += stats["substeps"]
        self._steps += 1
        if self._steps < STIFF_WINDOW:
            return
        mean = self._total / self._steps
        stiff = mean > STIFF_SUBSTEPS
        if stiff.any() and self._key not in _WARNED:
            b = int(np.flatnonzero(stiff)[0])
            _WARNED.add(self._key)
            warnings.warn(
                stiff_message(self.cfg, stats, b, float(mean[b]), self._steps),
                StiffSwarmWarning,
                stacklevel=5,
            )
        self._done = self._key in _WARNED
        self._total[:] = 0.0
        self._steps = 0


def stiff_message(
    cfg: SwarmConfig, stats: dict[str, np.ndarray], b: int, mean: float, steps: int
) -> str:
    """The warning for swarm ``b``, stiff at ``mean`` substeps per step over ``steps``."""
    n, d = cfg.n_agents, cfg.dim
    near = float(stats["nearest_neighbor_distance"][b])
    expanse = float(stats["expanse"][b])
    # a uniform disc (ball) of radius R has a mean distance to its centre of 2R/3 (3R/4)
    ball, mean_radius = (math.pi, 2.0 / 3.0) if d == 2 else (4.0 * math.pi / 3.0, 0.75)
    radius = expanse / mean_radius
    density = n / (ball * radius**d) if radius > 0 else math.inf
    cause = (
        f"swarm {b} took {mean:.1f} substeps per step of dt={cfg.dt:g} on average over "
        f"{steps} steps (more than {STIFF_SUBSTEPS:g}): each step costs that many force "
        f"evaluations. Cause: its agents are packed close, mean nearest-neighbour distance "
        f"{near:.3g}, about {density:.3g} agents per unit {'area' if d == 2 else 'volume'} "
        f"({n} agents)"
    )
    remedy = "lower dt (more, cheaper steps of the same physics)"
    if cfg.dynamics == "social_potential":
        p = cfg.physics
        stability = p.h_stability if d == 2 else p.h_stability_3d
        cause += f", against the repulsion length l_r={p.l_r:g}; the pair law is " + (
            "H-stable"
            if stability > 1
            else f"not H-stable (C*l^{d} = {stability:.3g} <= 1: the swarm contracts "
            "to a density that grows with N)"
        )
        implicit = (
            ""
            if cfg.integrator == "implicit_damping_euler"
            else "integrator='implicit_damping_euler' (fewer substeps where the damping "
            "sets them; docs/models.md §7), "
        )
        remedy = (
            "an H-stable parameter set (SocialPotentialParams.large_swarm()), "
            + implicit
            + "a less dense start (init_density), "
            + remedy
            + ", or, for large N, backend='cutoff' or 'torch' (each substep cheaper)"
        )
    elif cfg.dynamics == "lagrangian":
        lag = cfg.lagrangian
        cause += (
            f"; the Lagrangian step's substeps keep each pair's clearance from the safety "
            f"radii (r={lag.r}) and its local error within step_tol={lag.step_tol:g} of "
            "that clearance, so close pairs take short substeps"
        )
        loosest = (
            "" if lag.step_tol >= 1.0 else "a looser tolerance (lagrangian.step_tol, at most 1), "
        )
        remedy = (
            loosest
            + "smaller safety radii (lagrangian.r), a less dense start (init_density), "
            + remedy
        )
    return f"stiff swarm: {cause}. To speed it up: {remedy}. (Said once per config.)"
