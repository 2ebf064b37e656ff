"""The swarm tasks as a BenchMARL task: ``SwarmTask.SWARM_NAV``, ``SWARM_INFORMED``, ``SWARM_MILL``.

``SwarmTask.SWARM_NAV.get_task()`` is SwarmNav with its defaults;
``get_task(config={...})`` takes any keyword of the env (``n_agents``, ``max_steps``,
``physics``, ``perturbations``, ``config`` for a YAML file, ...) and ``return_state``
(a global ``"state"`` for centralised critics). The config is checked when the task is
made: an unknown key raises :class:`~swarm_envs.config.UnknownKeyError` (a
``TypeError``), a bad value :class:`ValueError`. BenchMARL's ``num_envs`` (its
``on_policy_n_envs_per_worker``, ``off_policy_n_envs_per_worker`` and
``evaluation_episodes``) is the number of swarms that one
:class:`~train.benchmarl.torchrl_env.SwarmTorchRLEnv` steps at once, so BenchMARL
collects from it as from VMAS, without a process or a Python env per swarm.

Actions are continuous (MAPPO, IPPO, MASAC, MADDPG, ISAC, IDDPG); the discrete-only
algorithms (QMIX, VDN, IQL) are refused by BenchMARL. Evaluation videos are not
rendered.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from typing import Any

from swarm_envs.envs.adapters.inputs import make_config
from train.benchmarl import INSTALL_HINT
from train.benchmarl.torchrl_env import GROUP, SwarmTorchRLEnv

try:
    from benchmarl.environments.common import Task, TaskClass
    from torchrl.data import Composite
    from torchrl.envs import EnvBase
except ImportError as err:  # pragma: no cover - the extra is installed in CI
    raise ImportError(INSTALL_HINT) from err

__all__ = ["SwarmTask", "SwarmTaskClass"]

#: The ``task`` of each member of :class:`SwarmTask`.
TASK_OF = {"SWARM_NAV": "navigation", "SWARM_INFORMED": "informed", "SWARM_MILL": "mill"}

#: The task config's keys that are not :class:`~swarm_envs.config.SwarmConfig` fields.
OWN_KEYS = ("config", "return_state")


class SwarmTaskClass(TaskClass):
    """One swarm task with its config (module docstring); made by :class:`SwarmTask`."""

    def __init__(self, name: str, config: dict[str, Any] | None) -> None:
        config = dict(config or {})
        if "task" in config:
            raise ValueError(
                f"the task config of {name} must not set 'task': each task is its own member "
                f"of SwarmTask ({', '.join(TASK_OF)}), got task={config['task']!r}"
            )
        super().__init__(name, config)
        self.swarm_task = TASK_OF[name]
        # Checked now, so that a bad key fails before BenchMARL builds an experiment.
        env_kwargs = {k: v for k, v in config.items() if k not in OWN_KEYS}
        self.swarm_config = make_config(
            config.get("config"),
            {**env_kwargs, "task": self.swarm_task},
            owner=f"SwarmTask.{name}",
            keywords=OWN_KEYS,
        )

    def get_env_fun(
        self, num_envs: int, continuous_actions: bool, seed: int | None, device: Any
    ) -> Callable[[], EnvBase]:
        if not continuous_actions:
            raise ValueError(
                "the swarm tasks have continuous actions only; choose an algorithm for "
                "continuous actions (MAPPO, IPPO, MASAC, ISAC, MADDPG, IDDPG)"
            )
        config = copy.deepcopy(self.config)
        task = self.swarm_task

        def make() -> EnvBase:
            env = SwarmTorchRLEnv(num_envs, device=device, task=task, **config)
            if seed is not None:
                env.set_seed(seed)
            return env

        return make

    def supports_continuous_actions(self) -> bool:
        return True

    def supports_discrete_actions(self) -> bool:
        return False

    def has_render(self, env: EnvBase) -> bool:
        return False

    def max_steps(self, env: EnvBase) -> int:
        return self.swarm_config.max_steps

    def group_map(self, env: EnvBase) -> dict[str, list[str]]:
        return {GROUP: [f"agent_{i}" for i in range(self.swarm_config.n_agents)]}

    def observation_spec(self, env: EnvBase) -> Composite:
        spec = env.full_observation_spec_unbatched.clone()
        if "state" in spec.keys():
            del spec["state"]
        return spec

    def info_spec(self, env: EnvBase) -> Composite | None:
        return None

    def state_spec(self, env: EnvBase) -> Composite | None:
        spec = env.full_observation_spec_unbatched
        if "state" not in spec.keys():
            return None
        return Composite({"state": spec["state"].clone()})

    def action_spec(self, env: EnvBase) -> Composite:
        return env.full_action_spec_unbatched

    def action_mask_spec(self, env: EnvBase) -> Composite | None:
        return None

    @staticmethod
    def env_name() -> str:
        return "swarm_envs"


class SwarmTask(Task):
    """The swarm tasks for BenchMARL; ``get_task()`` without a config gives the task's
    defaults (there is no YAML of them inside BenchMARL's package)."""

    SWARM_NAV = None
    SWARM_INFORMED = None
    SWARM_MILL = None

    @staticmethod
    def associated_class() -> type[SwarmTaskClass]:
        return SwarmTaskClass

    def get_task(self, config: dict[str, Any] | None = None) -> TaskClass:
        return self.associated_class()(name=self.name, config=config or {})

    def get_from_yaml(self, path: str | None = None) -> TaskClass:
        """The task with the config of the YAML file ``path`` (its keys as for
        ``get_task``); without one, the task's defaults."""
        if path is None:
            return self.get_task()
        from swarm_envs.config_mapping import load_yaml

        return self.get_task(config=load_yaml(path))
