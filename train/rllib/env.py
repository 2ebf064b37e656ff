"""RLlib's view of SwarmNav: a thin ``MultiAgentEnv`` over ``swarm_nav_v0.parallel_env``.

Why not RLlib's ``ParallelPettingZooEnv``: in Ray 2.60 it builds its agent list from a
``set`` (the order changes with ``PYTHONHASHSEED``, which breaks reproducible runs) and
resets the env once, unseeded, in its constructor. This adapter keeps PettingZoo's
order (``agent_0`` … ``agent_{N-1}``), exposes the per-agent spaces as the new API
stack reads them (``observation_spaces`` / ``action_spaces``), and passes
``reset(seed=...)`` through; otherwise it forwards the ParallelEnv unchanged and adds
the ``"__all__"`` flags RLlib needs.

``env_config`` (RLlib's ``EnvContext``, a dict) holds keyword arguments of
:func:`swarm_envs.swarm_nav_v0.parallel_env`. The trainer passes the fully resolved
:class:`~swarm_envs.config.SwarmConfig` as plain data, so remote env runners need no
YAML file.

The class needs Ray; it is built on first access (``from train.rllib.env import
SwarmNavMultiAgentEnv``), so this module imports without Ray.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from typing import Any

from train.rllib.cluster import require_ray

# SwarmNavMultiAgentEnv is built on first access by the module's __getattr__.
__all__ = ["ENV_NAME", "SwarmNavMultiAgentEnv", "make_env", "register"]  # noqa: F822

#: Name under which :func:`register` makes the env known to RLlib / Tune.
ENV_NAME = "swarm_envs/SwarmNav-v0-rllib"


@functools.cache
def _env_class() -> type:
    require_ray()
    from ray.rllib.env.multi_agent_env import MultiAgentEnv

    from swarm_envs import swarm_nav_v0

    class SwarmNavMultiAgentEnv(MultiAgentEnv):
        """RLlib ``MultiAgentEnv`` over
        :class:`~swarm_envs.envs.adapters.swarm_nav.SwarmNavParallelEnv`.

        Args:
            config: keyword arguments of ``swarm_nav_v0.parallel_env`` (RLlib passes its
                ``env_config`` here).
        """

        def __init__(self, config: Mapping[str, Any] | None = None) -> None:
            super().__init__()
            kwargs = dict(config or {})
            self.par_env = swarm_nav_v0.parallel_env(**kwargs)
            self.cfg = self.par_env.cfg
            names: list[str] = list(self.par_env.possible_agents)
            self.possible_agents = list(names)
            self.agents = []
            self.observation_spaces = {a: self.par_env.observation_space(a) for a in names}
            self.action_spaces = {a: self.par_env.action_space(a) for a in names}

        # RLlib types agent ids as Hashable | str, and MultiAgentEnv's reset and step
        # override gymnasium.Env's incompatibly: this env's ids are the str names above.
        # (Without Ray installed, MultiAgentEnv is untyped and the ignores go unused.)
        def reset(  # type: ignore[override, unused-ignore]
            self, *, seed: int | None = None, options: dict | None = None
        ) -> tuple[dict[str, Any], dict[str, Any]]:
            obs, infos = self.par_env.reset(seed=seed, options=options)
            self.agents = list(self.par_env.agents)
            return obs, infos

        def step(  # type: ignore[override, unused-ignore]
            self, action_dict: dict[str, Any]
        ) -> tuple[dict, dict, dict, dict, dict]:
            obs, rewards, terminated, truncated, infos = self.par_env.step(action_dict)
            self.agents = list(self.par_env.agents)
            terminated = {**terminated, "__all__": all(terminated.values())}
            truncated = {**truncated, "__all__": all(truncated.values())}
            return obs, rewards, terminated, truncated, infos

        def render(self) -> Any:
            return self.par_env.render()

        def close(self) -> None:
            self.par_env.close()

    # Importable by name (pickled by reference): ``train.rllib.env.SwarmNavMultiAgentEnv``.
    SwarmNavMultiAgentEnv.__module__ = __name__
    SwarmNavMultiAgentEnv.__qualname__ = "SwarmNavMultiAgentEnv"
    return SwarmNavMultiAgentEnv


def __getattr__(name: str) -> Any:
    if name == "SwarmNavMultiAgentEnv":
        return _env_class()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def make_env(config: Mapping[str, Any] | None = None) -> Any:
    """A new :class:`SwarmNavMultiAgentEnv` (the env creator given to RLlib)."""
    return _env_class()(config)


def register(name: str = ENV_NAME) -> str:
    """Register :func:`make_env` with Ray Tune's registry under ``name``; returns it."""
    require_ray()
    from ray.tune.registry import register_env

    register_env(name, make_env)
    return name
