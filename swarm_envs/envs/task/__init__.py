"""The SwarmNav tasks, defined once: statistics, observation, reward and episode end.

Every core (numpy, cut-off, torch; the C step through the conformance tests) executes
these definitions on its own arrays (see ``docs/design.md``), for the task the config
names (:class:`~swarm_envs.tasks.TaskSpec`, from :mod:`swarm_envs.tasks`' registry):

- :mod:`~swarm_envs.envs.task.statistics`: :data:`STATISTICS` (``info``), the
  :class:`Frame` they read, a task's own (:func:`task_statistics`);
- :mod:`~swarm_envs.envs.task.observation`: the observation layout, :func:`observation`,
  a task's :class:`ObservationFeature` s;
- :mod:`~swarm_envs.envs.task.reward`: :data:`REWARD_TERMS`, :func:`reward`;
- :mod:`~swarm_envs.envs.task.episode`: when an episode ends;
- :mod:`~swarm_envs.envs.task.shipped`: the package's tasks as registry entries.
"""

from swarm_envs.envs.task.observation import (
    INFORMED_FLAG,
    OBS_BOUND,
    FeatureInputs,
    ObservationFeature,
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
    arrival_success,
    stat_keys,
    statistics,
    success_count,
    task_statistics,
)

__all__ = [
    "INFORMED_FLAG",
    "OBS_BOUND",
    "REWARD_TERMS",
    "STATISTICS",
    "STAT_KEYS",
    "FeatureInputs",
    "Frame",
    "ObservationFeature",
    "RewardInputs",
    "RewardTerm",
    "Statistic",
    "arrival_success",
    "observation",
    "observation_size",
    "ranked_neighbors",
    "reward",
    "stat_keys",
    "statistics",
    "success_count",
    "task_statistics",
]
