"""PettingZoo-style module for SwarmNav v0: ``parallel_env``, ``env``, ``raw_env``, ``vec_env``.

>>> from swarm_envs import swarm_nav_v0
>>> par = swarm_nav_v0.parallel_env(n_agents=4)
>>> obs, infos = par.reset(seed=0)
>>> sorted(obs)[:2], obs["agent_0"].dtype
(['agent_0', 'agent_1'], dtype('float32'))

Every API here follows one input rule for actions and seeds (``docs/inputs.md``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from pettingzoo.utils import wrappers
from pettingzoo.utils.conversions import parallel_to_aec_wrapper
from pettingzoo.utils.env import AECEnv

from swarm_envs.envs.adapters.inputs import check_agent_action
from swarm_envs.envs.adapters.swarm_nav import SwarmNavParallelEnv

if TYPE_CHECKING:
    from swarm_envs.envs.adapters.vec_env import SwarmNavVecEnv


class _CheckedParallelToAEC(parallel_to_aec_wrapper):
    """PettingZoo's ``parallel_to_aec`` wrapper that checks each action when it is given.

    The wrapper would pass an agent's action to the parallel env only once the last
    agent has acted; here each action is checked against the input rule
    (``docs/inputs.md``) in its own ``step`` call, so the error comes from the call
    that gave it (and names the agent). A terminated or truncated agent's action must
    be ``None`` (PettingZoo's rule), else :class:`ValueError`.
    """

    def step(self, action: Any) -> None:
        agent = self.agent_selection
        if self.terminations[agent] or self.truncations[agent]:
            if action is not None:
                raise ValueError(
                    f"action of {agent} must be None: the agent is done (terminated or "
                    f"truncated), got {type(action).__name__}"
                )
        else:
            action = check_agent_action(action, self.env.cfg.dim, agent)
        super().step(action)


def parallel_env(**kwargs: Any) -> SwarmNavParallelEnv:
    """The PettingZoo ``ParallelEnv`` (the source of truth); kwargs as in the env docstring."""
    return SwarmNavParallelEnv(**kwargs)


def raw_env(**kwargs: Any) -> AECEnv:
    """The bare AEC env (PettingZoo's convention): :func:`parallel_env` converted as
    PettingZoo's ``parallel_to_aec`` does, checking each action as it is given, without
    wrappers."""
    return _CheckedParallelToAEC(parallel_env(**kwargs))


def env(**kwargs: Any) -> AECEnv:
    """The AEC env: :func:`raw_env` in PettingZoo's order-enforcing wrapper (once)."""
    return wrappers.OrderEnforcingWrapper(raw_env(**kwargs))


def vec_env(n_swarms: int = 1, **kwargs: Any) -> SwarmNavVecEnv:
    """A batched SB3 ``VecEnv`` with ``n_swarms × n_agents`` slots (one shared policy).

    See :class:`swarm_envs.envs.adapters.vec_env.SwarmNavVecEnv`. Imported lazily (it needs SB3,
    and so torch).
    """
    from swarm_envs.envs.adapters.vec_env import SwarmNavVecEnv

    return SwarmNavVecEnv(n_swarms, **kwargs)


def for_task(task: str, module: str, kwargs: dict[str, Any]) -> dict[str, Any]:
    """``kwargs`` with ``task`` set, for the module of that task (a PettingZoo module
    such as ``swarm_informed_v0``); another ``task`` given raises :class:`ValueError`."""
    given = kwargs.get("task", task)
    if given != task:
        from swarm_envs.tasks import task_names, task_spec

        modules = [task_spec(n).module for n in task_names()]
        raise ValueError(
            f"{module} runs task={task!r}, got task={given!r}; each task has its module "
            f"({', '.join(m.rsplit('.', 1)[-1] for m in modules if m)}), and "
            "swarm_nav_v0 runs any task with task=..."
        )
    return {**kwargs, "task": task}


def task_functions(task: str, module: str) -> tuple[Callable[..., Any], ...]:
    """``(parallel_env, raw_env, env, vec_env)`` of the PettingZoo module ``module`` of
    ``task``: this module's functions with ``task`` set (:func:`for_task`). A user's
    task file becomes such a module with
    ``parallel_env, raw_env, env, vec_env = task_functions("my_task", __name__)``."""

    def task_parallel_env(**kwargs: Any) -> SwarmNavParallelEnv:
        return parallel_env(**for_task(task, module, kwargs))

    def task_raw_env(**kwargs: Any) -> AECEnv:
        return raw_env(**for_task(task, module, kwargs))

    def task_env(**kwargs: Any) -> AECEnv:
        return env(**for_task(task, module, kwargs))

    def task_vec_env(n_swarms: int = 1, **kwargs: Any) -> SwarmNavVecEnv:
        return vec_env(n_swarms, **for_task(task, module, kwargs))

    made = (task_parallel_env, task_raw_env, task_env, task_vec_env)
    for fn, base in zip(made, (parallel_env, raw_env, env, vec_env), strict=True):
        fn.__name__ = fn.__qualname__ = base.__name__
        fn.__module__ = module
        fn.__doc__ = f"{base.__doc__}\n\n    With ``task={task!r}`` (and its defaults)."
    return made


__all__ = ["env", "for_task", "parallel_env", "raw_env", "task_functions", "vec_env"]
