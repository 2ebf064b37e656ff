"""The ``perturbations`` section of a swarm config: agents that fail, join or stay away,
and noise on what the agents sense and do.

Every field is a number, or a range ``[low, high]`` from which each episode draws its
value uniformly (integers for the step times), so one config can train on randomised
perturbations and another evaluate at fixed ones. The defaults perturb nothing.

>>> p = Perturbations(failed_fraction=0.3, failure_mode="frozen")
>>> p.fails_agents, p.needs_masks
(True, True)
>>> Perturbations(failed_fraction=[0.0, 0.5]).bounds("failed_fraction")
(0.0, 0.5)
>>> Perturbations(obs_noise=-1)
Traceback (most recent call last):
...
ValueError: Perturbations.obs_noise must be in [0, inf), got -1.0
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from swarm_envs.physics._validation import check_real

#: What a failed agent does (``Perturbations.failure_mode``).
FAILURE_MODES = ("passive", "removed", "frozen")

#: A value or a ``(low, high)`` range drawn per episode.
Ranged = float | tuple[float, float]


def check_ranged(owner: str, name: str, value: Any, *, integer: bool, **bounds: Any) -> Any:
    """``value`` checked as a number in ``bounds``, or a ``[low, high]`` pair of them."""
    if isinstance(value, Sequence) and not isinstance(value, (str, bytes)):
        if len(value) != 2:
            raise ValueError(
                f"{owner}.{name} must be a number or a range [low, high], got {list(value)!r}"
            )
        low, high = (check_ranged(owner, name, item, integer=integer, **bounds) for item in value)
        if high < low:
            raise ValueError(f"{owner}.{name} range [low, high] needs low <= high, got {value!r}")
        return (low, high)
    if integer:
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise ValueError(
                f"{owner}.{name} must be an integer >= {bounds['low']:g} (a step), got {value!r}"
            )
        check_real(owner, name, value, **bounds)
        return int(value)
    return check_real(owner, name, value, **bounds)


@dataclass(frozen=True)
class Perturbations:
    """Agents that fail, join or are absent, and sensing and actuation noise.

    Counts per swarm are ``⌊fraction · N⌋``; which agents is drawn per episode from
    the env's generator, as are the ranges' values, the failure and joining times and
    the noise, so the same seed gives the same rollout.
    """

    failed_fraction: Ranged = 0.0
    """Fraction of the agents that fail during an episode, in ``[0, 1)``."""
    failure_mode: str = "passive"
    """What a failed agent does, one of :data:`FAILURE_MODES`: ``"passive"`` keeps its
    passive physics but its actions are ignored; ``"removed"`` leaves the swarm and the
    physics; ``"frozen"`` stops and stays where it is, an obstacle that still repels and
    attracts the others."""
    failure_time: Ranged = 0
    """The step after which each failing agent fails: 0 (failed from the start) or
    later; a range draws each agent's own step."""
    absent_fraction: Ranged = 0.0
    """Fraction of the agents absent for the whole episode, in ``[0, 1)``: a smaller
    swarm in the same slots (a range gives a random swarm size per episode)."""
    join_fraction: Ranged = 0.0
    """Fraction of the agents that join during the episode, in ``[0, 1)``: absent until
    their join step, then placed at their own start position (inside the start disc)
    at rest."""
    join_time: Ranged = 50
    """The step after which each joining agent appears, ``>= 1`` (a range draws each
    agent's own step)."""
    obs_noise: Ranged = 0.0
    """Standard deviation of Gaussian noise added to every observed feature (not the
    slot flags), in observation units, before clipping."""
    action_noise: Ranged = 0.0
    """Standard deviation of Gaussian noise added to every action before clipping to
    ``[−1, 1]``."""
    neighbor_dropout: Ranged = 0.0
    """Probability, in ``[0, 1)``, that a neighbour slot is dropped in a step: it then
    reads as padding (all zeros)."""

    def __post_init__(self) -> None:
        owner = type(self).__name__
        fractions = ("failed_fraction", "absent_fraction", "join_fraction", "neighbor_dropout")
        for name in fractions:
            value = check_ranged(
                owner,
                name,
                getattr(self, name),
                integer=False,
                low=0.0,
                high=1.0,
                high_inclusive=False,
            )
            object.__setattr__(self, name, value)
        for name in ("obs_noise", "action_noise"):
            value = check_ranged(owner, name, getattr(self, name), integer=False, low=0.0)
            object.__setattr__(self, name, value)
        failure_time = check_ranged(owner, "failure_time", self.failure_time, integer=True, low=0)
        join_time = check_ranged(owner, "join_time", self.join_time, integer=True, low=1)
        object.__setattr__(self, "failure_time", failure_time)
        object.__setattr__(self, "join_time", join_time)
        if self.failure_mode not in FAILURE_MODES:
            raise ValueError(
                f"{owner}.failure_mode must be one of {FAILURE_MODES}, got {self.failure_mode!r}"
            )
        most = sum(self.bounds(name)[1] for name in fractions[:3])
        if most > 1.0 - 1e-8:  # the counts round within 1e-9 each: keep an agent for sure
            raise ValueError(
                f"{owner}: failed_fraction + absent_fraction + join_fraction must stay below "
                f"1 (some agent must remain), got up to {most:g}"
            )

    def bounds(self, name: str) -> tuple[Any, Any]:
        """``(low, high)`` of a field (``(value, value)`` for a number)."""
        value = getattr(self, name)
        return tuple(value) if isinstance(value, tuple) else (value, value)

    @property
    def fails_agents(self) -> bool:
        """Whether some agent can fail in an episode."""
        return self.bounds("failed_fraction")[1] > 0

    @property
    def needs_masks(self) -> bool:
        """Whether agents can leave or stop in the physics (removed, frozen, absent or
        joining agents): the cores then mask pairs and updates, not only actions."""
        physical = self.fails_agents and self.failure_mode != "passive"
        return physical or self.bounds("absent_fraction")[1] > 0 or self.joins

    @property
    def joins(self) -> bool:
        """Whether some agent can join during an episode."""
        return self.bounds("join_fraction")[1] > 0

    @property
    def any(self) -> bool:
        """Whether anything is perturbed."""
        return any(
            self.bounds(f.name)[1] > 0
            for f in fields(self)
            if f.name not in ("failure_mode", "failure_time", "join_time")
        )


def agent_count(fraction: float, n_agents: int) -> int:
    """``⌊fraction · N⌋`` agents (to round-off: 0.3 of 10 is 3).

    >>> agent_count(0.3, 10), agent_count(0.29, 100), agent_count(0.5, 3)
    (3, 29, 1)
    """
    return math.floor(fraction * n_agents + 1e-9)
