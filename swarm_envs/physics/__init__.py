"""Pure, vectorised physics of the swarm models over ``(..., N, d)`` arrays.

Public interface (docs/design.md): :class:`SocialPotentialParams`, :func:`forces`,
:func:`energy`, :func:`simulate`. The other models of the seeds live in their own
modules (``zone``, ``piecewise``, ``lagrangian``) with ``ZoneParams``,
``PiecewiseParams`` and ``LagrangianParams``, exported here too. ``simulate`` dispatches
on the parameter type to the simulator of the model registered for it
(:mod:`swarm_envs.models`, which imports the physics alone; a user's model registered
there is simulated the same way). No environment, training or rendering code is
imported here.
"""

from swarm_envs.physics.initial import random_swarm, uniform_ball
from swarm_envs.physics.integrators import INTEGRATORS, simulate, step, verlet_step
from swarm_envs.physics.lagrangian import LagrangianParams, simulate_lagrangian
from swarm_envs.physics.piecewise import PiecewiseParams, simulate_piecewise
from swarm_envs.physics.social_potential import (
    RHO_FLOOR,
    PairGeometry,
    SocialPotentialParams,
    energy,
    forces,
    goal_force,
    goal_potential,
    kinetic_energy,
    pair_geometry,
    pair_potential,
    potential_energy,
)
from swarm_envs.physics.zone import ZoneParams, simulate_zone

__all__ = [
    "INTEGRATORS",
    "RHO_FLOOR",
    "LagrangianParams",
    "PairGeometry",
    "PiecewiseParams",
    "SocialPotentialParams",
    "ZoneParams",
    "energy",
    "forces",
    "goal_force",
    "goal_potential",
    "kinetic_energy",
    "pair_geometry",
    "pair_potential",
    "potential_energy",
    "random_swarm",
    "simulate",
    "simulate_lagrangian",
    "simulate_piecewise",
    "simulate_zone",
    "step",
    "uniform_ball",
    "verlet_step",
]
