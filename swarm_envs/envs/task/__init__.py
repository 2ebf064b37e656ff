"""The SwarmNav task, defined once: statistics, observation and reward.

Every core (numpy, cut-off, torch; the C step through the conformance tests) executes
these definitions on its own arrays (see ``docs/design.md``):

- :mod:`~swarm_envs.envs.task.statistics`: :data:`STATISTICS` (``info``), the
  :class:`Frame` they read;
- :mod:`~swarm_envs.envs.task.observation`: the observation layout, :func:`observation`;
- :mod:`~swarm_envs.envs.task.reward`: :data:`REWARD_TERMS`, :func:`reward`.
"""

from swarm_envs.envs.task.observation import (
    OBS_BOUND,
    observation,
    observation_size,
    ranked_neighbors,
)
from swarm_envs.envs.task.reward import REWARD_TERMS, RewardInputs, RewardTerm, reward
from swarm_envs.envs.task.statistics import (
    STAT_KEYS,
    STATISTICS,
    Frame,
    Statistic,
    statistics,
    success_count,
)

__all__ = [
    "OBS_BOUND",
    "REWARD_TERMS",
    "STATISTICS",
    "STAT_KEYS",
    "Frame",
    "RewardInputs",
    "RewardTerm",
    "Statistic",
    "observation",
    "observation_size",
    "ranked_neighbors",
    "reward",
    "statistics",
    "success_count",
]
