"""PettingZoo module for SwarmMill v0: ``parallel_env``, ``env``, ``raw_env``, ``vec_env``.

Bring a self-propelled swarm to the goal and hold a mill around it: the reward pays
the members' tangential speed about the goal, up to the cruise speed.
The env is the SwarmNav env with ``task="mill"`` and that task's defaults
(:mod:`swarm_envs.tasks`, ``docs/tasks.md``); every keyword of ``swarm_nav_v0`` is
accepted here too, and another ``task`` raises :class:`ValueError`.

>>> from swarm_envs import swarm_mill_v0
>>> swarm_mill_v0.parallel_env(n_agents=4).cfg.task
'mill'
"""

from swarm_envs.swarm_nav_v0 import task_functions

TASK = "mill"

parallel_env, raw_env, env, vec_env = task_functions(TASK, __name__)

__all__ = ["TASK", "env", "parallel_env", "raw_env", "vec_env"]
