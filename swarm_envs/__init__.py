"""swarm_envs: Gymnasium and PettingZoo environments for learned swarm control.

``import swarm_envs`` registers ``swarm_envs/SwarmNav-v0``, ``swarm_envs/SwarmInformed-v0``
and ``swarm_envs/SwarmMill-v0`` (one per task of the package, :data:`TASK_IDS`; a task
registered later with :func:`register_task` brings its own) with Gymnasium:
``gym.make`` builds :class:`~swarm_envs.envs.adapters.swarm_nav.SwarmNavEnv` with that ``task``,
``gym.make_vec`` the batched :class:`~swarm_envs.envs.adapters.gym_vector.SwarmNavVectorEnv`
(its ``vector_entry_point``); the PettingZoo modules are ``swarm_nav_v0``,
``swarm_informed_v0`` and ``swarm_mill_v0``. The
episode length is the config's ``max_steps`` alone: the env truncates itself there, and
no ``max_episode_steps`` (``TimeLimit``) is registered. The import also makes the envs'
OpenMP users safe in processes forked afterwards (:mod:`swarm_envs._runtime.fork`).
:class:`TaskSpec` and :func:`register_task` add a task (:mod:`swarm_envs.tasks`;
``docs/tasks.md``); :mod:`swarm_envs.plugins` imports a user's file that registers
them (the files ``SWARM_ENVS_PLUGINS`` lists are imported with the package).
:class:`SwarmUnstableError` is what a step that goes unstable raises
(``SwarmConfig.on_unstable``). :func:`tune_allocator` is an explicit, process-wide
speed-up of glibc's heap for long runs (the command-line tools call it;
``SWARM_ENVS_TUNE_ALLOCATOR=1`` applies it at import).
"""

import os

from swarm_envs._runtime.allocator import tune_allocator
from swarm_envs._runtime.fork import install_fork_handlers

__version__ = "0.1.0"

install_fork_handlers()

if os.environ.get("SWARM_ENVS_TUNE_ALLOCATOR", "").strip() == "1":
    tune_allocator()

# The registry's first entries, the package's tasks, register their ids with Gymnasium.
from swarm_envs.tasks import TASK_IDS, TaskSpec, register_task  # noqa: E402

ENV_ID = TASK_IDS["navigation"]

from swarm_envs import swarm_informed_v0, swarm_mill_v0, swarm_nav_v0  # noqa: E402
from swarm_envs.envs.common import SwarmUnstableError  # noqa: E402

if os.environ.get("SWARM_ENVS_PLUGINS"):  # a worker of a process that loaded plugins
    from swarm_envs.plugins import load_plugins_from_environment

    load_plugins_from_environment()

__all__ = [
    "ENV_ID",
    "TASK_IDS",
    "SwarmUnstableError",
    "TaskSpec",
    "__version__",
    "register_task",
    "swarm_informed_v0",
    "swarm_mill_v0",
    "swarm_nav_v0",
    "tune_allocator",
]
