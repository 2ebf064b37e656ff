"""PettingZoo module for SwarmInformed v0: ``parallel_env``, ``env``, ``raw_env``, ``vec_env``.

Navigation when only ``informed_fraction`` of the agents observe the goal (0.3 by
default); the others see their neighbours and which of them are informed.
The env is the SwarmNav env with ``task="informed"`` and that task's defaults
(:mod:`swarm_envs.tasks`, ``docs/tasks.md``); every keyword of ``swarm_nav_v0`` is
accepted here too, and another ``task`` raises :class:`ValueError`.

>>> from swarm_envs import swarm_informed_v0
>>> swarm_informed_v0.parallel_env(n_agents=4).cfg.task
'informed'
"""

from swarm_envs.swarm_nav_v0 import task_functions

TASK = "informed"

parallel_env, raw_env, env, vec_env = task_functions(TASK, __name__)

__all__ = ["TASK", "env", "parallel_env", "raw_env", "vec_env"]
