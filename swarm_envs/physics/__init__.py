"""Pure, vectorised physics of the swarm models over ``(..., N, d)`` arrays.

Public interface (DESIGN.md): :class:`SocialPotentialParams`, :func:`forces`,
:func:`energy`, :func:`simulate`. No environment, training or rendering code is
imported here.
"""

from swarm_envs.physics.initial import random_swarm, uniform_ball
from swarm_envs.physics.integrators import INTEGRATORS, simulate, step, verlet_step
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

__all__ = [
    "INTEGRATORS",
    "RHO_FLOOR",
    "PairGeometry",
    "SocialPotentialParams",
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
    "step",
    "uniform_ball",
    "verlet_step",
]
